// Per-texel raster throughput: rasterize_uv of a 100k-triangle mesh into 2048² (and 8192²), and
// the splat + 16-texel margin that follows a bake.
//
// Mesh: a 224×224-quad wavy sheet (100 352 triangles) unwrapped into 4×4 UV islands with
// 1/64-wide gaps, about 88% of the image covered, per-corner arrays as the add-on passes them.
//
//   build-texel/canopy_ao_bench --benchmark_filter=Texel
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "canopy_ao/canopy_model.h"
#include "canopy_ao/parallel.h"
#include "canopy_ao/raytrace.h"
#include "canopy_ao/sphere_fit.h"
#include "canopy_ao/texel_raster.h"

using namespace canopy_ao;

namespace {

struct Sheet {
  std::vector<float> uv, pos, nrm;
  Sheet() {
    const int n = 224, islands = 4, per = n / islands;
    const float gap = 1.0f / 64, cell = 1.0f / islands, span = cell - gap;
    for (int b = 0; b < n; ++b) {
      for (int a = 0; a < n; ++a) {
        // Corners of quad (a, b) seen from its own island (a + 1 may start the next island).
        auto c = [&](int da, int db) {
          const int ia = a / per, ib = b / per;
          const int aa = a + da, bb = b + db;
          const float fu = float(aa - ia * per) / per, fv = float(bb - ib * per) / per;
          uv.insert(uv.end(), {ia * cell + gap / 2 + fu * span, ib * cell + gap / 2 + fv * span});
          const float x = float(aa) / n, y = float(bb) / n;
          pos.insert(pos.end(), {x, y, 0.1f * std::sin(12 * x) * std::cos(9 * y)});
          const float dzx = 1.2f * std::cos(12 * x) * std::cos(9 * y);
          const float dzy = -0.9f * std::sin(12 * x) * std::sin(9 * y);
          const float l = std::sqrt(1 + dzx * dzx + dzy * dzy);
          nrm.insert(nrm.end(), {-dzx / l, -dzy / l, 1 / l});
        };
        c(0, 0), c(1, 0), c(1, 1);
        c(0, 0), c(1, 1), c(0, 1);
      }
    }
  }
  CornerTriangles view() const { return {uv.data(), pos.data(), nrm.data(), uv.size() / 6}; }
};

const Sheet& sheet() {
  static const Sheet s;
  return s;
}

// Args: resolution, threads (0 = all), conservative.
void BM_Texel_rasterize(benchmark::State& state) {
  const Sheet& s = sheet();
  const int prev = set_max_threads(int(state.range(1)));
  RasterOptions o;
  o.width = o.height = int(state.range(0));
  o.conservative = state.range(2) != 0;
  std::size_t texels = 0;
  for (auto _ : state) {
    const TexelSet t = rasterize_uv(s.view(), o);
    texels = t.size();
    benchmark::DoNotOptimize(t.positions.data());
  }
  set_max_threads(prev);
  state.counters["triangles"] = double(s.uv.size() / 6);
  state.counters["texels"] = double(texels);
  state.counters["texels/s"] =
      benchmark::Counter(double(state.iterations()) * texels, benchmark::Counter::kIsRate);
}

void BM_Texel_splat_margin16(benchmark::State& state) {
  const Sheet& s = sheet();
  RasterOptions o;
  o.width = o.height = int(state.range(0));
  const TexelSet t = rasterize_uv(s.view(), o);
  std::vector<float> values(t.size(), 0.5f);
  for (auto _ : state) {
    const TexelImage r =
        splat_texels(t.pixels.data(), values.data(), t.size(), 1, o.width, o.height, 16);
    benchmark::DoNotOptimize(r.image.pixels.data());
  }
  state.counters["texels"] = double(t.size());
}

// The per-texel figure: a whole 2048² bake with the sphere model — raster, one AO value per
// texel, splat with a 16-texel margin — of the 100k-triangle mesh. Target: under 1 s.
void BM_Texel_bake_sphere(benchmark::State& state) {
  const Sheet& s = sheet();
  const Sphere shell = fit_min_sphere(PointsView{s.pos.data(), s.pos.size() / 3});
  CanopyOptions co;
  co.tau = 1.5f;
  RasterOptions o;
  o.width = o.height = int(state.range(0));
  std::size_t texels = 0;
  for (auto _ : state) {
    const TexelSet t = rasterize_uv(s.view(), o);
    std::vector<float> ao(t.size());
    ao_canopy_sphere(PointsView{t.positions.data(), t.size()},
                     PointsView{t.normals.data(), t.size()}, shell, co, ao.data());
    const TexelImage r = splat_texels(t.pixels.data(), ao.data(), t.size(), 1, o.width,
                                      o.height, 16);
    texels = t.size();
    benchmark::DoNotOptimize(r.image.pixels.data());
  }
  state.counters["texels"] = double(texels);
}

// The ray-traced texel bake's rays per second (64 rays on every 16th texel of the 2048² set,
// against the sheet itself; the per-texel rate is the ray rate / 64).
void BM_Texel_raytrace_rays(benchmark::State& state) {
  const Sheet& s = sheet();
  RasterOptions o;
  o.width = o.height = 2048;
  const TexelSet t = rasterize_uv(s.view(), o);
  std::vector<float> p, n;
  for (std::size_t i = 0; i < t.size(); i += 16) {
    p.insert(p.end(), &t.positions[3 * i], &t.positions[3 * i] + 3);
    n.insert(n.end(), &t.normals[3 * i], &t.normals[3 * i] + 3);
  }
  std::vector<std::int32_t> tris(s.pos.size() / 3);
  for (std::size_t i = 0; i < tris.size(); ++i) tris[i] = std::int32_t(i);
  const RayTracer tracer(PointsView{s.pos.data(), s.pos.size() / 3}, tris.data(), tris.size() / 3);
  RayTraceOptions ro;
  ro.samples = 64;
  std::vector<float> out(p.size() / 3);
  for (auto _ : state) {
    tracer.ao(PointsView{p.data(), out.size()}, PointsView{n.data(), out.size()}, ro, out.data());
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["rays/s"] = benchmark::Counter(
      double(state.iterations()) * double(out.size()) * ro.samples, benchmark::Counter::kIsRate);
}

}  // namespace

// Real time: the work runs on TBB workers, not on the benchmark's thread.
BENCHMARK(BM_Texel_rasterize)
    ->Args({2048, 1, 1})
    ->Args({2048, 0, 1})
    ->Args({2048, 0, 0})
    ->Args({8192, 0, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_Texel_splat_margin16)->Arg(2048)->Arg(8192)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Texel_bake_sphere)->Arg(2048)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Texel_raytrace_rays)->Unit(benchmark::kMillisecond)->UseRealTime();
