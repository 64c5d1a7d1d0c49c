#include "canopy_ao/grass_cover.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {

void check(const GrassCoverData& d) {
  if (!std::isfinite(d.ground)) throw std::invalid_argument("ground must be finite");
  if (!std::isfinite(d.blade) || !(d.blade > 0)) {
    throw std::invalid_argument("blade must be finite and > 0, got " + std::to_string(d.blade));
  }
  if (!(d.visibility >= 0 && d.visibility <= 1)) {
    throw std::invalid_argument("visibility must be in [0, 1], got " +
                                std::to_string(d.visibility));
  }
  if (!std::isfinite(d.cell) || !(d.cell > 0)) {
    throw std::invalid_argument("cell must be finite and > 0, got " + std::to_string(d.cell));
  }
  if (!std::isfinite(d.origin_x) || !std::isfinite(d.origin_y)) {
    throw std::invalid_argument("origin must be finite");
  }
  // Keys and widths below 2^52: every cell index and bound below is exact in double, and
  // no sum of them overflows.
  constexpr std::int64_t kMaxKey = std::int64_t{1} << 52;
  if (d.width < 1 || d.width >= kMaxKey) {
    throw std::invalid_argument("width must be in [1, 2^52), got " + std::to_string(d.width));
  }
  for (std::size_t k = 0; k < d.keys.size(); ++k) {
    if (d.keys[k] < 0 || d.keys[k] >= kMaxKey || (k > 0 && d.keys[k] <= d.keys[k - 1])) {
      throw std::invalid_argument("keys must be in [0, 2^52) and strictly increasing (keys[" +
                                  std::to_string(k) + "] = " + std::to_string(d.keys[k]) + ")");
    }
  }
  const double m = std::ceil(d.blade / d.cell);
  if (!(m <= double(GrassCover::kMaxDiscCells))) {
    throw std::invalid_argument("blade / cell must be at most " +
                                std::to_string(GrassCover::kMaxDiscCells) + ", got " +
                                std::to_string(d.blade / d.cell));
  }
}

// x clamped to [lo, hi] (NaN → lo), as an integer.
std::int64_t clamped(double x, std::int64_t lo, std::int64_t hi) {
  const double c = x > double(lo) ? (x < double(hi) ? x : double(hi)) : double(lo);
  return static_cast<std::int64_t>(c);
}

}  // namespace

GrassCover::GrassCover(GrassCoverData data) : d_(std::move(data)) {
  check(d_);
  m_ = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(d_.blade / d_.cell)));
  const std::int64_t r2 = m_ * m_;
  double total = 0;
  for (std::int64_t di = -m_; di <= m_; ++di) {
    const std::int64_t rest = r2 - di * di;
    auto w = static_cast<std::int64_t>(std::sqrt(double(rest)));
    while (w * w > rest) --w;
    while ((w + 1) * (w + 1) <= rest) ++w;
    half_.push_back(w);
    total += double(2 * w + 1);
  }
  total_ = total;
  if (!d_.keys.empty()) {
    row_lo_ = d_.keys.front() / d_.width;
    row_hi_ = d_.keys.back() / d_.width;
  }
}

float GrassCover::visibility(Vec3 x) const {
  // Beyond a blade height of the ground level, or no footprint: the layer is not above.
  if (!(std::fabs(double(x.z) - d_.ground) <= d_.blade) || d_.keys.empty()) return 1.0f;
  // The point's cell, clamped to just outside the footprint's rows and columns: a clamped
  // cell's disc holds no footprint cell, as the unclamped one's did not.
  const std::int64_t i = clamped(std::floor((double(x.x) - d_.origin_x) / d_.cell),
                                 row_lo_ - m_ - 1, row_hi_ + m_ + 1);
  const std::int64_t j = clamped(std::floor((double(x.y) - d_.origin_y) / d_.cell), -m_ - 1,
                                 d_.width + m_);
  const auto first = d_.keys.begin(), last = d_.keys.end();
  std::int64_t hits = 0;
  const std::int64_t r_lo = std::max({i - m_, row_lo_, std::int64_t{0}});
  const std::int64_t r_hi = std::min(i + m_, row_hi_);
  for (std::int64_t row = r_lo; row <= r_hi; ++row) {
    const std::int64_t w = half_[static_cast<std::size_t>(row - i + m_)];
    const std::int64_t lo = std::max<std::int64_t>(j - w, 0);
    const std::int64_t hi = std::min<std::int64_t>(j + w, d_.width - 1);
    if (lo > hi) continue;
    hits += std::upper_bound(first, last, row * d_.width + hi) -
            std::lower_bound(first, last, row * d_.width + lo);
  }
  return static_cast<float>(1.0 - (double(hits) / total_) * (1.0 - d_.visibility));
}

void GrassCover::ground_visibility(PointsView positions, float* out) const {
  if (positions.size > 0 && (positions.data == nullptr || out == nullptr)) {
    throw std::invalid_argument("positions or out is null");
  }
  parallel_for_blocks(positions.size, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t k = b; k < e; ++k) out[k] = visibility(positions[k]);
  });
}

}  // namespace canopy_ao
