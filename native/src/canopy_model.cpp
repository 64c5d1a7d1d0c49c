// The canopy-shell model's public functions (canopy_model.h) and the run-time choice of
// kernel. The kernels themselves are canopy_model_kernels.inc, compiled twice here: portable
// (the build's baseline, x86-64-v2) and AVX2/FMA (GCC's target pragma), so that the module runs
// on any x86-64-v2 CPU and still uses AVX2/FMA where the CPU has them.
//
// Hot loops must vectorise into few instructions: see fast_math.h for no-trapping-math;
// finite-math-only and no-signed-zeros let min/max become vminps/vmaxps instead of
// compare+blend. Every value here is finite by construction (inputs are checked in
// model_checks.cpp, which is compiled without these options; no inf or NaN is produced).
#pragma GCC optimize("no-trapping-math", "finite-math-only", "no-signed-zeros")

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/model_checks.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "canopy_ao/fast_math.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/parallel.h"

namespace canopy_ao {

namespace {
namespace portable {
#include "canopy_model_kernels.inc"
}  // namespace portable

#ifdef CANOPY_AO_X86
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#define CANOPY_AO_AVX2 1
namespace avx2 {
#include "canopy_model_kernels.inc"
}  // namespace avx2
#undef CANOPY_AO_AVX2
#pragma GCC pop_options
#endif

// -1: not chosen yet; else a CanopyKernel.
std::atomic<int> g_kernel{-1};

CanopyKernel best_kernel() {
  const char* env = std::getenv("CANOPY_AO_KERNEL");
  if (env && std::strcmp(env, "portable") == 0) return CanopyKernel::Portable;
  return canopy_kernel_available(CanopyKernel::Avx2) ? CanopyKernel::Avx2
                                                     : CanopyKernel::Portable;
}

bool use_avx2() {
  int k = g_kernel.load(std::memory_order_relaxed);
  if (k < 0) {
    k = static_cast<int>(best_kernel());
    g_kernel.store(k, std::memory_order_relaxed);
  }
  return k == static_cast<int>(CanopyKernel::Avx2);
}

}  // namespace

#ifdef CANOPY_AO_X86
#define CANOPY_AO_DISPATCH(call) (use_avx2() ? avx2::call : portable::call)
#else
#define CANOPY_AO_DISPATCH(call) (portable::call)
#endif

bool canopy_kernel_available(CanopyKernel k) {
  if (k == CanopyKernel::Portable) return true;
#ifdef CANOPY_AO_X86
  return cpu_has_avx2_fma();
#else
  return false;
#endif
}

CanopyKernel canopy_kernel() {
  return use_avx2() ? CanopyKernel::Avx2 : CanopyKernel::Portable;
}

void set_canopy_kernel(CanopyKernel k) {
  if (!canopy_kernel_available(k))
    throw std::invalid_argument("this CPU cannot run the AVX2/FMA kernel");
  g_kernel.store(static_cast<int>(k), std::memory_order_relaxed);
}

// === One point
float canopy_visibility(Vec3 x, Vec3 n, const Ellipsoid& shell, const CanopyOptions& options) {
  check_canopy_options(options);
  check_ellipsoid(shell);
  return CANOPY_AO_DISPATCH(one_point(x, n, shell, options));
}

// === Arrays
void ao_canopy_sphere(PointsView positions, PointsView normals, const Sphere& sphere,
                      const CanopyOptions& options, float* out) {
  check_receivers(positions, normals);
  check_sphere(sphere);
  check_canopy_options(options);
  CANOPY_AO_DISPATCH(sphere(positions, normals, sphere, options, out));
}

void ao_canopy_ellipsoid(PointsView positions, PointsView normals, const Ellipsoid& ellipsoid,
                         const CanopyOptions& options, float* out) {
  check_receivers(positions, normals);
  check_ellipsoid(ellipsoid);
  check_canopy_options(options);
  CANOPY_AO_DISPATCH(ellipsoid(positions, normals, ellipsoid, options, out));
}

void ao_canopy_shells(PointsView positions, PointsView normals,
                      const std::vector<Ellipsoid>& shells, const CanopyOptions& options,
                      ShellCombine combine, float* out) {
  check_receivers(positions, normals);
  check_canopy_options(options);
  if (shells.empty()) throw std::invalid_argument("shells must not be empty");
  for (const Ellipsoid& s : shells) check_ellipsoid(s);
  CANOPY_AO_DISPATCH(shells(positions, normals, shells, options, combine, out));
}

}  // namespace canopy_ao
