// Canopy AO — libstdc++ functions newer than the portable zip's C++ baseline, for the libraries
// it carries (docs/PORTABILITY.md, 'C++ runtime'). Built into libcxxcompat-canopyao.so.1 only by
// scripts/build_portable.sh.
//
// The zip's baseline is GCC 10's libstdc++ (GLIBCXX_3.4.28, CXXABI_1.3.12). The module links
// its C++ runtime statically, but the carried Embree and TBB are the distribution's binaries,
// compiled by a newer GCC: whatever they call that is newer than the baseline is defined here.
// scripts/portable_cxx.py drops those calls' version requirements (the symbol then binds by
// name: to the system's libstdc++ where it has the function, else to this library, which the
// carried library lists as a need) and stops the build on any such call not defined here.
//
// Each definition does what libstdc++'s own does, with functions the baseline already has.
#include <exception>
#include <new>

namespace {

// exception_ptr's layout: the exception object's address, nothing else.
struct RawExceptionPtr {
  void* object;
};
// exception_ptr's copy constructor and destructor as libstdc++ exports them since GCC 4.4
// (CXXABI_1.3.3): out of line, each adds or drops one reference of the exception object (GCC
// 11's headers inline them as calls to _M_addref/_M_release below, so these are named by symbol).
extern "C" void cxx_exception_ptr_copy(RawExceptionPtr* self, const RawExceptionPtr* other) noexcept
    __asm__("_ZNSt15__exception_ptr13exception_ptrC1ERKS0_");
extern "C" void cxx_exception_ptr_destroy(RawExceptionPtr* self) noexcept
    __asm__("_ZNSt15__exception_ptr13exception_ptrD1Ev");

}  // namespace

namespace std {

// GLIBCXX_3.4.29 (GCC 11): std::allocator<T>::allocate's size check, inlined into callers.
[[noreturn]] void __throw_bad_array_new_length() { throw bad_array_new_length(); }

namespace __exception_ptr {

// CXXABI_1.3.13 (GCC 11): called by exception_ptr's inline copy constructor and destructor
// (TBB carries exceptions between threads in exception_ptrs). One reference more: a copy made
// by the exported constructor and never destroyed.
void exception_ptr::_M_addref() noexcept {
  RawExceptionPtr copy;
  cxx_exception_ptr_copy(&copy, reinterpret_cast<const RawExceptionPtr*>(this));
}

// One reference less (the exception destroyed and freed with the last): the exported destructor
// run on a copy of the address. Called only by the inline destructor, which ends the object.
void exception_ptr::_M_release() noexcept {
  RawExceptionPtr self{*reinterpret_cast<void* const*>(this)};
  cxx_exception_ptr_destroy(&self);
}

}  // namespace __exception_ptr
}  // namespace std
