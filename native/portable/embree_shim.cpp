// Canopy AO — the portable module's Embree calls (docs/PORTABILITY.md, 'Loading beside
// Blender's own copies'). Built into _core only by scripts/build_portable.sh
// (-DCANOPY_AO_EMBREE_SHIM=<soname of the carried Embree>).
//
// A Blender that links Embree 4 (Debian's 4.3 and 5.x) has rtcNewDevice & co. in the process's
// global scope, under the same names as Embree 3's and with another ABI; the dynamic linker
// looks there first, so the module's calls would land in Blender's Embree and crash. Here
// every Embree function the core calls is defined in the module itself, hidden (bound at link
// time), and forwards to the function of that name in the carried library, looked up with
// dlsym on its own handle, which searches only that library.
#include <dlfcn.h>

#include <stdexcept>
#include <string>

#pragma GCC visibility push(hidden)
#include <embree3/rtcore.h>
#pragma GCC visibility pop

#ifndef CANOPY_AO_EMBREE_SHIM
#error "CANOPY_AO_EMBREE_SHIM must name the carried Embree's soname"
#endif

namespace {

void* carried_symbol(const char* name) {
  static void* const handle = dlopen(CANOPY_AO_EMBREE_SHIM, RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    throw std::runtime_error(std::string("Canopy AO cannot load its Embree (" CANOPY_AO_EMBREE_SHIM
                                         "), which should lie beside the module: ") + dlerror());
  }
  void* f = dlsym(handle, name);
  if (f == nullptr) {
    throw std::runtime_error(std::string("Canopy AO's Embree (" CANOPY_AO_EMBREE_SHIM ") has no ") +
                             name);
  }
  return f;
}

}  // namespace

#define CANOPY_AO_FORWARD(ret, name, params, args)                                     \
  extern "C" ret name params {                                                          \
    static const auto carried = reinterpret_cast<decltype(&name)>(carried_symbol(#name)); \
    return carried args;                                                                \
  }

CANOPY_AO_FORWARD(unsigned int, rtcAttachGeometry, (RTCScene s, RTCGeometry g), (s, g))
CANOPY_AO_FORWARD(void, rtcCommitGeometry, (RTCGeometry g), (g))
CANOPY_AO_FORWARD(void, rtcCommitScene, (RTCScene s), (s))
CANOPY_AO_FORWARD(RTCError, rtcGetDeviceError, (RTCDevice d), (d))
CANOPY_AO_FORWARD(ssize_t, rtcGetDeviceProperty, (RTCDevice d, RTCDeviceProperty p), (d, p))
CANOPY_AO_FORWARD(RTCDevice, rtcNewDevice, (const char* config), (config))
CANOPY_AO_FORWARD(RTCGeometry, rtcNewGeometry, (RTCDevice d, RTCGeometryType t), (d, t))
CANOPY_AO_FORWARD(RTCScene, rtcNewScene, (RTCDevice d), (d))
CANOPY_AO_FORWARD(void, rtcOccluded1M,
                  (RTCScene s, RTCIntersectContext* c, RTCRay* r, unsigned int m, size_t stride),
                  (s, c, r, m, stride))
CANOPY_AO_FORWARD(void, rtcReleaseDevice, (RTCDevice d), (d))
CANOPY_AO_FORWARD(void, rtcReleaseGeometry, (RTCGeometry g), (g))
CANOPY_AO_FORWARD(void, rtcReleaseScene, (RTCScene s), (s))
CANOPY_AO_FORWARD(void, rtcSetDeviceErrorFunction, (RTCDevice d, RTCErrorFunction f, void* u),
                  (d, f, u))
CANOPY_AO_FORWARD(void, rtcSetGeometryInstancedScene, (RTCGeometry g, RTCScene s), (g, s))
CANOPY_AO_FORWARD(void, rtcSetGeometryOccludedFilterFunction,
                  (RTCGeometry g, RTCFilterFunctionN f), (g, f))
CANOPY_AO_FORWARD(void, rtcSetGeometryTransform,
                  (RTCGeometry g, unsigned int step, RTCFormat fmt, const void* xfm),
                  (g, step, fmt, xfm))
CANOPY_AO_FORWARD(void, rtcSetSceneBuildQuality, (RTCScene s, RTCBuildQuality q), (s, q))
CANOPY_AO_FORWARD(void, rtcSetSceneFlags, (RTCScene s, RTCSceneFlags f), (s, f))
CANOPY_AO_FORWARD(void, rtcSetSharedGeometryBuffer,
                  (RTCGeometry g, RTCBufferType t, unsigned int slot, RTCFormat fmt,
                   const void* ptr, size_t offset, size_t stride, size_t count),
                  (g, t, slot, fmt, ptr, offset, stride, count))
