// Canopy AO — one source for Embree 3 and Embree 4 (internal header: raytrace.cpp and the
// ray-tracing benchmark only).
//
// Which Embree: CANOPY_AO_EMBREE4=1 (set by CMake when it found Embree 4) or =0 selects;
// without the macro, Embree 3's header is used when present, else Embree 4's.
//
// What differs, and what this header gives both versions:
//  - the per-query state: Embree 3's RTCIntersectContext, Embree 4's RTCRayQueryContext passed
//    inside RTCOccludedArguments → QueryContext, init_context();
//  - stream calls (rtcOccluded1M) exist only in Embree 3 → occluded(), which takes an AoS
//    array of rays and traces it as one stream (Embree 3) or as 8-wide packets (Embree 4);
//  - RTCFilterFunctionNArguments::context has the version's context type; a filter casts it
//    back to the structure that embeds QueryContext as its first member (see raytrace.cpp).
// Everything else used here (devices, scenes, triangle geometries, shared buffers, filter
// functions on a geometry, RTCRay's layout, error codes) has the same spelling in both.
#pragma once

#if defined(CANOPY_AO_EMBREE4)
#if CANOPY_AO_EMBREE4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif
#elif defined(__has_include)
#if __has_include(<embree3/rtcore.h>)
#include <embree3/rtcore.h>
#else
#include <embree4/rtcore.h>
#endif
#else
#include <embree3/rtcore.h>
#endif

#include <cstddef>

#if RTC_VERSION_MAJOR < 3 || RTC_VERSION_MAJOR > 4
#error "Canopy AO supports Embree 3 and Embree 4"
#endif

namespace canopy_ao::embree {

#if RTC_VERSION_MAJOR >= 4
using QueryContext = RTCRayQueryContext;
inline void init_context(QueryContext* context) { rtcInitRayQueryContext(context); }
#else
using QueryContext = RTCIntersectContext;
/// Incoherent rays (Embree 3's default flag): AO rays leave a point in every direction.
inline void init_context(QueryContext* context) { rtcInitIntersectContext(context); }
#endif

/// Embree's version, "3.13.5" or "4.3.3".
inline const char* version_string() { return RTC_VERSION_STRING; }

/// Tests rays[0..count) for occlusion with `scene`; Embree sets tfar to -inf on every occluded
/// ray and leaves the others untouched. `context` reaches the geometries' filter functions.
inline void occluded(RTCScene scene, QueryContext* context, RTCRay* rays, std::size_t count) {
#if RTC_VERSION_MAJOR >= 4
  // No streams in Embree 4: 8-wide packets (AVX2's native width; Embree splits them on narrower
  // ISAs), the tail masked off through `valid`.
  RTCOccludedArguments args;
  rtcInitOccludedArguments(&args);  // incoherent, every feature, no argument filter
  args.context = context;
  for (std::size_t first = 0; first < count; first += 8) {
    const std::size_t lanes = count - first < 8 ? count - first : 8;
    alignas(32) int valid[8];
    alignas(32) RTCRay8 packet;
    for (std::size_t l = 0; l < 8; ++l) {
      // Inactive lanes repeat the first ray: Embree ignores them but reads their fields.
      const RTCRay& r = rays[first + (l < lanes ? l : 0)];
      valid[l] = l < lanes ? -1 : 0;
      packet.org_x[l] = r.org_x;
      packet.org_y[l] = r.org_y;
      packet.org_z[l] = r.org_z;
      packet.tnear[l] = r.tnear;
      packet.dir_x[l] = r.dir_x;
      packet.dir_y[l] = r.dir_y;
      packet.dir_z[l] = r.dir_z;
      packet.time[l] = r.time;
      packet.tfar[l] = r.tfar;
      packet.mask[l] = r.mask;
      packet.id[l] = r.id;
      packet.flags[l] = r.flags;
    }
    rtcOccluded8(valid, scene, &packet, &args);
    for (std::size_t l = 0; l < lanes; ++l) rays[first + l].tfar = packet.tfar[l];
  }
#else
  rtcOccluded1M(scene, context, rays, static_cast<unsigned>(count), sizeof(RTCRay));
#endif
}

}  // namespace canopy_ao::embree
