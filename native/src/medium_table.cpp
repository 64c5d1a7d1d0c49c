#include "canopy_ao/medium_table.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include "canopy_ao/parallel.h"

namespace canopy_ao {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kTableSamples = 512;  // polar-angle nodes per entry: |ΔAO| ≤ 1.1e-4

// ∫_0^{2π} max(a + b cos φ, 0) dφ with a = μ cosβ, b = sin(θ) sinβ: the cosine lobe max(ω·n, 0)
// integrated over the circle of directions at polar angle θ = acos μ from the radial axis.
inline double azimuth_lobe(double mu, double c, double s) {
  const double a = mu * c;
  const double b = std::sqrt(std::max(0.0, 1.0 - mu * mu)) * s;
  if (a >= b) return 2.0 * kPi * a;
  if (a <= -b) return 0.0;
  const double phi0 = std::acos(-a / b);  // the lobe is positive for |φ| < φ0
  return 2.0 * (a * phi0 + b * std::sin(phi0));
}

// Midpoint nodes over the directions that cross the unit sphere, seen from radius r:
// μ = cos(angle to the outward radial axis), w = solid-angle weight / 2π (the azimuth is done by
// azimuth_lobe), len = chord inside the sphere.
struct Nodes {
  std::vector<double> mu, w, len;
  bool outside = false;
};

Nodes make_nodes(double r, int n) {
  Nodes q;
  q.mu.resize(n);
  q.w.resize(n);
  q.len.resize(n);
  q.outside = r > 1.0;
  if (!q.outside) {
    // Every direction leaves the sphere: L = −rμ + sqrt(1 − r²(1 − μ²)).
    const double dt = kPi / n;
    for (int k = 0; k < n; ++k) {
      const double t = (k + 0.5) * dt;
      const double mu = std::cos(t);
      q.mu[k] = mu;
      q.w[k] = std::sin(t) * dt;
      q.len[k] = -r * mu + std::sqrt(std::max(0.0, 1.0 - r * r * (1.0 - mu * mu)));
    }
  } else {
    // Only the cone of half-angle asin(1/r) around the centre direction meets the sphere;
    // integrate over that cone's angle α (μ = −cos α) so a far sphere still gets all n nodes.
    const double amax = std::asin(1.0 / r);
    const double da = amax / n;
    for (int k = 0; k < n; ++k) {
      const double a = (k + 0.5) * da;
      const double sa = std::sin(a);
      q.mu[k] = -std::cos(a);
      q.w[k] = sa * da;
      q.len[k] = 2.0 * std::sqrt(std::max(0.0, 1.0 - r * r * sa * sa));
    }
  }
  return q;
}

// Effective chord −ln(AO)/τ (its τ → 0 limit at τ = 0) from lobe-weighted node sums, with
// e[k] = e^{−τ L_k} precomputed (shared by every normal angle of a row).
// Inside: AO = Σ K w e^{−τL} / Σ K w (normalised by the quadrature's own hemisphere, so the
// centre gives exactly e^{−τ}). Outside: AO = 1 − Σ K w (1 − e^{−τL}) / π.
double effective_chord(const Nodes& q, const double* kw, const double* e, double tau) {
  const int n = static_cast<int>(q.len.size());
  double sum = 0, den = 0;
  if (tau <= 0) {
    for (int k = 0; k < n; ++k) {
      sum += kw[k] * q.len[k];
      den += kw[k];
    }
    return q.outside ? sum / kPi : (den > 0 ? sum / den : 0.0);
  }
  if (q.outside) {
    for (int k = 0; k < n; ++k) sum += kw[k] * e[k];  // here e[k] = 1 − e^{−τL} (expm1)
    const double occ = std::min(sum / kPi, 1.0);
    return -std::log1p(-occ) / tau;
  }
  for (int k = 0; k < n; ++k) {
    sum += kw[k] * e[k];
    den += kw[k];
  }
  return -std::log(sum / den) / tau;
}

// e^{−τL} inside, 1 − e^{−τL} outside (kept apart so neither loses precision).
void transmittances(const Nodes& q, double tau, double* e) {
  const int n = static_cast<int>(q.len.size());
  for (int k = 0; k < n; ++k) {
    e[k] = q.outside ? -std::expm1(-tau * q.len[k]) : std::exp(-tau * q.len[k]);
  }
}

const double kWMax = 1.0 - 1.0 / MediumTable::kMaxRadius;
const double kLogTauMax = std::log1p(MediumTable::kMaxTau);

// Fractional node coordinates of the three axes (inverse of *_of_node).
inline float radius_coord(float r) {
  constexpr int kIn = MediumTable::kRadiusInside - 1;
  if (r <= 1.0f) return kIn * (1.0f - std::sqrt(std::max(0.0f, 1.0f - r)));
  const float w = 1.0f - 1.0f / r;
  return std::min(kIn + MediumTable::kRadiusOutside * std::sqrt(w / static_cast<float>(kWMax)),
                  static_cast<float>(MediumTable::kRadius - 1));
}
inline float cos_coord(float c) {
  // c = sign(q)(1 − (1 − |q|)²), q ∈ [−1, 1] uniform: dense where the normal is near-radial.
  const float a = std::min(std::abs(c), 1.0f);
  const float q = std::copysign(1.0f - std::sqrt(1.0f - a), c);
  return (q + 1.0f) * 0.5f * (MediumTable::kCos - 1);
}
// Weights of the two τ nodes around tau so that L = w0 L_it + w1 L_it+1. The interpolation is
// linear in g = τ L_eff = −ln AO along τ (not in L_eff): node values of g grow with τ, so the
// result is monotone in τ, exact at the centre (g = τ) and exactly 0 at τ = 0. Beyond kMaxTau,
// L_eff is held.
inline void tau_weights(float tau, int* it, float* w0, float* w1) {
  constexpr int kLast = MediumTable::kTau - 1;
  if (tau >= static_cast<float>(MediumTable::kMaxTau)) {
    *it = kLast - 1, *w0 = 0.0f, *w1 = 1.0f;
    return;
  }
  int k = static_cast<int>(std::log1p(tau) / kLogTauMax * kLast);
  k = std::clamp(k, 0, kLast - 1);
  double t0 = MediumTable::tau_of_node(k), t1 = MediumTable::tau_of_node(k + 1);
  // guard against log/expm1 rounding putting tau just outside [t0, t1]
  if (tau < t0 && k > 0) --k, t1 = t0, t0 = MediumTable::tau_of_node(k);
  if (tau > t1 && k < kLast - 1) ++k, t0 = t1, t1 = MediumTable::tau_of_node(k + 1);
  const double t = std::clamp((tau - t0) / (t1 - t0), 0.0, 1.0);
  *it = k;
  *w0 = tau > 0 ? static_cast<float>(t0 * (1 - t) / tau) : 1.0f;
  *w1 = tau > 0 ? static_cast<float>(t1 * t / tau) : 0.0f;
}
inline void split(float f, int max_index, int* i, float* t) {
  int k = static_cast<int>(f);
  k = std::clamp(k, 0, max_index - 1);
  *i = k;
  *t = std::clamp(f - k, 0.0f, 1.0f);
}

// Far field beyond the table: the medium is a small sphere; its occlusion scales with its
// solid angle, (r_max/r)², at the same normal angle.
inline float far_ao(float ao_at_max, float r) {
  const float s = static_cast<float>(MediumTable::kMaxRadius) / r;
  return 1.0f - (1.0f - ao_at_max) * s * s;
}

void require_finite_points(PointsView p, const char* name) {
  for (std::size_t i = 0; i < 3 * p.size; ++i) {
    if (!std::isfinite(p.data[i])) {
      std::ostringstream s;
      s << name << " has a non-finite value (NaN or inf) at row " << i / 3;
      throw std::invalid_argument(s.str());
    }
  }
}

void require_tau(float tau) {
  if (!std::isfinite(tau) || tau < 0) {
    throw std::invalid_argument("tau must be a finite number >= 0, got " + std::to_string(tau));
  }
}

void require_receivers(PointsView positions, PointsView normals) {
  if (positions.size != normals.size) {
    throw std::invalid_argument("positions and normals must have the same number of rows");
  }
  require_finite_points(positions, "positions");
  require_finite_points(normals, "normals");
}

void require_ellipsoid(const Ellipsoid& e, const char* name) {
  bool ok = is_finite(e.center) && is_finite(e.radii) && e.radii.x > 0 && e.radii.y > 0 &&
            e.radii.z > 0;
  for (const Vec3& a : e.axes) ok = ok && is_finite(a);
  if (!ok) {
    throw std::invalid_argument(std::string(name) +
                                " must have a finite centre and axes and radii > 0");
  }
}

// (r, cosβ) of a receiver in the unit-sphere frame (centre at the origin); false for a zero
// normal (no hemisphere: AO 1, as the ray-traced reference). At the centre cosβ is irrelevant.
inline bool unit_frame_coords(Vec3 x, Vec3 n, float* r, float* c) {
  const float d = length(x);
  const float ln = length(n);
  *r = d;
  *c = d > 0 && ln > 0 ? dot(x, n) / (d * ln) : 0.0f;
  return ln > 0;
}

constexpr std::size_t kGrain = 1024;

}  // namespace

double medium_ao_quadrature(double r, double cos_beta, double tau, int samples) {
  if (!(r >= 0) || !std::isfinite(r) || !(tau >= 0) || !std::isfinite(tau) || samples < 1) {
    throw std::invalid_argument("medium_ao_quadrature: need r >= 0, tau >= 0, samples >= 1");
  }
  const double c = std::clamp(cos_beta, -1.0, 1.0);
  const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
  const Nodes q = make_nodes(r, samples);
  std::vector<double> kw(samples), e(samples);
  for (int k = 0; k < samples; ++k) kw[k] = azimuth_lobe(q.mu[k], c, s) * q.w[k];
  transmittances(q, tau, e.data());
  // A chord that round-off makes slightly negative would give AO > 1.
  return std::min(1.0, std::exp(-tau * effective_chord(q, kw.data(), e.data(), tau)));
}

double MediumTable::radius_of_node(int ir) {
  if (ir < kRadiusInside) {
    const double u = static_cast<double>(ir) / (kRadiusInside - 1);
    return 1.0 - (1.0 - u) * (1.0 - u);
  }
  const double v = static_cast<double>(ir - (kRadiusInside - 1)) / kRadiusOutside;
  return 1.0 / (1.0 - kWMax * v * v);
}
double MediumTable::cos_of_node(int ic) {
  const double q = -1.0 + 2.0 * ic / (kCos - 1);
  const double a = 1.0 - (1.0 - std::abs(q)) * (1.0 - std::abs(q));
  return std::copysign(a, q);
}
double MediumTable::tau_of_node(int it) {
  return std::expm1(kLogTauMax * it / (kTau - 1));
}

MediumTable::MediumTable() : leff_(static_cast<std::size_t>(kRadius) * kCos * kTau) {
  // One radius per task: each row depends only on its own nodes, so the table is bit-identical
  // whatever the thread count.
  parallel_for_blocks(kRadius, 1, [&](std::size_t b, std::size_t e) {
    std::vector<double> kw(kTableSamples), tr(static_cast<std::size_t>(kTau) * kTableSamples);
    for (std::size_t ir = b; ir < e; ++ir) {
      const Nodes q = make_nodes(radius_of_node(static_cast<int>(ir)), kTableSamples);
      for (int it = 0; it < kTau; ++it) transmittances(q, tau_of_node(it), &tr[it * kTableSamples]);
      for (int ic = 0; ic < kCos; ++ic) {
        const double c = cos_of_node(ic);
        const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
        for (int k = 0; k < kTableSamples; ++k) kw[k] = azimuth_lobe(q.mu[k], c, s) * q.w[k];
        for (int it = 0; it < kTau; ++it) {
          // At the centre every chord is 1: store it exactly so AO = e^{−τ} there.
          const double l = ir == 0 ? 1.0 : effective_chord(q, kw.data(), &tr[it * kTableSamples],
                                                           tau_of_node(it));
          leff_[(ir * kCos + ic) * kTau + it] = static_cast<float>(l);
        }
      }
    }
  });
}

const MediumTable& MediumTable::get() {
  static const MediumTable table;  // C++11: initialised once, thread-safe
  return table;
}

float MediumTable::ao(float r, float cos_beta, float tau) const {
  if (!(tau > 0)) return 1.0f;
  if (r > kMaxRadius) return far_ao(ao(static_cast<float>(kMaxRadius), cos_beta, tau), r);
  int ir, ic, it;
  float fr, fc, w0, w1;
  split(radius_coord(r), kRadius - 1, &ir, &fr);
  split(cos_coord(cos_beta), kCos - 1, &ic, &fc);
  tau_weights(tau, &it, &w0, &w1);
  auto at = [&](int a, int b) {
    const float* p = &leff_[(a * kCos + b) * kTau + it];
    return w0 * p[0] + w1 * p[1];
  };
  auto lerp = [](float x, float y, float t) { return x + (y - x) * t; };
  const float l = lerp(lerp(at(ir, ic), at(ir, ic + 1), fc),
                       lerp(at(ir + 1, ic), at(ir + 1, ic + 1), fc), fr);
  return std::clamp(std::exp(-tau * l), 0.0f, 1.0f);
}

MediumTable::Slice MediumTable::slice(float tau) const {
  Slice s;
  s.tau_ = tau;
  s.leff_.resize(static_cast<std::size_t>(kRadius) * kCos);
  int it;
  float w0, w1;
  tau_weights(std::max(tau, 0.0f), &it, &w0, &w1);
  for (int ir = 0; ir < kRadius; ++ir) {
    for (int ic = 0; ic < kCos; ++ic) {
      s.leff_[ir * kCos + ic] = w0 * node(ir, ic, it) + w1 * node(ir, ic, it + 1);
    }
  }
  return s;
}

float MediumTable::Slice::ao(float r, float cos_beta) const {
  if (!(tau_ > 0)) return 1.0f;
  if (r > kMaxRadius) return far_ao(ao(static_cast<float>(kMaxRadius), cos_beta), r);
  int ir, ic;
  float fr, fc;
  split(radius_coord(r), kRadius - 1, &ir, &fr);
  split(cos_coord(cos_beta), kCos - 1, &ic, &fc);
  const float* p = leff_.data() + ir * kCos + ic;
  const float l0 = p[0] + (p[1] - p[0]) * fc;
  const float l1 = p[kCos] + (p[kCos + 1] - p[kCos]) * fc;
  const float l = l0 + (l1 - l0) * fr;
  return std::clamp(std::exp(-tau_ * l), 0.0f, 1.0f);
}

void ao_medium_sphere(PointsView positions, PointsView normals, const Sphere& sphere, float tau,
                      float* out) {
  if (!is_finite(sphere.center) || !std::isfinite(sphere.radius) || !(sphere.radius > 0)) {
    throw std::invalid_argument("sphere must have a finite centre and a radius > 0");
  }
  require_tau(tau);
  require_receivers(positions, normals);
  const MediumTable::Slice s = MediumTable::get().slice(tau);
  const float inv_r = 1.0f / sphere.radius;
  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      float r, c;
      const bool ok = unit_frame_coords((positions[i] - sphere.center) * inv_r, normals[i], &r, &c);
      out[i] = ok ? s.ao(r, c) : 1.0f;
    }
  });
}

void ao_medium_ellipsoid(PointsView positions, PointsView normals, const Ellipsoid& ellipsoid,
                         float tau, float* out) {
  require_ellipsoid(ellipsoid, "ellipsoid");
  require_tau(tau);
  require_receivers(positions, normals);
  const MediumTable::Slice s = MediumTable::get().slice(tau);
  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      float r, c;
      const bool ok = unit_frame_coords(ellipsoid.to_unit(positions[i]),
                                        ellipsoid.normal_to_unit(normals[i]), &r, &c);
      out[i] = ok ? s.ao(r, c) : 1.0f;
    }
  });
}

void ao_medium_shells(PointsView positions, PointsView normals,
                      const std::vector<Ellipsoid>& shells, const std::vector<float>& taus,
                      MediumCombine combine, float* out) {
  if (!(taus.size() == 1 || taus.size() == shells.size())) {
    throw std::invalid_argument("taus must hold one value or one per shell (" +
                                std::to_string(shells.size()) + "), got " +
                                std::to_string(taus.size()));
  }
  for (std::size_t k = 0; k < shells.size(); ++k) {
    require_ellipsoid(shells[k], ("shells[" + std::to_string(k) + "]").c_str());
  }
  for (float t : taus) require_tau(t);
  require_receivers(positions, normals);
  const MediumTable& table = MediumTable::get();
  std::vector<MediumTable::Slice> slices;  // one per τ given (one τ: one slice for all)
  for (float t : taus) slices.push_back(table.slice(t));
  std::vector<const MediumTable::Slice*> ptrs;
  for (const MediumTable::Slice& sl : slices) ptrs.push_back(&sl);
  ao_medium_shells_sliced(positions, normals, shells, ptrs, combine, out);
}

void ao_medium_shells_sliced(PointsView positions, PointsView normals,
                             const std::vector<Ellipsoid>& shells,
                             const std::vector<const MediumTable::Slice*>& slices,
                             MediumCombine combine, float* out) {
  if (!(slices.size() == 1 || slices.size() == shells.size())) {
    throw std::invalid_argument("slices must hold one or one per shell (" +
                                std::to_string(shells.size()) + "), got " +
                                std::to_string(slices.size()));
  }
  for (std::size_t k = 0; k < shells.size(); ++k) {
    require_ellipsoid(shells[k], ("shells[" + std::to_string(k) + "]").c_str());
  }
  require_receivers(positions, normals);
  const std::size_t per_shell = slices.size() == 1 ? 0 : 1;
  parallel_for_blocks(positions.size, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Vec3 x = positions[i], n = normals[i];
      float v = 1.0f;
      if (combine == MediumCombine::Product) {
        for (std::size_t k = 0; k < shells.size(); ++k) {
          float r, c;
          if (unit_frame_coords(shells[k].to_unit(x), shells[k].normal_to_unit(n), &r, &c)) {
            v *= slices[k * per_shell]->ao(r, c);
          }
        }
      } else if (!shells.empty()) {
        std::size_t best = 0;
        float best_d = INFINITY;
        for (std::size_t k = 0; k < shells.size(); ++k) {
          const Vec3 d = x - shells[k].center;
          const float d2 = dot(d, d);
          if (d2 < best_d) best_d = d2, best = k;
        }
        float r, c;
        if (unit_frame_coords(shells[best].to_unit(x), shells[best].normal_to_unit(n), &r, &c)) {
          v = slices[best * per_shell]->ao(r, c);
        }
      }
      out[i] = v;
    }
  });
}

}  // namespace canopy_ao
