// Canopy AO — k shells by k-means++ / Lloyd, one fitted proxy per cluster.
#include "canopy_ao/shells.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "canopy_ao/parallel.h"
#include "canopy_ao/sphere_fit.h"
#include "fit_detail.h"

namespace canopy_ao {

namespace {

using namespace fit_detail;

double dist2(Vec3 a, const P3& c) { return fit_detail::dist2(to_p3(a), c); }

constexpr std::size_t kGrain = 4096;

}  // namespace

ShellFit fit_shells(PointsView points, const ShellFitOptions& o) {
  check_fit_points(points);
  check_trim(o.trim);
  if (o.k < 1) {
    std::ostringstream s;
    s << "k must be >= 1, got " << o.k;
    throw std::invalid_argument(s.str());
  }
  if (o.max_iterations < 1) throw std::invalid_argument("max_iterations must be >= 1");
  EllipsoidFitOptions eo = o.ellipsoid;
  eo.trim = o.trim;
  // Validate the ellipsoid options up front, not after the clustering work.
  {
    const float one[3] = {0, 0, 0};
    if (o.kind == ShellKind::Ellipsoid) fit_min_ellipsoid(PointsView{one, 1}, eo);
  }

  const std::size_t n = points.size;
  const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(o.k), n);
  SplitMix64 rng{o.seed ^ 0xC0FFEE1234567ull};

  // 1. k-means++ seeding: each new centre drawn with probability ∝ D(x)², D = distance to the
  // nearest centre so far. Stops early when every point is a centre (D² sums to 0).
  std::vector<P3> centres;
  std::vector<double> d2(n);
  auto add_centre = [&](std::size_t i) {
    const Vec3 p = points[i];
    centres.push_back({double(p.x), double(p.y), double(p.z)});
    const P3 c = centres.back();
    const bool first = centres.size() == 1;
    parallel_for_blocks(n, kGrain, [&](std::size_t b, std::size_t e) {
      for (std::size_t j = b; j < e; ++j) {
        const double d = dist2(points[j], c);
        d2[j] = first ? d : std::min(d2[j], d);
      }
    });
  };
  add_centre(static_cast<std::size_t>(rng.next() % n));
  while (centres.size() < k) {
    double total = 0;
    for (double x : d2) total += x;
    if (!(total > 0)) break;
    const double target = rng.uniform() * total;
    double acc = 0;
    std::size_t pick = n;
    for (std::size_t j = 0; j < n; ++j) {
      acc += d2[j];
      if (acc > target && d2[j] > 0) {
        pick = j;
        break;
      }
    }
    if (pick == n)  // round-off at the top end: the last point with D > 0
      for (std::size_t j = n; j-- > 0;)
        if (d2[j] > 0) {
          pick = j;
          break;
        }
    add_centre(pick);
  }
  const std::size_t kc = centres.size();

  // 2. Lloyd iterations. Stop when no label changes, or (scikit-learn's rule) when the summed
  // squared centroid shift drops to 1e-4 × the data's mean per-axis variance — then one last
  // assignment makes the labels match the final centroids.
  double var = 0;
  {
    P3 mean{0, 0, 0};
    for (std::size_t j = 0; j < n; ++j)
      for (int a = 0; a < 3; ++a) mean[a] += points.data[3 * j + a];
    for (double& x : mean) x /= double(n);
    for (std::size_t j = 0; j < n; ++j) var += dist2(points[j], mean);
    var /= 3.0 * double(n);
  }
  const double shift_tol = 1e-4 * var;
  bool settled = false;
  ShellFit out;
  std::vector<std::int32_t> label(n, -1);
  std::vector<double> dist(n);
  for (int it = 0; it < o.max_iterations; ++it) {
    std::vector<char> changed_block((n + kGrain - 1) / kGrain, 0);
    parallel_for_blocks(n, kGrain, [&](std::size_t b, std::size_t e) {
      bool changed = false;
      for (std::size_t j = b; j < e; ++j) {
        const Vec3 p = points[j];
        std::int32_t best = 0;
        double bd = dist2(p, centres[0]);
        for (std::size_t c = 1; c < kc; ++c) {
          const double d = dist2(p, centres[c]);
          if (d < bd) {
            bd = d;
            best = static_cast<std::int32_t>(c);
          }
        }
        changed |= label[j] != best;
        label[j] = best;
        dist[j] = bd;
      }
      changed_block[b / kGrain] = changed;
    });
    out.iterations = it + 1;
    const bool changed =
        std::any_of(changed_block.begin(), changed_block.end(), [](char c) { return c != 0; });
    if ((!changed && it > 0) || settled) {
      out.converged = true;
      break;
    }
    if (it + 1 == o.max_iterations) break;  // labels stay those of the current centroids
    // Update: centroids in double, summed in point order (thread-count independent).
    std::vector<P3> sum(kc, P3{0, 0, 0});
    std::vector<std::size_t> count(kc, 0);
    const std::vector<P3> before = centres;
    for (std::size_t j = 0; j < n; ++j) {
      const Vec3 p = points[j];
      P3& s = sum[label[j]];
      s[0] += p.x;
      s[1] += p.y;
      s[2] += p.z;
      ++count[label[j]];
    }
    for (std::size_t c = 0; c < kc; ++c) {
      if (count[c] > 0) {
        for (int a = 0; a < 3; ++a) centres[c][a] = sum[c][a] / double(count[c]);
        continue;
      }
      // Empty: re-seed at the point farthest from its centroid, taken from a cluster of ≥ 2.
      std::size_t far = n;
      for (std::size_t j = 0; j < n; ++j)
        if (count[label[j]] >= 2 && dist[j] > 0 && (far == n || dist[j] > dist[far])) far = j;
      if (far == n) continue;  // nothing to split: stays empty, dropped below
      const Vec3 p = points[far];
      centres[c] = {double(p.x), double(p.y), double(p.z)};
      --count[label[far]];
      dist[far] = 0;
      label[far] = static_cast<std::int32_t>(c);  // so the next empty cluster picks another
      count[c] = 1;
    }
    double shift = 0;
    for (std::size_t c = 0; c < kc; ++c)
      for (int a = 0; a < 3; ++a) shift += (centres[c][a] - before[c][a]) * (centres[c][a] - before[c][a]);
    settled = shift <= shift_tol;
  }

  // 3. Drop empty clusters, renumber, fit one shell per cluster.
  std::vector<std::vector<float>> members(kc);
  for (std::size_t j = 0; j < n; ++j) {
    const float* p = points.data + 3 * j;
    members[label[j]].insert(members[label[j]].end(), p, p + 3);
  }
  std::vector<std::int32_t> remap(kc, -1);
  for (std::size_t c = 0; c < kc; ++c) {
    if (members[c].empty()) continue;
    remap[c] = static_cast<std::int32_t>(out.shells.size());
    const PointsView view{members[c].data(), members[c].size() / 3};
    if (o.kind == ShellKind::Sphere) {
      out.shells.push_back(Ellipsoid::from_sphere(fit_min_sphere(view, o.trim)));
    } else {
      out.shells.push_back(fit_min_ellipsoid(view, eo));
    }
    P3 m{0, 0, 0};
    for (std::size_t j = 0; j < view.size; ++j)
      for (int a = 0; a < 3; ++a) m[a] += view.data[3 * j + a];
    out.centroids.push_back(Vec3{float(m[0] / double(view.size)), float(m[1] / double(view.size)),
                                 float(m[2] / double(view.size))});
  }
  out.labels.resize(n);
  for (std::size_t j = 0; j < n; ++j) out.labels[j] = remap[label[j]];
  return out;
}

}  // namespace canopy_ao
