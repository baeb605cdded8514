// This process's memory as the kernel counts it (Linux /proc), for reports and benchmarks.
#pragma once

#include <cstdint>

namespace imr {

// Resident set size now (bytes), from /proc/self/statm; 0 when unreadable.
uint64_t ResidentBytes();
// The peak resident set size so far (bytes): VmHWM of /proc/self/status; 0 when unreadable.
uint64_t PeakResidentBytes();

}  // namespace imr
