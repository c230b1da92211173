// Counts operator new calls per thread, for "this path does not allocate" tests. It REPLACES the
// global operator new/delete: include it in exactly one source file of a test executable.
// (tests/server/fem/no_alloc_test.cpp interposes malloc itself instead: it must also see
// CHOLMOD's and OpenBLAS's C allocations.)
#pragma once

#include <cstdlib>
#include <new>

namespace neurosim::testing {
inline thread_local long t_allocations = 0;  // operator new calls on this thread
// This thread's count so far (the calling thread's: call it from the thread under test).
inline long allocations_on_this_thread() { return t_allocations; }
}  // namespace neurosim::testing

void* operator new(std::size_t size) {
  ++neurosim::testing::t_allocations;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
// GCC 12 inlines these into gtest's `delete` of a `new`ed object and then warns that free() meets
// a pointer from operator new (-Wmismatched-new-delete): here operator new IS malloc, so the
// pair matches; the warning is silenced for these two definitions only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop
