#include "support/allocation_counter.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

namespace {

std::atomic<bool> g_all_threads{false};
thread_local bool t_this_thread = false;
std::atomic<std::uint64_t> g_allocations{0};

void count() {
  if (t_this_thread || g_all_threads.load(std::memory_order_relaxed))
    g_allocations.fetch_add(1, std::memory_order_relaxed);
}

void* counted_malloc(std::size_t n) {
  count();
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}

}  // namespace

namespace tissue::testing {
std::uint64_t allocations() { return g_allocations.load(); }
void reset_allocations() { g_allocations.store(0); }
void count_all_threads(bool on) { g_all_threads.store(on); }
void count_this_thread(bool on) { t_this_thread = on; }
}  // namespace tissue::testing

void* operator new(std::size_t n) { return counted_malloc(n); }
void* operator new[](std::size_t n) { return counted_malloc(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  count();
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& t) noexcept { return operator new(n, t); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
