// An exception thrown in a TBB task body reaches the caller through the carried TBB, with the
// portable module's C++ runtime (docs/PORTABILITY.md, 'C++ runtime'): this library is linked as
// the module is (libstdc++ static and private) against the zip's libtbb-canopyao, whose
// exception_ptr calls bind to the compat library or the system's libstdc++. Built and loaded
// (ctypes, as Python loads the module) in the bare root by tests/portable/test_portable.sh:
//   g++ -shared -fPIC -static-libstdc++ -Wl,--exclude-libs,ALL -Wl,--gc-sections (a version \
//       script exporting run alone) ... tbb_exceptions.cpp PKG/libtbb-canopyao.so.12
// run() returns how many of 50 parallel loops, each with one throwing iteration (at a
// different place, on whichever thread runs it), delivered that exception intact to the caller.
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <stdexcept>
#include <string>

extern "C" __attribute__((visibility("default"))) int run() {
  int delivered = 0;
  for (int round = 0; round < 50; ++round) {
    const std::string expected = "iteration " + std::to_string(999 - 7 * round);
    try {
      tbb::task_arena().execute([&] {  // the machine's threads
        tbb::parallel_for(0, 1000, [&](int i) {
          if (i == 999 - 7 * round) throw std::runtime_error("iteration " + std::to_string(i));
        });
      });
    } catch (const std::runtime_error& e) {
      delivered += expected == e.what();
    }
  }
  return delivered;
}
