// ScratchVector<T>: a std::vector whose resize leaves the new elements uninitialised (default-initialised) instead
// of zeroing them, for per-thread scratch buffers that every use overwrites before it reads them (the object
// losses' crops, SSIM's line buffers): there a growing resize zeroed megabytes a step for nothing, on one thread.
// Only for trivially constructible T (float, double, int); value-initialising calls (resize(n, v), assign) behave
// as std::vector's.
#pragma once
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace hgs {

template <class T>
struct DefaultInitAllocator : std::allocator<T> {
  static_assert(std::is_trivially_default_constructible_v<T>);
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() noexcept = default;
  template <class U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;  // default-initialised: no zeroing
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <class T>
using ScratchVector = std::vector<T, DefaultInitAllocator<T>>;

// v resized to n when its old values need not survive: a growth past its storage reallocates without copying them
// (a serial copy of megabytes where per-view buffers change size from view to view).
template <class T>
void resize_discarding(ScratchVector<T>& v, size_t n) {
  if (n > v.capacity()) v.clear();
  v.resize(n);
}

}  // namespace hgs
