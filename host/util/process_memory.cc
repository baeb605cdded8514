#include "host/util/process_memory.h"

#include <malloc.h>
#include <unistd.h>

#include <cstddef>
#include <fstream>
#include <string>

// jemalloc's control interface, resolved only where the executable links jemalloc (weak: null
// elsewhere, e.g. the tests and the Python module under glibc's malloc).
extern "C" int mallctl(const char* name, void* oldp, std::size_t* oldlenp, void* newp,
                       std::size_t newlen) __attribute__((weak));

namespace imr {

uint64_t ResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  uint64_t pages_total = 0, pages_resident = 0;
  if (!(statm >> pages_total >> pages_resident)) return 0;
  return pages_resident * static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
}

uint64_t PeakResidentBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;  // "... kB"
  return 0;
}

HeapBytes CurrentHeapBytes() {
  HeapBytes h;
  if (mallctl != nullptr) {
    // The statistics are a snapshot taken at an "epoch": advance it first.
    uint64_t epoch = 1;
    std::size_t size = sizeof(epoch);
    std::size_t allocated = 0, resident = 0, n = sizeof(std::size_t);
    if (mallctl("epoch", &epoch, &size, &epoch, size) == 0 &&
        mallctl("stats.allocated", &allocated, &n, nullptr, 0) == 0 &&
        mallctl("stats.resident", &resident, &n, nullptr, 0) == 0) {
      h.allocator = "jemalloc";
      h.allocated = allocated;
      h.resident = resident;
    }
    return h;
  }
  const struct mallinfo2 m = ::mallinfo2();
  h.allocator = "glibc";
  h.allocated = m.uordblks + m.hblkhd;
  h.resident = m.arena + m.hblkhd;
  return h;
}

}  // namespace imr
