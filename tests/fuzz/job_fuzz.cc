// Job files (host/io/job.h): ParseJobText never throws for bad input; every problem is a value.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/io/job.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const imr::io::JobParseResult r = imr::io::ParseJobText(text, "/fuzz/job.json");
  if (r.ok()) {
    for (const std::string& s : r.job.sequences) (void)r.job.OutputDirectory(s);
  }
  return 0;
}
