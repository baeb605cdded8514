// This process's memory as the kernel counts it (Linux /proc), for reports and benchmarks.
#pragma once

#include <cstdint>
#include <string>

namespace imr {

// Resident set size now (bytes), from /proc/self/statm; 0 when unreadable.
uint64_t ResidentBytes();
// The peak resident set size so far (bytes): VmHWM of /proc/self/status; 0 when unreadable.
uint64_t PeakResidentBytes();

// What the allocator says of its heap: the bytes the program holds (allocated) and the bytes the
// allocator keeps resident for it (its pages in use, freed ones not yet returned, its metadata).
// RSS minus `resident` is code, libraries and stacks; `resident` minus `allocated` is what freeing
// did not give back. From jemalloc's mallctl when the executable links it (imr does), else from
// glibc's mallinfo2 (`resident`: the arenas' and mmapped bytes).
struct HeapBytes {
  std::string allocator;  // "jemalloc", "glibc", or empty: unknown (the figures are 0)
  uint64_t allocated = 0;
  uint64_t resident = 0;
};
HeapBytes CurrentHeapBytes();

}  // namespace imr
