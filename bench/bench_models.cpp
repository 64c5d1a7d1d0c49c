// Throughput of the analytic AO models (vertices/s), 10^5..10^7 points, 1 and 2 threads.
//   build-models/canopy_ao_bench --benchmark_filter=Models
// Inputs are AoS float32 (N×3) positions and unit normals, as the add-on passes them; the
// output buffer is reused (the Python binding allocates a new array each call, which adds the
// page faults of a fresh 4N-byte buffer).
// The bare-loop baseline below needs fast_exp to vectorise (see fast_math.h).
#pragma GCC optimize("no-trapping-math")

#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/fast_math.h"
#include "canopy_ao/grass.h"
#include "canopy_ao/occluders.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/reeves_blau.h"

using namespace canopy_ao;

namespace {
constexpr std::size_t kMax = 10'000'000;

// Receivers: points uniform in the unit ball scaled to `radius` around the origin (a canopy),
// random unit normals. Built once, shared by every benchmark (prefixes of it).
struct Data {
  std::vector<float> p, n, out;
  Data() : p(3 * kMax), n(3 * kMax), out(kMax) {
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> u(-1, 1);
    for (std::size_t i = 0; i < kMax; ++i) {
      float x, y, z;
      do {
        x = u(rng), y = u(rng), z = u(rng);
      } while (x * x + y * y + z * z > 1);
      p[3 * i] = 5 * x, p[3 * i + 1] = 5 * y, p[3 * i + 2] = 5 * z + 6;
      float a, b, c, l;
      do {
        a = u(rng), b = u(rng), c = u(rng), l = a * a + b * b + c * c;
      } while (l > 1 || l < 1e-4f);
      l = 1 / std::sqrt(l);
      n[3 * i] = a * l, n[3 * i + 1] = b * l, n[3 * i + 2] = c * l;
    }
  }
  PointsView pv(std::size_t k) const { return {p.data(), k}; }
  PointsView nv(std::size_t k) const { return {n.data(), k}; }
};

Data& data() {
  static Data d;
  return d;
}

Ellipsoid tilted() {
  Ellipsoid e;
  e.center = {0, 0, 6};
  const float c = std::cos(0.4f), s = std::sin(0.4f);
  e.axes[0] = {c, s, 0};
  e.axes[1] = {-s, c, 0};
  e.axes[2] = {0, 0, 1};
  e.radii = {5.5f, 5.2f, 6};  // contains every receiver, like a fitted shell
  return e;
}

template <class Fn>
void run(benchmark::State& state, Fn&& fn) {
  const std::size_t n = static_cast<std::size_t>(state.range(0));
  const int prev = set_max_threads(static_cast<int>(state.range(1)));
  Data& d = data();
  for (auto _ : state) {
    fn(d.pv(n), d.nv(n), d.out.data());
    benchmark::DoNotOptimize(d.out.data());
    benchmark::ClobberMemory();
  }
  set_max_threads(prev);
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(n));
}

// The machine's ceiling for the one-sphere model's memory traffic (28 B per vertex): read AoS
// positions and normals, one exponential of a dot product per point, write a float; the same
// blocks and threads as the models. With AVX2 the AoS → SoA transpose is the model's own
// (load8_aos, fast_math.h); GCC's own stride-3 vectorisation of the plain loop is ~3x slower,
// so it is no ceiling. Whatever the model does beyond this costs compute.

void bare_loop_tail(const float* __restrict pp, const float* __restrict nn, std::size_t i,
                    std::size_t e, float* __restrict oo) {
  for (; i < e; ++i) {
    const float t = pp[3 * i] * nn[3 * i] + pp[3 * i + 1] * nn[3 * i + 1] +
                    (pp[3 * i + 2] - 6.0f) * nn[3 * i + 2];
    oo[i] = fast_exp(-0.1f * t * t);
  }
}

#ifdef CANOPY_AO_X86
CANOPY_AO_TARGET_AVX2 void bare_loop_avx2(const float* __restrict pp,
                                          const float* __restrict nn, std::size_t b,
                                          std::size_t e, float* __restrict oo) {
  std::size_t i = b;
  alignas(32) float d[8];
  for (; i + 8 <= e; i += 8) {
    __m256 px, py, pz, qx, qy, qz;
    load8_aos(pp + 3 * i, px, py, pz);
    load8_aos(nn + 3 * i, qx, qy, qz);
    pz = _mm256_sub_ps(pz, _mm256_set1_ps(6.0f));
    const __m256 t = _mm256_fmadd_ps(pz, qz, _mm256_fmadd_ps(py, qy, _mm256_mul_ps(px, qx)));
    _mm256_store_ps(d, _mm256_mul_ps(_mm256_mul_ps(t, t), _mm256_set1_ps(-0.1f)));
    for (int k = 0; k < 8; ++k) oo[i + k] = fast_exp(d[k]);  // vectorised by GCC
  }
  bare_loop_tail(pp, nn, i, e, oo);
}
#endif

// The ceiling is the CPU's best code: AVX2 where it has it, as the dispatched models.
void bare_loop(const float* __restrict pp, const float* __restrict nn, std::size_t b,
               std::size_t e, float* __restrict oo) {
#ifdef CANOPY_AO_X86
  if (cpu_has_avx2_fma()) return bare_loop_avx2(pp, nn, b, e, oo);
#endif
  bare_loop_tail(pp, nn, b, e, oo);
}

void Models_BareLoopSphere(benchmark::State& state) {
  run(state, [&](PointsView p, PointsView n, float* o) {
    parallel_for_blocks(p.size, 16384, [&](std::size_t b, std::size_t e) {
      bare_loop(p.data, n.data, b, e, o);
    });
  });
}

void Models_CanopySphere(benchmark::State& state) {
  const Sphere s{{0, 0, 6}, 5.0f};
  run(state, [&](PointsView p, PointsView n, float* o) { ao_canopy_sphere(p, n, s, {1.5f}, o); });
}
// The same through the portable (baseline) kernel, for comparison with the dispatched one.
void Models_CanopySpherePortable(benchmark::State& state) {
  const Sphere s{{0, 0, 6}, 5.0f};
  const CanopyKernel prev = canopy_kernel();
  set_canopy_kernel(CanopyKernel::Portable);
  run(state, [&](PointsView p, PointsView n, float* o) { ao_canopy_sphere(p, n, s, {1.5f}, o); });
  set_canopy_kernel(prev);
}
void Models_CanopyEllipsoid(benchmark::State& state) {
  const Ellipsoid e = tilted();
  run(state,
      [&](PointsView p, PointsView n, float* o) { ao_canopy_ellipsoid(p, n, e, {1.5f}, o); });
}
void Models_CanopyShells4(benchmark::State& state) {
  std::vector<Ellipsoid> shells;
  for (int k = 0; k < 4; ++k) {
    shells.push_back(Ellipsoid::from_sphere({{k < 2 ? -2.0f : 2.0f, k % 2 ? -2.0f : 2.0f, 6}, 3.5f}));
  }
  run(state, [&](PointsView p, PointsView n, float* o) {
    ao_canopy_shells(p, n, shells, {1.5f}, ShellCombine::Product, o);
  });
}
void Models_ReevesBlau(benchmark::State& state) {
  const Ellipsoid e = tilted();
  run(state, [&](PointsView p, PointsView, float* o) { ao_reeves_blau(p, e, 1.5f, o); });
}
void Models_Grass(benchmark::State& state) {
  GrassOptions g;
  g.ground_height = 1.0f;
  g.blade_height = 4.0f;
  run(state, [&](PointsView p, PointsView n, float* o) { ao_grass(p, n, g, o); });
}
// A forest of 32×32 trees (radius 3 on a 12-unit lattice, ε = 1e-2: d_far ≈ 53) around the
// receivers (which sit in and around the central tree).
void Models_Occluders1024(benchmark::State& state) {
  std::vector<Ellipsoid> forest;
  for (int i = 0; i < 32; ++i)
    for (int j = 0; j < 32; ++j)
      forest.push_back(Ellipsoid::from_sphere({{12.0f * (i - 16), 12.0f * (j - 16), 6}, 3.0f}));
  const OccluderField field(forest, OccluderOptions{1.5f, 1e-2f, false});
  state.counters["max_candidates"] = static_cast<double>(field.max_candidates());
  run(state, [&](PointsView p, PointsView n, float* o) { field.ao(p, n, o); });
}

void sizes(benchmark::internal::Benchmark* b) {
  for (int threads : {1, 2})
    for (int64_t n : {100'000, 1'000'000, 10'000'000}) b->Args({n, threads});
  b->ArgNames({"n", "threads"})->UseRealTime()->Unit(benchmark::kMillisecond);
}
}  // namespace

BENCHMARK(Models_BareLoopSphere)->Apply(sizes);
BENCHMARK(Models_CanopySphere)->Apply(sizes);
BENCHMARK(Models_CanopySpherePortable)->Apply(sizes);
BENCHMARK(Models_CanopyEllipsoid)->Apply(sizes);
BENCHMARK(Models_CanopyShells4)->Apply(sizes);
BENCHMARK(Models_ReevesBlau)->Apply(sizes);
BENCHMARK(Models_Grass)->Apply(sizes);
BENCHMARK(Models_Occluders1024)->Apply(sizes);
