// Native stage timing (stage_clock.h): what a profiled bake reports, and that profiling
// changes no result.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "canopy_ao/raytrace.h"
#include "canopy_ao/stage_clock.h"

using namespace canopy_ao;

namespace {

// A unit ground quad (z = 0) with a roof quad at z = 1 over half of it: a mix of open and
// blocked rays, vertex receivers at Cycles' bake point (the add-on's path).
struct Scene {
  std::vector<float> v{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0,  // ground
                       0, 0, 1, 0.5f, 0, 1, 0.5f, 1, 1, 0, 1, 1};  // roof
  std::vector<std::int32_t> t{0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6};
  std::vector<float> n{0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1,
                       0, 0, -1, 0, 0, -1, 0, 0, -1, 0, 0, -1};
  RayTracer tracer() const {
    BakeShading shading;
    shading.vertex_normals = {n.data(), n.size() / 3};
    return RayTracer({v.data(), v.size() / 3}, t.data(), t.size() / 3, shading, {}, {});
  }
  std::vector<float> ao(const RayTracer& rt) const {
    std::vector<std::int32_t> ids{0, 1, 2, 3, 4, 5, 6, 7};
    OwnPrimitives own;
    own.vertex_ids = ids.data();
    RayTraceOptions o;
    o.samples = 64;
    std::vector<float> out(8);
    rt.ao({v.data(), 8}, {n.data(), 8}, own, o, out.data());
    return out;
  }
};

bool has(const std::vector<std::pair<std::string, std::pair<double, long long>>>& stages,
         const std::string& name) {
  for (const auto& s : stages) {
    if (s.first == name) return s.second.first >= 0.0 && s.second.second >= 1;
  }
  return false;
}

}  // namespace

TEST(StageClock, OffRecordsNothing) {
  set_stage_profiling(false);
  take_stage_seconds();
  const Scene s;
  s.ao(s.tracer());
  EXPECT_TRUE(take_stage_seconds().empty());
}

TEST(StageClock, ProfiledBakeNamesItsStagesAndKeepsItsResult) {
  const Scene s;
  set_stage_profiling(false);
  const std::vector<float> plain = s.ao(s.tracer());
  set_stage_profiling(true);
  take_stage_seconds();
  const std::vector<float> profiled = s.ao(s.tracer());
  const auto stages = take_stage_seconds();
  set_stage_profiling(false);
  EXPECT_EQ(plain, profiled);  // bit for bit
  for (const char* name : {"tracer: checks, copies", "tracer: corner tables",
                           "tracer: BVH build", "rays: tracing (CPU)",
                           "rays: sampling, starts (CPU)", "rays: reduction (CPU)",
                           "rays: wall (all blocks)"}) {
    EXPECT_TRUE(has(stages, name)) << name;
  }
  EXPECT_TRUE(take_stage_seconds().empty());  // taking clears
  // The roof shades the ground under it (vertex 0 sees it over about a tenth of its
  // hemisphere): the result is a real bake, not all open.
  EXPECT_LT(plain[0], 0.97f);
}
