#pragma once

// Replaces the global operator new and delete, every form (the aligned ones
// too), with malloc and free behind a hook the including test defines:
//
//   void herm::test::on_allocation(std::size_t size) noexcept;
//
// called for every allocation through operator new, on whatever thread.
// Include it in one file of a test program only (it defines the
// operators). Every form is replaced, the aligned ones too, so that no
// pair mixes these with a sanitizer runtime's (AddressSanitizer checks that
// new and delete match).

#include <cstddef>
#include <cstdlib>
#include <new>

namespace herm::test {

void on_allocation(std::size_t size) noexcept;

namespace replaced_new {

inline void* allocate(std::size_t size) noexcept {
  on_allocation(size);
  return std::malloc(size == 0 ? 1 : size);
}

inline void* allocate(std::size_t size, std::align_val_t al) noexcept {
  on_allocation(size);
  auto align = static_cast<std::size_t>(al);
  // aligned_alloc wants a multiple of the alignment.
  auto n = size == 0 ? 1 : size;
  auto rounded = (n + align - 1) / align * align;
  return std::aligned_alloc(align, rounded);
}

template <class... Align>
void* allocate_or_throw(std::size_t size, Align... al) {
  if (auto* p = allocate(size, al...))
    return p;
  throw std::bad_alloc{};
}

} // namespace replaced_new

} // namespace herm::test

// GCC sees malloc and free behind these operators and warns that they do
// not match when it inlines them; they do.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

void* operator new(std::size_t n) {
  return herm::test::replaced_new::allocate_or_throw(n);
}
void* operator new[](std::size_t n) {
  return herm::test::replaced_new::allocate_or_throw(n);
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  return herm::test::replaced_new::allocate(n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  return herm::test::replaced_new::allocate(n);
}
void* operator new(std::size_t n, std::align_val_t al) {
  return herm::test::replaced_new::allocate_or_throw(n, al);
}
void* operator new[](std::size_t n, std::align_val_t al) {
  return herm::test::replaced_new::allocate_or_throw(n, al);
}
void* operator new(std::size_t n, std::align_val_t al,
                   const std::nothrow_t&) noexcept {
  return herm::test::replaced_new::allocate(n, al);
}
void* operator new[](std::size_t n, std::align_val_t al,
                     const std::nothrow_t&) noexcept {
  return herm::test::replaced_new::allocate(n, al);
}

void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::align_val_t,
                       const std::nothrow_t&) noexcept {
  std::free(p);
}

#pragma GCC diagnostic pop
