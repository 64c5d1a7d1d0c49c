// Checks the portable zip's libcxxcompat-canopyao (native/portable/cxx_compat.cpp) against
// libstdc++'s own behaviour, calling the library's functions by dlsym on its handle (the
// program's own calls go to the system's libstdc++). Run by tests/portable/test_portable.sh:
//   cxx_compat_check PATH/libcxxcompat-canopyao.so.1
// Prints one line and exits 0, or names what differs and exits 1.
#include <dlfcn.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <new>

namespace {

int alive = 0;  // Tracked objects in existence: an exception object's destruction is seen.
struct Tracked {
  Tracked() { ++alive; }
  Tracked(const Tracked&) { ++alive; }
  ~Tracked() { --alive; }
};

int failures = 0;
void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "cxx_compat_check: %s\n", what);
    ++failures;
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: cxx_compat_check LIBRARY\n");
    return 2;
  }
  void* lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (lib == nullptr) {
    std::fprintf(stderr, "cxx_compat_check: %s\n", dlerror());
    return 1;
  }
  using Member = void (*)(std::exception_ptr*);
  auto addref = reinterpret_cast<Member>(dlsym(lib, "_ZNSt15__exception_ptr13exception_ptr9_M_addrefEv"));
  auto release = reinterpret_cast<Member>(dlsym(lib, "_ZNSt15__exception_ptr13exception_ptr10_M_releaseEv"));
  auto throw_length = reinterpret_cast<void (*)()>(dlsym(lib, "_ZSt28__throw_bad_array_new_lengthv"));
  if (addref == nullptr || release == nullptr || throw_length == nullptr) {
    std::fprintf(stderr, "cxx_compat_check: %s lacks a function\n", argv[1]);
    return 1;
  }

  // A reference taken and dropped leaves the exception alive; the last one dropped destroys it.
  {
    std::exception_ptr p = std::make_exception_ptr(Tracked());
    check(alive == 1, "make_exception_ptr did not leave one exception object");
    addref(&p);
    { std::exception_ptr copy = p; }  // libstdc++'s own reference counting in between
    release(&p);
    check(alive == 1, "_M_addref then _M_release destroyed the exception (or leaked a copy)");
    addref(&p);
    release(&p);
    release(&p);  // the last reference: gone
    check(alive == 0, "_M_release of the last reference did not destroy the exception");
    std::memset(static_cast<void*>(&p), 0, sizeof p);  // released above: nothing left to drop
  }
  // The exception is rethrown intact from a pointer whose references the library counted.
  {
    std::exception_ptr p = std::make_exception_ptr(Tracked());
    addref(&p);
    std::exception_ptr q;
    std::memcpy(static_cast<void*>(&q), static_cast<const void*>(&p), sizeof p);  // q owns it
    p = nullptr;
    bool caught = false;
    try {
      std::rethrow_exception(q);
    } catch (const Tracked&) {
      caught = true;
    }
    check(caught, "the exception did not survive _M_addref");
    q = nullptr;
    check(alive == 0, "the exception outlived its last reference");
  }
  // __throw_bad_array_new_length throws what libstdc++'s throws.
  {
    bool caught = false;
    try {
      throw_length();
    } catch (const std::bad_array_new_length& e) {
      caught = std::strcmp(e.what(), std::bad_array_new_length().what()) == 0;
    } catch (...) {
    }
    check(caught, "__throw_bad_array_new_length did not throw std::bad_array_new_length");
  }
  if (failures == 0) std::printf("libcxxcompat-canopyao: exception_ptr references and bad_array_new_length as libstdc++\n");
  return failures == 0 ? 0 : 1;
}
