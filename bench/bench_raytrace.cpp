// Ray-traced AO throughput: RayTracer::ao against bare Embree loops on the same canopy.
//
// Scene: 500k random leaf triangles (≈0.05 units, optical depth ~2 along a radius) in a ball
// of radius 5; receivers at 20k leaf centroids with the leaf normal, 64 rays each.
// "bare_occluded1" is the loop anyone would write first (one rtcOccluded1 per ray, fixed local
// directions, no per-point rotation); "bare_1M" the same rays as one 64-ray stream per point
// (second argument 1 = coherent flag; Embree 3 only: Embree 4 has no streams); "bare_packet8"
// as rtcOccluded8 packets (what RayTracer uses on Embree 4). Target:
// RayTracer ≥ 80% of the fastest bare loop (docs/DESIGN.md, 'Facts measured in Blender': 2.5–4 M incoherent AO rays/s
// per core). rays/cpu_s divides by the CPU time of the whole process: a per-core figure that
// survives other processes sharing the cores; rays/s is wall-clock.
//
//   build-rt/canopy_ao_bench --benchmark_filter=RayTrace
#include <benchmark/benchmark.h>

#include <time.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"
#include "../native/src/embree_compat.h"

using namespace canopy_ao;

namespace {

constexpr int kTriangles = 500000;
constexpr int kReceivers = 20000;
constexpr int kSamples = 64;

struct Canopy {
  std::vector<float> v, p, n;
  std::vector<std::int32_t> t;
  Canopy() {
    std::mt19937 rng(2024);
    std::uniform_real_distribution<float> u(-1, 1);
    for (int k = 0; k < kTriangles; ++k) {
      Vec3 c;
      do c = {u(rng), u(rng), u(rng)};
      while (dot(c, c) > 1);
      c = c * 5.0f;
      Vec3 q[3];
      for (auto& x : q) x = c + 0.05f * Vec3{u(rng), u(rng), u(rng)};
      for (const auto& x : q) v.insert(v.end(), {x.x, x.y, x.z});
      t.insert(t.end(), {3 * k, 3 * k + 1, 3 * k + 2});
      if (k < kReceivers) {
        const Vec3 m = (q[0] + q[1] + q[2]) / 3.0f;
        Vec3 nn = normalize(cross(q[1] - q[0], q[2] - q[0]));
        if (u(rng) < 0) nn = -nn;  // either side of a leaf
        p.insert(p.end(), {m.x, m.y, m.z});
        n.insert(n.end(), {nn.x, nn.y, nn.z});
      }
    }
  }
  PointsView vertices() const { return {v.data(), v.size() / 3}; }
  PointsView points() const { return {p.data(), p.size() / 3}; }
  PointsView normals() const { return {n.data(), n.size() / 3}; }
};

const Canopy& canopy() {
  static const Canopy c;
  return c;
}

const RayTracer& tracer() {
  static const RayTracer t(canopy().vertices(), canopy().t.data(), canopy().t.size() / 3);
  return t;
}

// A bare Embree scene of the same triangles, set up the way Embree's minimal tutorial does.
struct BareScene {
  RTCDevice device = rtcNewDevice(nullptr);
  RTCScene scene = rtcNewScene(device);
  float offset = 0;
  BareScene() {
    const Canopy& c = canopy();
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), c.v.size() / 3));
    std::copy(c.v.begin(), c.v.end(), vb);
    auto* ib = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t), c.t.size() / 3));
    std::copy(c.t.begin(), c.t.end(), ib);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(scene);
    offset = tracer().auto_offset();
  }
  ~BareScene() {
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  }
};

const BareScene& bare() {
  static const BareScene b;
  return b;
}

// Fixed cosine-weighted local directions, shared by every point.
std::vector<Vec3> local_directions() {
  std::vector<Vec3> d;
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  for (int s = 0; s < kSamples; ++s) {
    const float a = u(rng), ph = 6.2831853f * u(rng);
    d.push_back({std::sqrt(a) * std::cos(ph), std::sqrt(a) * std::sin(ph), std::sqrt(1 - a)});
  }
  return d;
}

inline void basis(Vec3 n, Vec3* t, Vec3* b) {
  const float sign = std::copysign(1.0f, n.z), a = -1.0f / (sign + n.z), c = n.x * n.y * a;
  *t = {1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x};
  *b = {c, sign + n.y * n.y * a, -n.y};
}

inline RTCRay make_ray(Vec3 o, Vec3 d) {
  RTCRay r;
  r.org_x = o.x, r.org_y = o.y, r.org_z = o.z, r.tnear = 0;
  r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z, r.time = 0;
  r.tfar = INFINITY, r.mask = 0xffffffffu, r.id = 0, r.flags = 0;
  return r;
}

// The per-query arguments of the bare loops, in either Embree's spelling.
#if RTC_VERSION_MAJOR >= 4
struct BareQuery {
  RTCOccludedArguments args;
  explicit BareQuery(bool coherent) {
    rtcInitOccludedArguments(&args);
    if (coherent) args.flags = RTC_RAY_QUERY_FLAG_COHERENT;
  }
  void occluded1(RTCScene s, RTCRay* r) { rtcOccluded1(s, r, &args); }
  void occluded8(const int* valid, RTCScene s, RTCRay8* r) { rtcOccluded8(valid, s, r, &args); }
};
#else
struct BareQuery {
  RTCIntersectContext ctx;
  explicit BareQuery(bool coherent) {
    rtcInitIntersectContext(&ctx);
    if (coherent) ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  }
  void occluded1(RTCScene s, RTCRay* r) { rtcOccluded1(s, &ctx, r); }
  void occluded8(const int* valid, RTCScene s, RTCRay8* r) { rtcOccluded8(valid, s, &ctx, r); }
  void occluded1M(RTCScene s, RTCRay* r, unsigned n) { rtcOccluded1M(s, &ctx, r, n, sizeof(RTCRay)); }
};
#endif

double process_cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// rays/s is wall-clock; rays/cpu_s divides by the CPU time of all our threads, so it stays a
// per-core figure when other processes share the cores.
void report(benchmark::State& state, double rays, double open_fraction, double cpu_seconds) {
  state.counters["rays/s"] = benchmark::Counter(rays, benchmark::Counter::kIsRate);
  state.counters["rays/cpu_s"] = rays / cpu_seconds;
  state.counters["mean_AO"] = open_fraction;
}

// Second argument 1: each receiver names its own triangle (leaf k), so its rays skip it by the
// occlusion filter and start on the leaf (the add-on's texel path); 0: the normal offset.
void BM_RayTracer_ao(benchmark::State& state) {
  const RayTracer& rt = tracer();
  const int prev = set_max_threads(static_cast<int>(state.range(0)));
  RayTraceOptions o;
  o.samples = kSamples;
  std::vector<float> out(canopy().points().size);
  std::vector<std::int32_t> leaf(out.size());
  for (std::size_t k = 0; k < leaf.size(); ++k) leaf[k] = static_cast<std::int32_t>(k);
  OwnPrimitives own;
  if (state.range(1)) own.triangle_ids = leaf.data();
  const double cpu0 = process_cpu_seconds();
  for (auto _ : state) {
    rt.ao(canopy().points(), canopy().normals(), own, o, out.data());
    benchmark::ClobberMemory();
  }
  const double cpu1 = process_cpu_seconds();
  double sum = 0;
  for (float x : out) sum += x;
  set_max_threads(prev);
  report(state, static_cast<double>(state.iterations()) * kReceivers * kSamples,
         sum / kReceivers, cpu1 - cpu0);
}

// The leaves' own vertices as receivers (the add-on's vertex path), each naming itself:
// second argument 0 = the own-surface rule (a tracer without vertex normals), 1 = Cycles' bake
// point (the tracer the add-on builds: vertex normals given, per-corner starts, terminator
// lift, a ROBUST scene). Same rays, same counts: the ratio is what the bake point costs.
void BM_RayTracer_vertices(benchmark::State& state) {
  const Canopy& c = canopy();
  const std::size_t nv = 3 * static_cast<std::size_t>(kReceivers);
  std::vector<float> vn(c.v.size());
  for (std::size_t k = 0; k < c.t.size() / 3; ++k) {
    const Vec3 a = c.vertices()[3 * k], b = c.vertices()[3 * k + 1], d = c.vertices()[3 * k + 2];
    const Vec3 f = normalize(cross(b - a, d - a));
    for (int j = 0; j < 3; ++j) std::copy(&f.x, &f.x + 3, vn.begin() + 9 * k + 3 * j);
  }
  static const RayTracer plain(c.vertices(), c.t.data(), c.t.size() / 3);
  static const RayTracer baking(c.vertices(), c.t.data(), c.t.size() / 3,
                                BakeShading{{vn.data(), vn.size() / 3}, nullptr}, {}, {});
  const RayTracer& rt = state.range(1) ? baking : plain;
  const int prev = set_max_threads(static_cast<int>(state.range(0)));
  RayTraceOptions o;
  o.samples = kSamples;
  std::vector<float> out(nv);
  std::vector<std::int32_t> self(nv);
  for (std::size_t k = 0; k < nv; ++k) self[k] = static_cast<std::int32_t>(k);
  OwnPrimitives own;
  own.vertex_ids = self.data();
  const PointsView pts{c.v.data(), nv}, nrm{vn.data(), nv};
  const double cpu0 = process_cpu_seconds();
  for (auto _ : state) {
    rt.ao(pts, nrm, own, o, out.data());
    benchmark::ClobberMemory();
  }
  const double cpu1 = process_cpu_seconds();
  double sum = 0;
  for (float x : out) sum += x;
  set_max_threads(prev);
  report(state, static_cast<double>(state.iterations()) * static_cast<double>(nv) * kSamples,
         sum / static_cast<double>(nv), cpu1 - cpu0);
}

// Runs a bare loop over all receivers under the benchmark's thread cap: trace(scene, ctx, o,
// n, t, b) returns how many of a point's rays are open, given its origin o, unit normal n and
// basis (t, b). Everything but the tracing is the same for the three bare loops.
template <class Trace>
void run_bare(benchmark::State& state, Trace trace) {
  const BareScene& sc = bare();
  const Canopy& c = canopy();
  const int prev = set_max_threads(static_cast<int>(state.range(0)));
  std::vector<int> open(kReceivers);
  const double cpu0 = process_cpu_seconds();
  for (auto _ : state) {
    parallel_for_blocks(kReceivers, 64, [&](std::size_t begin, std::size_t end) {
      BareQuery query(state.range(1) != 0);
      for (std::size_t i = begin; i < end; ++i) {
        const Vec3 n = c.normals()[i], o = c.points()[i] + n * sc.offset;
        Vec3 t, b;
        basis(n, &t, &b);
        open[i] = trace(sc.scene, &query, o, n, t, b);
      }
    });
  }
  const double cpu1 = process_cpu_seconds();
  double sum = 0;
  for (int k : open) sum += static_cast<double>(k) / kSamples;
  set_max_threads(prev);
  report(state, static_cast<double>(state.iterations()) * kReceivers * kSamples,
         sum / kReceivers, cpu1 - cpu0);
}

// One rtcOccluded1 per ray.
void BM_RayTrace_bare_occluded1(benchmark::State& state) {
  const auto dirs = local_directions();
  run_bare(state, [&](RTCScene scene, BareQuery* q, Vec3 o, Vec3 n, Vec3 t, Vec3 b) {
    int k = 0;
    for (const Vec3& d : dirs) {
      RTCRay r = make_ray(o, t * d.x + b * d.y + n * d.z);
      q->occluded1(scene, &r);
      k += r.tfar >= 0;
    }
    return k;
  });
}

#if RTC_VERSION_MAJOR < 4
// The same rays as one rtcOccluded1M stream per point; second argument 1 =
// RTC_INTERSECT_CONTEXT_FLAG_COHERENT (a point's rays share their origin).
void BM_RayTrace_bare_1M(benchmark::State& state) {
  const auto dirs = local_directions();
  run_bare(state, [&](RTCScene scene, BareQuery* q, Vec3 o, Vec3 n, Vec3 t, Vec3 b) {
    alignas(64) RTCRay rays[kSamples];
    for (int s = 0; s < kSamples; ++s) {
      const Vec3& d = dirs[s];
      rays[s] = make_ray(o, t * d.x + b * d.y + n * d.z);
    }
    q->occluded1M(scene, rays, kSamples);
    int k = 0;
    for (const RTCRay& r : rays) k += r.tfar >= 0;
    return k;
  });
}
#endif

// The same rays as 8-wide packets (rtcOccluded8, AVX2), 8 packets per point.
void BM_RayTrace_bare_packet8(benchmark::State& state) {
  const auto dirs = local_directions();
  run_bare(state, [&](RTCScene scene, BareQuery* q, Vec3 o, Vec3 n, Vec3 t, Vec3 b) {
    alignas(32) const int valid[8] = {-1, -1, -1, -1, -1, -1, -1, -1};
    int k = 0;
    for (int s0 = 0; s0 < kSamples; s0 += 8) {
      RTCRay8 r;
      for (int l = 0; l < 8; ++l) {
        const Vec3& d = dirs[s0 + l];
        const Vec3 w = t * d.x + b * d.y + n * d.z;
        r.org_x[l] = o.x, r.org_y[l] = o.y, r.org_z[l] = o.z, r.tnear[l] = 0;
        r.dir_x[l] = w.x, r.dir_y[l] = w.y, r.dir_z[l] = w.z, r.time[l] = 0;
        r.tfar[l] = INFINITY, r.mask[l] = 0xffffffffu, r.id[l] = 0, r.flags[l] = 0;
      }
      q->occluded8(valid, scene, &r);
      for (int l = 0; l < 8; ++l) k += r.tfar[l] >= 0;
    }
    return k;
  });
}

void BM_RayTracer_build(benchmark::State& state) {
  const Canopy& c = canopy();
  RayTracerBuildOptions opt;
  opt.high_quality = state.range(1) != 0;
  const int prev = set_max_threads(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    RayTracer t(c.vertices(), c.t.data(), c.t.size() / 3, opt);
    benchmark::DoNotOptimize(t.triangle_count());
  }
  set_max_threads(prev);
  state.counters["triangles/s"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * kTriangles, benchmark::Counter::kIsRate);
}

}  // namespace

// Real time: the work runs on TBB workers, not on the benchmark's thread.
BENCHMARK(BM_RayTracer_ao)->Args({1, 0})->Args({2, 0})->Args({1, 1})->Args({2, 1})
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_RayTracer_vertices)->Args({1, 0})->Args({1, 1})->Args({2, 0})->Args({2, 1})
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_RayTrace_bare_occluded1)->Args({1, 0})->Args({2, 0})->Unit(benchmark::kMillisecond)
    ->UseRealTime()->MinTime(1.0);
#if RTC_VERSION_MAJOR < 4
BENCHMARK(BM_RayTrace_bare_1M)->Args({1, 0})->Args({2, 0})->Args({1, 1})->Args({2, 1})
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
#endif
BENCHMARK(BM_RayTrace_bare_packet8)->Args({1, 0})->Args({2, 0})->Unit(benchmark::kMillisecond)
    ->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_RayTracer_build)->Args({1, 0})->Args({2, 0})->Args({2, 1})
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
