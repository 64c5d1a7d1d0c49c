#include "canopy_ao/occluders.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "canopy_ao/model_checks.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr std::size_t kMaxCells = std::size_t(1) << 20;  // grid memory bound (4 MB of offsets)
constexpr int kMaxDim = 1024;
}  // namespace

float sphere_occlusion(float cos_theta, float sin2_sigma) {
  if (!(sin2_sigma > 0)) return 0.0f;  // also NaN
  return sphere_occlusion_law(std::clamp(cos_theta, -1.0f, 1.0f), sin2_sigma);
}

namespace {
// The share of a shell's blocked fraction that lies within the AO distance: the cosine-weighted
// cone within reach over the whole silhouette's (occluders.h, "AO distance"). 1 when D does not
// bind; the sphere with squared radius r2 stands for the shell.
float reach_share(float c, float d2, float r2, float distance) {
  const float full = std::min(r2 / d2, 1.0f);
  const float part = reach_sin2(d2, r2, distance);
  if (part >= full) return 1.0f;
  if (!(part > 0)) return 0.0f;
  const float whole = sphere_occlusion(c, full);
  return whole > 0 ? std::clamp(sphere_occlusion(c, part) / whole, 0.0f, 1.0f) : 0.0f;
}
}  // namespace

float shell_opacity(float tau) {
  // Mean chord of a sphere 4R/3 (Cauchy) through a medium of τ per radius.
  return static_cast<float>(1.0 - std::exp(-4.0 * static_cast<double>(tau) / 3.0));
}

float occluder_visibility(Vec3 x, Vec3 n, const Ellipsoid& shell, float opacity,
                          float distance) {
  const Vec3 u = shell.to_unit(x);
  if (!(dot(u, u) > 1.0f)) return 1.0f;  // inside: the canopy model's job
  const float nn = dot(n, n);
  if (!(nn > 1e-30f)) return 1.0f;  // zero normal: facing away, the occluder is below horizon
  const Vec3 dv = shell.center - x;
  const float nd = dot(n, dv) / std::sqrt(nn);  // d · cos θ
  const float rmax = std::max({shell.radii.x, shell.radii.y, shell.radii.z});
  if (nd <= -rmax) return 1.0f;  // even the bounding sphere is below the horizon
  const float d2 = dot(dv, dv);
  const float d = std::sqrt(d2);
  // Sphere with the ellipsoid's projected area along the view direction (exact for spheres):
  // r_eq² = r₁r₂r₃ sqrt(Σ (t_k/r_k)²), t_k = dot(dv/d, a_k); sin²σ = r_eq²/d², evaluated as
  // (r₁/d)(r₂/d) · sqrt(Σ (t_k r₃/r_k)²) so that no intermediate overflows.
  float q = 0;
  for (int k = 0; k < 3; ++k) {
    const float t = dot(dv, shell.axes[k]) / d * (shell.radii.z / shell.radii[k]);
    q += t * t;
  }
  float sin2 = std::min((shell.radii.x / d) * (shell.radii.y / d) * std::sqrt(q), 1.0f);
  if (distance < std::numeric_limits<float>::infinity()) {
    sin2 = reach_sin2(d2, sin2 * d2, distance);  // the opaque sphere: the reached cone, exact
  }
  const float occ = opacity * sphere_occlusion(nd / d, sin2);
  return std::clamp(1.0f - occ, 0.0f, 1.0f);
}

float occluder_visibility_medium(Vec3 x, Vec3 n, const Ellipsoid& shell,
                                 const MediumTable::Slice& slice, float distance) {
  // The unit frame of docs/DESIGN.md, 'The method ladder', as the in-shell models: x' = diag(1/r)
  // Qᵀ (x − C), normal by
  // the inverse transpose (an affine map keeps the tangent half-space, so "wholly below the
  // horizon" is exact). Measured against the same table on occluder_visibility's equivalent
  // sphere (r = d/r_eq): that one darkened real-mesh grounds almost as much as the old law.
  const Vec3 u = shell.to_unit(x);
  const float uu = dot(u, u);
  if (!(uu > 1.0f)) return 1.0f;  // inside: the canopy model's job
  if (!(dot(n, n) > 1e-30f)) return 1.0f;  // zero normal: facing away
  const Vec3 nu = shell.normal_to_unit(n);
  const float ru = std::sqrt(uu);
  const float cb = std::clamp(dot(nu, u) / ru, -1.0f, 1.0f);  // cos β in the unit frame
  if (cb * ru >= 1.0f) return 1.0f;  // the unit sphere wholly below the horizon
  const float v = slice.ao(ru, cb);
  if (!(distance < std::numeric_limits<float>::infinity())) return v;
  // The AO distance, in world terms: the sphere of the shell's projected area (as
  // occluder_visibility) gives the share of the blocked fraction within reach.
  const Vec3 dv = shell.center - x;
  const float d2 = dot(dv, dv), d = std::sqrt(d2);
  float q = 0;
  for (int k = 0; k < 3; ++k) {
    const float t = dot(dv, shell.axes[k]) / d * (shell.radii.z / shell.radii[k]);
    q += t * t;
  }
  const float r2 = std::min((shell.radii.x / d) * (shell.radii.y / d) * std::sqrt(q), 1.0f) * d2;
  const float c = dot(n, dv) / (d * std::sqrt(dot(n, n)));
  return std::clamp(1.0f - (1.0f - v) * reach_share(c, d2, r2, distance), 0.0f, 1.0f);
}

OccluderMaterial OccluderMaterial::of(const OccluderOptions& options) {
  OccluderMaterial m;
  if (options.solid) return m;  // opaque: τ and law not used
  check_tau(options.tau);
  m.opacity = shell_opacity(options.tau);
  m.medium = options.law == OccluderLaw::Medium;
  if (m.medium) m.slice = MediumTable::get().slice(options.tau);
  return m;
}

// === OccluderField
OccluderField::OccluderField(std::vector<Ellipsoid> shells, const OccluderOptions& options,
                             std::vector<std::int32_t> groups)
    : shells_(std::move(shells)), groups_(std::move(groups)) {
  if (!groups_.empty()) {
    if (groups_.size() != shells_.size()) {
      throw std::invalid_argument("groups must be empty or one per shell, got " +
                                  std::to_string(groups_.size()) + " for " +
                                  std::to_string(shells_.size()) + " shells");
    }
    for (std::int32_t g : groups_) {
      if (g < 0) throw std::invalid_argument("groups must be >= 0, got " + std::to_string(g));
    }
  }
  if (!std::isfinite(options.epsilon) || options.epsilon < 0 || options.epsilon >= 1) {
    throw std::invalid_argument("epsilon must be in [0, 1), got " +
                                std::to_string(options.epsilon));
  }
  for (const Ellipsoid& s : shells_) check_ellipsoid(s);
  if (!(options.distance > 0)) {  // also NaN
    throw std::invalid_argument("distance must be > 0 (inf = unlimited), got " +
                                std::to_string(options.distance));
  }
  distance_ = options.distance;
  material_ = OccluderMaterial::of(options);  // outside any parallel body (the medium table)
  const std::size_t n = shells_.size();
  if (n >= std::numeric_limits<std::uint32_t>::max()) throw std::invalid_argument("too many shells");
  far_.resize(n);
  rmax_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    rmax_[i] = std::max({shells_[i].radii.x, shells_[i].radii.y, shells_[i].radii.z});
  }

  const bool limited = distance_ < std::numeric_limits<float>::infinity();
  if ((options.epsilon == 0 && !limited) || n == 0) {
    // No cut-off: a single list of everything, used for every receiver.
    unbounded_ = true;
    std::fill(far_.begin(), far_.end(), std::numeric_limits<float>::infinity());
    items_.resize(n);
    for (std::size_t i = 0; i < n; ++i) items_[i] = static_cast<std::uint32_t>(i);
    cell_start_ = {0, static_cast<std::uint32_t>(n)};
    max_candidates_ = n;
    return;
  }

  // Shanmugam–Arikan Eq. 5 with the shell's largest radius (r_eq ≤ r_max), and the AO
  // distance: nothing beyond D + r_max is reached.
  const double e = static_cast<double>(options.epsilon) / (2.0 * kPi);
  const double sin_far = options.epsilon > 0 ? std::sqrt(1.0 - (1.0 - e) * (1.0 - e)) : 0.0;
  Vec3 lo{std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
          std::numeric_limits<float>::max()};
  Vec3 hi = -lo;
  for (std::size_t i = 0; i < n; ++i) {
    const Ellipsoid& s = shells_[i];
    const float rmax = std::max({s.radii.x, s.radii.y, s.radii.z});
    const double eps_far = sin_far > 0 ? rmax / sin_far : std::numeric_limits<double>::infinity();
    far_[i] = static_cast<float>(std::min(eps_far, static_cast<double>(distance_) + rmax));
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], s.center[k] - far_[i]);
      hi[k] = std::max(hi[k], s.center[k] + far_[i]);
    }
  }
  // Cell ≈ the median reach, so an occluder covers ~3³ cells and a cell's list holds the
  // occluders that can reach it; grown until the grid fits the memory bound.
  std::vector<float> sorted = far_;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  double cell = std::max(static_cast<double>(sorted[n / 2]), 1e-6);
  std::size_t cells = 0;
  for (;;) {
    cells = 1;
    bool fits = true;
    for (int k = 0; k < 3; ++k) {
      const double cnt = std::ceil((static_cast<double>(hi[k]) - lo[k]) / cell);
      if (cnt > kMaxDim) fits = false;
      dims_[k] = std::max(1, static_cast<int>(std::min(cnt, double(kMaxDim))));
      cells *= static_cast<std::size_t>(dims_[k]);
    }
    if (fits && cells <= kMaxCells) break;
    cell *= 1.25;
  }
  lo_ = lo;
  inv_cell_ = static_cast<float>(1.0 / cell);

  // CSR fill in two passes: count, then place. Cells are kept only if the occluder's reach
  // sphere touches the cell box.
  auto for_cells = [&](std::size_t i, auto&& fn) {
    const Ellipsoid& s = shells_[i];
    int a[3], b[3];
    for (int k = 0; k < 3; ++k) {
      a[k] = std::clamp(static_cast<int>(std::floor((s.center[k] - far_[i] - lo_[k]) * inv_cell_)),
                        0, dims_[k] - 1);
      b[k] = std::clamp(static_cast<int>(std::floor((s.center[k] + far_[i] - lo_[k]) * inv_cell_)),
                        0, dims_[k] - 1);
    }
    const double r2 = static_cast<double>(far_[i]) * far_[i];
    for (int z = a[2]; z <= b[2]; ++z)
      for (int y = a[1]; y <= b[1]; ++y)
        for (int x = a[0]; x <= b[0]; ++x) {
          const int idx[3] = {x, y, z};
          double dd = 0;
          for (int k = 0; k < 3; ++k) {
            const double blo = lo_[k] + idx[k] * cell, bhi = blo + cell;
            const double c = s.center[k];
            const double t = c < blo ? blo - c : (c > bhi ? c - bhi : 0.0);
            dd += t * t;
          }
          if (dd <= r2) fn((static_cast<std::size_t>(z) * dims_[1] + y) * dims_[0] + x);
        }
  };
  std::vector<std::size_t> count(cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) for_cells(i, [&](std::size_t c) { ++count[c + 1]; });
  for (std::size_t c = 0; c < cells; ++c) {
    max_candidates_ = std::max(max_candidates_, count[c + 1]);
    count[c + 1] += count[c];
  }
  if (count[cells] >= std::numeric_limits<std::uint32_t>::max()) {
    throw Error("occluder grid too large");
  }
  cell_start_.assign(count.begin(), count.end());
  items_.resize(count[cells]);
  std::vector<std::size_t> fill(count.begin(), count.end() - 1);
  for (std::size_t i = 0; i < n; ++i)
    for_cells(i, [&](std::size_t c) { items_[fill[c]++] = static_cast<std::uint32_t>(i); });
}

// material_of(i): shell i's material, or nullptr to leave the shell out.
template <class MaterialOf>
float OccluderField::visit(Vec3 x, Vec3 n, MaterialOf&& material_of) const {
  std::size_t cell = 0;
  if (!unbounded_) {
    int idx[3];
    for (int k = 0; k < 3; ++k) {
      const float t = std::floor((x[k] - lo_[k]) * inv_cell_);
      if (!(t >= 0 && t < static_cast<float>(dims_[k]))) return 1.0f;  // beyond every reach
      idx[k] = static_cast<int>(t);
    }
    cell = (static_cast<std::size_t>(idx[2]) * dims_[1] + idx[1]) * dims_[0] + idx[0];
  }
  const float nn = dot(n, n);
  if (!(nn > 1e-30f)) return 1.0f;  // zero normal: every occluder is "below the horizon"
  const Vec3 nu = n / std::sqrt(nn);
  float v = 1.0f;
  for (std::uint32_t j = cell_start_[cell]; j < cell_start_[cell + 1]; ++j) {
    const std::uint32_t i = items_[j];
    const Vec3 dv = shells_[i].center - x;
    if (dot(dv, dv) > far_[i] * far_[i]) continue;  // Shanmugam–Arikan cut-off
    // Bounding sphere wholly below the tangent plane (cos θ ≤ −sin σ): blocks nothing. Cheap,
    // and it removes about half the pairs before any transcendental function.
    if (dot(nu, dv) <= -rmax_[i]) continue;
    const OccluderMaterial* m = material_of(i);
    if (m == nullptr) continue;
    v *= m->medium ? occluder_visibility_medium(x, nu, shells_[i], m->slice, distance_)
                   : occluder_visibility(x, nu, shells_[i], m->opacity, distance_);  // Π (1 − occ_i)
  }
  return v;
}

float OccluderField::visibility(Vec3 x, Vec3 n) const {
  return visit(x, n, [this](std::uint32_t) -> const OccluderMaterial* { return &material_; });
}

float OccluderField::visibility(Vec3 x, Vec3 n, const OccluderMaterial* const* by_group,
                                std::int32_t skip) const {
  return visit(x, n, [&](std::uint32_t i) -> const OccluderMaterial* {
    const std::int32_t g = group(i);
    return g == skip ? nullptr : by_group[g];
  });
}

float OccluderField::visibility(Vec3 x, Vec3 n, std::int32_t skip) const {
  return visit(x, n, [&](std::uint32_t i) -> const OccluderMaterial* {
    return group(i) == skip ? nullptr : &material_;
  });
}

void OccluderField::ao(PointsView positions, PointsView normals, float* out) const {
  check_receivers(positions, normals);
  parallel_for_blocks(positions.size, 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) out[i] = visibility(positions[i], normals[i]);
  });
}

void ao_occluders(PointsView positions, PointsView normals, const std::vector<Ellipsoid>& shells,
                  const OccluderOptions& options, float* out) {
  check_receivers(positions, normals);
  OccluderField(shells, options).ao(positions, normals, out);
}

}  // namespace canopy_ao
