// Canopy AO — minimum-volume enclosing ellipsoid (Khachiyan / Todd–Yildirim) with a PCA fallback.
#include "canopy_ao/ellipsoid_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "canopy_ao/parallel.h"
#include "canopy_ao/sphere_fit.h"
#include "fit_detail.h"

namespace canopy_ao {

namespace {

using namespace fit_detail;

void check_options(const EllipsoidFitOptions& o) {
  check_trim(o.trim);
  std::ostringstream s;
  if (!(o.tolerance > 0 && o.tolerance < 1)) {
    s << "tolerance must be in (0, 1), got " << o.tolerance;
  } else if (o.max_points < 4) {
    s << "max_points must be >= 4, got " << o.max_points;
  } else if (!(o.min_radius_ratio > 0 && o.min_radius_ratio <= 1)) {
    s << "min_radius_ratio must be in (0, 1], got " << o.min_radius_ratio;
  } else if (o.max_iterations < 1) {
    s << "max_iterations must be >= 1, got " << o.max_iterations;
  } else {
    return;
  }
  throw std::invalid_argument(s.str());
}

// Gauss–Jordan inverse of an n×n matrix (n ≤ 4) with partial pivoting; false if singular
// relative to its largest entry.
bool invert(int n, const double a_in[4][4], double inv[4][4]) {
  double a[4][8];
  double scale = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      a[i][j] = a_in[i][j];
      a[i][n + j] = i == j ? 1 : 0;
      scale = std::max(scale, std::abs(a_in[i][j]));
    }
  if (!(scale > 0) || !std::isfinite(scale)) return false;
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int r = c + 1; r < n; ++r)
      if (std::abs(a[r][c]) > std::abs(a[piv][c])) piv = r;
    if (!(std::abs(a[piv][c]) > 1e-14 * scale)) return false;
    if (piv != c)
      for (int j = 0; j < 2 * n; ++j) std::swap(a[c][j], a[piv][j]);
    const double d = 1 / a[c][c];
    for (int j = 0; j < 2 * n; ++j) a[c][j] *= d;
    for (int r = 0; r < n; ++r) {
      if (r == c || a[r][c] == 0) continue;
      const double f = a[r][c];
      for (int j = 0; j < 2 * n; ++j) a[r][j] -= f * a[c][j];
    }
  }
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) inv[i][j] = a[i][n + j];
  return true;
}

// An ellipsoid in the normalised d-dimensional frame: { z : (z − c)ᵀ A (z − c) ≤ 1 }.
struct LocalEllipsoid {
  int d = 3;
  double c[3] = {0, 0, 0};
  double A[3][3] = {};
  double g(const P3& z) const {
    double y[3], s = 0;
    for (int i = 0; i < d; ++i) y[i] = z[i] - c[i];
    for (int i = 0; i < d; ++i)
      for (int j = 0; j < d; ++j) s += y[i] * A[i][j] * y[j];
    return s;
  }
  double det() const {
    if (d == 1) return A[0][0];
    if (d == 2) return A[0][0] * A[1][1] - A[0][1] * A[1][0];
    return A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
           A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
           A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
  }
  void scale(double s) {  // A /= s
    for (int i = 0; i < d; ++i)
      for (int j = 0; j < d; ++j) A[i][j] /= s;
  }
};

// Khachiyan's algorithm with Todd–Yildirim away steps on points z (first d coordinates used).
// Lifted points q = (z, 1); weights u on the simplex; X(u) = Σ uᵢ qᵢ qᵢᵀ; Mᵢ = qᵢᵀ X⁻¹ qᵢ.
// INV: Σ u = 1, u ≥ 0. Returns false if X became singular (affinely dependent active set).
// u_io: null (start from equal weights), or the start weights (m values, sum 1), which are
// replaced by the final ones.
bool khachiyan(const std::vector<P3>& z, int d, double tol, int max_iter, LocalEllipsoid* out,
               int* iterations, bool* converged, std::vector<double>* u_io = nullptr) {
  const int m = static_cast<int>(z.size());
  const int D = d + 1;
  std::vector<double> u(m, 1.0 / m), M(m);
  if (u_io != nullptr && static_cast<int>(u_io->size()) == m) u = *u_io;
  *converged = false;
  int it = 0;
  for (;; ++it) {
    double X[4][4] = {}, Xi[4][4];
    for (int i = 0; i < m; ++i) {
      double q[4];
      for (int k = 0; k < d; ++k) q[k] = z[i][k];
      q[d] = 1;
      for (int r = 0; r < D; ++r)
        for (int c = 0; c < D; ++c) X[r][c] += u[i] * q[r] * q[c];
    }
    if (!invert(D, X, Xi)) return false;
    int j = 0, l = -1;
    for (int i = 0; i < m; ++i) {
      double q[4], s = 0;
      for (int k = 0; k < d; ++k) q[k] = z[i][k];
      q[d] = 1;
      for (int r = 0; r < D; ++r)
        for (int c = 0; c < D; ++c) s += q[r] * Xi[r][c] * q[c];
      M[i] = s;
      if (s > M[j]) j = i;
      if (u[i] > 0 && (l < 0 || s < M[l])) l = i;
    }
    if (!std::isfinite(M[j])) return false;
    const double eps_plus = M[j] / D - 1, eps_minus = 1 - M[l] / D;
    if (eps_plus <= tol && eps_minus <= tol) {
      *converged = true;
      break;
    }
    if (it >= max_iter) break;
    if (eps_plus >= eps_minus) {
      // Khachiyan's step towards the most violated point (closed-form line search).
      const double beta = (M[j] - D) / (D * (M[j] - 1));
      for (double& w : u) w *= 1 - beta;
      u[j] += beta;
    } else {
      // Away step from the weighted point that is deepest inside (Todd–Yildirim).
      const double drop = u[l] / (1 - u[l]);
      const double beta = M[l] - 1 > 1e-12 ? std::min((D - M[l]) / (D * (M[l] - 1)), drop) : drop;
      for (double& w : u) w *= 1 + beta;
      u[l] -= beta;
      if (u[l] < 0) u[l] = 0;
    }
  }
  *iterations += it;
  if (u_io != nullptr) *u_io = u;
  // Centre c = Σ uᵢ zᵢ; shape A = (Σ uᵢ zᵢ zᵢᵀ − c cᵀ)⁻¹ / d.
  double c[3] = {0, 0, 0}, S[4][4] = {}, Si[4][4];
  for (int i = 0; i < m; ++i)
    for (int k = 0; k < d; ++k) c[k] += u[i] * z[i][k];
  for (int i = 0; i < m; ++i)
    for (int r = 0; r < d; ++r)
      for (int s = 0; s < d; ++s) S[r][s] += u[i] * (z[i][r] - c[r]) * (z[i][s] - c[s]);
  if (!invert(d, S, Si)) return false;
  out->d = d;
  for (int r = 0; r < d; ++r) {
    out->c[r] = c[r];
    for (int s = 0; s < d; ++s) out->A[r][s] = Si[r][s] / d;
  }
  return true;
}

// Points extreme along fixed directions (in the normalised frame, where the cloud is roughly
// round): a cheap superset-of-a-core-set for Khachiyan. Lowest index wins ties.
std::vector<int> extreme_points(const std::vector<P3>& z, int d) {
  std::vector<P3> dirs;
  if (d == 1) {
    dirs = {{1, 0, 0}, {-1, 0, 0}};
  } else if (d == 2) {
    for (int i = 0; i < 64; ++i) {
      const double a = 2 * M_PI * i / 64;
      dirs.push_back({std::cos(a), std::sin(a), 0});
    }
  } else {
    // Fibonacci sphere: 128 near-uniform directions, plus the 6 axis directions.
    const int n = 128;
    const double golden = M_PI * (3 - std::sqrt(5.0));
    for (int i = 0; i < n; ++i) {
      const double y = 1 - 2 * (i + 0.5) / n, r = std::sqrt(1 - y * y), t = golden * i;
      dirs.push_back({r * std::cos(t), y, r * std::sin(t)});
    }
    for (int k = 0; k < 3; ++k)
      for (double s : {1.0, -1.0}) {
        P3 e{0, 0, 0};
        e[k] = s;
        dirs.push_back(e);
      }
  }
  std::vector<int> best(dirs.size(), 0);
  std::vector<double> val(dirs.size(), -INFINITY);
  for (int i = 0; i < static_cast<int>(z.size()); ++i)
    for (std::size_t k = 0; k < dirs.size(); ++k) {
      const double v = z[i][0] * dirs[k][0] + z[i][1] * dirs[k][1] + z[i][2] * dirs[k][2];
      if (v > val[k]) {
        val[k] = v;
        best[k] = i;
      }
    }
  std::sort(best.begin(), best.end());
  best.erase(std::unique(best.begin(), best.end()), best.end());
  return best;
}

// Largest g over all points, in parallel with a thread-count-independent max.
// Largest of fn(i) over i in [0, n), ≥ 0: parallel blocks of a fixed size, so the result does
// not depend on the thread count.
template <class Fn>
double parallel_max(std::size_t n, const Fn& fn) {
  constexpr std::size_t grain = 1 << 14;
  std::vector<double> block((n + grain - 1) / grain, 0.0);
  parallel_for_blocks(n, grain, [&](std::size_t b, std::size_t en) {
    double mx = 0;
    for (std::size_t i = b; i < en; ++i) mx = std::max(mx, fn(i));
    block[b / grain] = mx;
  });
  double mx = 0;
  for (double x : block) mx = std::max(mx, x);
  return mx;
}

// Mean and covariance of points[idx]: per-block sums (fixed blocks, added in block order, so
// the result does not depend on the thread count), two streaming passes.
void mean_cov(PointsView points, const std::vector<std::size_t>& idx, P3* mean, double cov[3][3]) {
  constexpr std::size_t grain = 1 << 14;
  const std::size_t n = idx.size(), blocks = (n + grain - 1) / grain;
  std::vector<std::array<double, 9>> part(blocks);
  parallel_for_blocks(n, grain, [&](std::size_t b, std::size_t e) {
    double m[3] = {0, 0, 0};
    for (std::size_t i = b; i < e; ++i) {
      const P3 p = to_p3(points[idx[i]]);
      for (int k = 0; k < 3; ++k) m[k] += p[k];
    }
    for (int k = 0; k < 3; ++k) part[b / grain][k] = m[k];
  });
  P3 m{0, 0, 0};
  for (const auto& q : part)
    for (int k = 0; k < 3; ++k) m[k] += q[k];
  for (int k = 0; k < 3; ++k) m[k] /= double(n);
  parallel_for_blocks(n, grain, [&](std::size_t b, std::size_t e) {
    double c[3][3] = {};
    const P3 mm = m;
    for (std::size_t i = b; i < e; ++i) {
      const P3 p = to_p3(points[idx[i]]);
      const double d[3] = {p[0] - mm[0], p[1] - mm[1], p[2] - mm[2]};
      for (int r = 0; r < 3; ++r)
        for (int cc = 0; cc < 3; ++cc) c[r][cc] += d[r] * d[cc];
    }
    for (int r = 0; r < 3; ++r)
      for (int cc = 0; cc < 3; ++cc) part[b / grain][3 * r + cc] = c[r][cc];
  });
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) cov[r][c] = 0;
  for (const auto& q : part)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) cov[r][c] += q[3 * r + c];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) cov[r][c] /= double(n);
  *mean = m;
}

}  // namespace

void symmetric_eigen(int n, const double a_in[3][3], double w[3], double v[3][3]) {
  double a[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      a[i][j] = i < n && j < n ? a_in[i][j] : 0;
      v[i][j] = i == j ? 1 : 0;
    }
  // Cyclic Jacobi: each rotation zeroes one off-diagonal entry; converges quadratically.
  for (int sweep = 0; sweep < 64; ++sweep) {
    double off = 0, diag = 0;
    for (int i = 0; i < n; ++i) {
      diag += a[i][i] * a[i][i];
      for (int j = i + 1; j < n; ++j) off += a[i][j] * a[i][j];
    }
    if (off <= 1e-30 * diag || off == 0) break;
    for (int p = 0; p < n; ++p)
      for (int q = p + 1; q < n; ++q) {
        if (a[p][q] == 0) continue;
        const double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
        const double t = (theta >= 0 ? 1 : -1) / (std::abs(theta) + std::sqrt(theta * theta + 1));
        const double c = 1 / std::sqrt(t * t + 1), s = t * c;
        for (int k = 0; k < n; ++k) {  // A ← A J
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < n; ++k) {  // A ← Jᵀ A
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < n; ++k) {  // V ← V J
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
  }
  // Sort descending, columns of v along.
  int order[3] = {0, 1, 2};
  for (int i = 1; i < n; ++i)  // insertion sort, descending, on ≤ 3 entries
    for (int j = i; j > 0 && a[order[j]][order[j]] > a[order[j - 1]][order[j - 1]]; --j)
      std::swap(order[j], order[j - 1]);
  double vv[3][3];
  for (int k = 0; k < 3; ++k) {
    w[k] = k < n ? a[order[k]][order[k]] : 0;
    for (int i = 0; i < 3; ++i) vv[i][k] = k < n ? v[i][order[k]] : (i == k ? 1 : 0);
  }
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) v[i][k] = vv[i][k];
}

std::vector<std::size_t> ellipsoid_trimmed_indices(PointsView points, double trim) {
  check_fit_points(points);
  check_trim(trim);
  std::vector<std::size_t> first = trimmed_indices(points, trim);
  const std::size_t n = points.size;
  const std::size_t drop = static_cast<std::size_t>(std::floor(trim * double(n)));
  if (drop == 0 || first.size() <= 1) return first;
  P3 mean;
  double cov[3][3], w[3], v[3][3];
  mean_cov(points, first, &mean, cov);
  symmetric_eigen(3, cov, w, v);
  if (!(w[0] > 0)) return first;  // all kept points coincide
  for (double& x : w) x = std::max(x, 1e-4 * w[0]);
  std::vector<std::pair<double, std::size_t>> d(n);
  for (std::size_t i = 0; i < n; ++i) {
    const P3 p = to_p3(points[i]);
    double m2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double y = v[0][k] * (p[0] - mean[0]) + v[1][k] * (p[1] - mean[1]) +
                       v[2][k] * (p[2] - mean[2]);
      m2 += y * y / w[k];
    }
    d[i] = {m2, i};
  }
  const std::size_t kept = n - drop;
  std::nth_element(d.begin(), d.begin() + (kept - 1), d.end());
  std::vector<std::size_t> keep(kept);
  for (std::size_t i = 0; i < kept; ++i) keep[i] = d[i].second;
  std::sort(keep.begin(), keep.end());
  return keep;
}

Ellipsoid fit_min_ellipsoid(PointsView points, const EllipsoidFitOptions& options,
                            EllipsoidFitInfo* info, EllipsoidWarmStart* warm) {
  check_fit_points(points);
  check_options(options);
  std::vector<std::size_t> idx;
  if (options.trim > 0) {
    idx = ellipsoid_trimmed_indices(points, options.trim);
  } else {
    idx.resize(points.size);
    for (std::size_t i = 0; i < points.size; ++i) idx[i] = i;
  }
  EllipsoidFitOptions o = options;
  o.trim = 0;
  return fit_min_ellipsoid(points, idx, o, info, warm);
}

Ellipsoid fit_min_ellipsoid(PointsView points, const std::vector<std::size_t>& indices,
                            const EllipsoidFitOptions& options, EllipsoidFitInfo* info_out,
                            EllipsoidWarmStart* warm) {
  check_options(options);
  if (indices.empty()) throw std::invalid_argument("points is empty");
  for (std::size_t i : indices) {
    if (i >= points.size) throw std::invalid_argument("fit_min_ellipsoid: index out of range");
    if (!is_finite(points[i])) {
      std::ostringstream s;
      s << "points has a non-finite value (NaN or inf) at row " << i;
      throw std::invalid_argument(s.str());
    }
  }
  EllipsoidFitInfo info;
  const std::size_t n = indices.size();

  // 1. PCA frame: mean, covariance eigenvectors V (columns), box in that frame.
  P3 mean;
  double cov[3][3], w[3], V[3][3];
  mean_cov(points, indices, &mean, cov);
  symmetric_eigen(3, cov, w, V);
  // A point's coordinates in the PCA frame, computed where needed (streaming passes over the
  // points, no per-point copies: the fit must cost little beside reading the mesh).
  auto frame_y = [&](std::size_t i) {
    const P3 p = to_p3(points[indices[i]]);
    P3 y;
    for (int k = 0; k < 3; ++k)
      y[k] = V[0][k] * (p[0] - mean[0]) + V[1][k] * (p[1] - mean[1]) + V[2][k] * (p[2] - mean[2]);
    return y;
  };
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  {
    constexpr std::size_t grain = 1 << 14;
    std::vector<std::array<double, 6>> box((n + grain - 1) / grain);
    parallel_for_blocks(n, grain, [&](std::size_t b, std::size_t e) {
      std::array<double, 6> bx = {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY};
      for (std::size_t i = b; i < e; ++i) {
        const P3 y = frame_y(i);
        for (int k = 0; k < 3; ++k) {
          bx[k] = std::min(bx[k], y[k]);
          bx[3 + k] = std::max(bx[3 + k], y[k]);
        }
      }
      box[b / grain] = bx;
    });
    for (const auto& bx : box)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], bx[k]);
        hi[k] = std::max(hi[k], bx[3 + k]);
      }
  }
  double b[3], h[3], hmax = 0;
  for (int k = 0; k < 3; ++k) {
    b[k] = 0.5 * (lo[k] + hi[k]);
    h[k] = 0.5 * (hi[k] - lo[k]);
    hmax = std::max(hmax, h[k]);
  }
  Vec3 mean_f{float(mean[0]), float(mean[1]), float(mean[2])};
  const double floor_abs = min_proxy_radius(mean_f);

  // 2. Intrinsic dimension: axes whose half-extent is ≤ 1e-3 of the largest are degenerate.
  int dims[3], d = 0;
  if (hmax > 0.5 * floor_abs)
    for (int k = 0; k < 3; ++k)
      if (h[k] > 1e-3 * hmax) dims[d++] = k;
  info.dimension = d;

  // (centre in the PCA frame y, then (radius, unit axis in world) pairs)
  double yc[3] = {b[0], b[1], b[2]};
  std::array<std::pair<double, P3>, 3> ax;
  for (int k = 0; k < 3; ++k) ax[k] = {0.0, P3{V[0][k], V[1][k], V[2][k]}};

  if (d > 0) {
    // 3. Normalised frame z = (y − b) / h on the non-degenerate axes.
    auto frame_z = [&](std::size_t i) {
      const P3 y = frame_y(i);
      P3 z{0, 0, 0};
      for (int j = 0; j < d; ++j) z[j] = (y[dims[j]] - b[dims[j]]) / h[dims[j]];
      return z;
    };
    auto max_g = [&](const LocalEllipsoid& e) {
      if (d == 3 && e.d == 3) {  // the usual case with fixed loop bounds (it unrolls): the
        // same operations in the same order as frame_z and LocalEllipsoid::g
        const LocalEllipsoid el = e;
        return parallel_max(n, [&](std::size_t i) {
          const P3 y = frame_y(i);
          double u[3], g = 0;
          for (int k = 0; k < 3; ++k) u[k] = (y[k] - b[k]) / h[k] - el.c[k];
          for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) g += u[r] * el.A[r][c] * u[c];
          return g;
        });
      }
      return parallel_max(n, [&](std::size_t i) { return e.g(frame_z(i)); });
    };
    // PCA ellipsoid: the box's aspect, scaled to contain every point.
    LocalEllipsoid pca;
    pca.d = d;
    for (int j = 0; j < d; ++j) pca.A[j][j] = 1;
    pca.scale(std::max(max_g(pca), 1e-300));
    LocalEllipsoid best = pca;
    info.method_used = EllipsoidMethod::Pca;

    if (options.method != EllipsoidMethod::Pca) {
      // 4. Khachiyan on an active set drawn from a stride subsample.
      std::vector<std::size_t> pool;
      const std::size_t np = std::min(n, options.max_points);
      for (std::size_t j = 0; j < np; ++j) pool.push_back(j * n / np);
      std::vector<P3> zp(np);
      for (std::size_t j = 0; j < np; ++j) zp[j] = frame_z(pool[j]);
      // A warm start (the previous frame's support and weights) where it fits these points;
      // else the extreme points with equal weights.
      bool warmed = warm != nullptr && warm->points == n && warm->pool == np &&
                          warm->dimension == d && warm->active.size() > static_cast<std::size_t>(d) &&
                          warm->weights.size() == warm->active.size() &&
                          std::all_of(warm->active.begin(), warm->active.end(),
                                      [&](int a) { return a >= 0 && static_cast<std::size_t>(a) < np; });
      std::vector<int> active = warmed ? warm->active : extreme_points(zp, d);
      // Weights over `active`: the warm path carries them between rounds; the cold one starts
      // each round from equal ones (1/m, as khachiyan would) and keeps only the last round's.
      std::vector<double> u;
      if (warmed) u = warm->weights;
      std::vector<char> in_active(np, 0);
      for (int a : active) in_active[a] = 1;
      LocalEllipsoid kh;
      bool ok = false, conv = false;
      const double slack = 1 + (d + 1.0) / d * options.tolerance;
      for (int round = 0; round < 50; ++round) {
        std::vector<P3> za;
        for (int a : active) za.push_back(zp[a]);
        if (!warmed) u.assign(za.size(), 1.0 / std::max<std::size_t>(za.size(), 1));
        ok = static_cast<int>(za.size()) > d &&
             khachiyan(za, d, options.tolerance, options.max_iterations, &kh, &info.iterations,
                       &conv, &u);
        if (!ok && warmed) {  // a support that no longer spans: start afresh
          warmed = false;
          active = extreme_points(zp, d);
          std::fill(in_active.begin(), in_active.end(), 0);
          for (int a : active) in_active[a] = 1;
          round = -1;
          continue;
        }
        if (!ok) break;
        // The subsample's worst violators join the active set (≤ 64 a round).
        std::vector<std::pair<double, int>> viol;
        for (std::size_t j = 0; j < np; ++j) {
          if (in_active[j]) continue;
          const double g = kh.g(zp[j]);
          if (g > slack) viol.push_back({-g, static_cast<int>(j)});
        }
        if (viol.empty() || active.size() >= options.max_points) break;
        const std::size_t take = std::min<std::size_t>({viol.size(), 64, options.max_points - active.size()});
        std::partial_sort(viol.begin(), viol.begin() + take, viol.end());
        for (std::size_t t = 0; t < take; ++t) {
          active.push_back(viol[t].second);
          in_active[viol[t].second] = 1;
          if (warmed) u.push_back(0.0);  // joins with no weight: u stays on the simplex
        }
        if (!warmed) std::sort(active.begin(), active.end());
      }
      if (warm != nullptr) {  // the support for the next fit (weights > 0, renormalised)
        *warm = EllipsoidWarmStart{};
        if (ok && u.size() == active.size()) {  // u: the last round's weights
          const std::vector<double>& uf = u;
          double sum = 0;
          for (std::size_t a = 0; a < uf.size(); ++a)
            if (uf[a] > 1e-12) sum += uf[a];
          if (sum > 0) {
            warm->points = n, warm->pool = np, warm->dimension = d;
            for (std::size_t a = 0; a < uf.size(); ++a)
              if (uf[a] > 1e-12) {
                warm->active.push_back(active[a]);
                warm->weights.push_back(uf[a] / sum);
              }
          }
        }
      }
      info.active_points = active.size();
      info.converged = ok && conv;
      if (ok) {
        const double g = max_g(kh);
        if (std::isfinite(g) && g > 0) {
          info.containment_scale = std::sqrt(g);
          kh.scale(g);
          const bool finite = std::isfinite(kh.det()) && kh.det() > 0;
          if (finite && (options.method == EllipsoidMethod::Khachiyan || kh.det() >= pca.det())) {
            best = kh;
            info.method_used = EllipsoidMethod::Khachiyan;
          }
        }
      }
    }

    // 5. Back to the PCA frame: y = b + diag(h) z, so A_y = diag(1/h) A diag(1/h).
    double Ay[3][3], ew[3], ev[3][3];
    for (int r = 0; r < d; ++r) {
      yc[dims[r]] = b[dims[r]] + h[dims[r]] * best.c[r];
      for (int s = 0; s < d; ++s) Ay[r][s] = best.A[r][s] / (h[dims[r]] * h[dims[s]]);
    }
    symmetric_eigen(d, Ay, ew, ev);
    std::array<std::pair<double, P3>, 3> nd;
    int slot = 0;
    for (int j = 0; j < d; ++j) {
      P3 a{0, 0, 0};
      for (int r = 0; r < d; ++r)
        for (int k = 0; k < 3; ++k) a[k] += ev[r][j] * V[k][dims[r]];
      nd[slot++] = {1 / std::sqrt(std::max(ew[j], 1e-300)), a};
    }
    for (int k = 0; k < 3; ++k) {
      bool degenerate = true;
      for (int j = 0; j < d; ++j) degenerate &= dims[j] != k;
      if (degenerate) nd[slot++] = {0.0, P3{V[0][k], V[1][k], V[2][k]}};
    }
    ax = nd;
  }

  // 6. Assemble: centre, axes sorted by radius, orthonormal right-handed, clamped radii.
  double cw[3];
  for (int k = 0; k < 3; ++k)
    cw[k] = mean[k] + V[k][0] * yc[0] + V[k][1] * yc[1] + V[k][2] * yc[2];
  std::stable_sort(ax.begin(), ax.end(), [](const auto& p, const auto& q) { return p.first > q.first; });
  auto dotp = [](const P3& a, const P3& c) { return a[0] * c[0] + a[1] * c[1] + a[2] * c[2]; };
  auto unit = [&](P3 a) {
    const double l = std::sqrt(dotp(a, a));
    return P3{a[0] / l, a[1] / l, a[2] / l};
  };
  P3 a0 = unit(ax[0].second), a1 = ax[1].second;
  const double p01 = dotp(a0, a1);
  a1 = unit({a1[0] - p01 * a0[0], a1[1] - p01 * a0[1], a1[2] - p01 * a0[2]});
  const P3 a2{a0[1] * a1[2] - a0[2] * a1[1], a0[2] * a1[0] - a0[0] * a1[2],
              a0[0] * a1[1] - a0[1] * a1[0]};
  Ellipsoid e;
  e.center = round_to_vec3(cw);
  const double fa = min_proxy_radius(e.center);
  double r[3];
  for (int k = 0; k < 3; ++k)
    r[k] = std::max({ax[k].first, options.min_radius_ratio * ax[0].first, fa});
  const P3 axes[3] = {a0, a1, a2};
  for (int k = 0; k < 3; ++k) e.axes[k] = round_to_vec3(axes[k].data());

  // 7. Containment certificate on the rounded ellipsoid, in double: inflate if needed.
  const P3 c = to_p3(e.center);
  const P3 ea[3] = {to_p3(e.axes[0]), to_p3(e.axes[1]), to_p3(e.axes[2])};
  const double gmax = parallel_max(n, [&](std::size_t i) {
    const P3 p = to_p3(points[indices[i]]);
    const P3 dp{p[0] - c[0], p[1] - c[1], p[2] - c[2]};
    double g = 0;
    for (int k = 0; k < 3; ++k) {
      const double u = dotp(ea[k], dp) / r[k];
      g += u * u;
    }
    return g;
  });
  const double s = std::max(1.0, std::sqrt(gmax)) * (1 + 1e-6);
  for (int k = 0; k < 3; ++k) {
    const double rk = r[k] * s;
    float rf = static_cast<float>(rk);
    if (double(rf) < rk) rf = std::nextafter(rf, std::numeric_limits<float>::infinity());
    e.radii[k] = rf;
  }
  if (info_out) *info_out = info;
  return e;
}

double max_unit_norm2(const Ellipsoid& e, PointsView points) {
  const P3 c = to_p3(e.center);
  double gmax = 0;
  for (std::size_t i = 0; i < points.size; ++i) {
    const P3 p = to_p3(points[i]);
    double g = 0;
    for (int k = 0; k < 3; ++k) {
      const P3 a = to_p3(e.axes[k]);
      const double u =
          (a[0] * (p[0] - c[0]) + a[1] * (p[1] - c[1]) + a[2] * (p[2] - c[2])) / double(e.radii[k]);
      g += u * u;
    }
    gmax = std::max(gmax, g);
  }
  return gmax;
}

bool contains_all(const Ellipsoid& e, PointsView points, double rel_tol) {
  return max_unit_norm2(e, points) <= 1 + rel_tol;
}

}  // namespace canopy_ao
