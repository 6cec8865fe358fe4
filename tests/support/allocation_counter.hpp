// Heap allocations counted, for the tests that prove a path allocates
// nothing (the 1 kHz tick, the UDP device's read/write). Linking
// allocation_counter.cpp (library tissue_test_allocations) replaces the
// global operator new/delete of the whole test binary, so a binary links it
// at most once and defines no operator new of its own.
#pragma once

#include <cstdint>

namespace tissue::testing {

// Allocations counted since the last reset.
std::uint64_t allocations();
void reset_allocations();
// While on, every thread's allocations count (a window over the process).
void count_all_threads(bool on);
// While on, this thread's allocations count (others allocate freely).
void count_this_thread(bool on);

}  // namespace tissue::testing
