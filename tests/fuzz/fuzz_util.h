// Shared helpers of the libFuzzer targets (tests/fuzz/README.md): a scratch folder per process,
// files written from the fuzz input, the input split into several files, and the one rule of
// every reader target: bad input may throw std::runtime_error or std::invalid_argument, anything
// else (a crash, a sanitizer report, another exception, a hang) is a bug.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace imr::fuzz {

// One scratch folder per fuzzer process (removed at exit), under $TMPDIR.
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    std::string t = (std::filesystem::temp_directory_path() / "imr-fuzz-XXXXXX").string();
    if (!mkdtemp(t.data())) std::abort();
    static std::filesystem::path keep;
    keep = t;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(keep, ec);
    });
    return std::filesystem::path(t);
  }();
  return dir;
}

inline void WriteFile(const std::filesystem::path& path, std::string_view bytes) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!f) std::abort();
}

// The input cut at each line "@@@@" (the separator of the multi-file corpora); always `parts`
// pieces, missing ones empty, extra text appended to the last.
inline std::vector<std::string> SplitParts(const uint8_t* data, std::size_t size, std::size_t parts) {
  const std::string_view all(reinterpret_cast<const char*>(data), size);
  constexpr std::string_view kSep = "\n@@@@\n";
  std::vector<std::string> out;
  std::size_t pos = 0;
  while (out.size() + 1 < parts) {
    const std::size_t at = all.find(kSep, pos);
    if (at == std::string_view::npos) break;
    out.emplace_back(all.substr(pos, at - pos + 1));  // keep the line's newline
    pos = at + kSep.size();
  }
  out.emplace_back(all.substr(std::min(pos, all.size())));
  out.resize(parts);
  return out;
}

// A valid 4x3 8-bit grey PNG, for the readers that look at the first image's size.
inline std::string_view TinyPng() {
  static const unsigned char kPng[] = {
      0x89,0x50,0x4e,0x47,0x0d,0x0a,0x1a,0x0a,0x00,0x00,0x00,0x0d,0x49,0x48,0x44,0x52,0x00,0x00,
      0x00,0x04,0x00,0x00,0x00,0x03,0x08,0x00,0x00,0x00,0x00,0x91,0x9f,0xf1,0x1a,0x00,0x00,0x00,
      0x17,0x49,0x44,0x41,0x54,0x78,0x9c,0x63,0x60,0xe0,0x12,0x91,0x63,0xd0,0x30,0xb2,0x71,0x63,
      0x08,0x88,0x4a,0xc9,0x03,0x00,0x0c,0x8f,0x02,0x95,0x67,0x1d,0x16,0xaf,0x00,0x00,0x00,0x00,
      0x49,0x45,0x4e,0x44,0xae,0x42,0x60,0x82};
  return {reinterpret_cast<const char*>(kPng), sizeof(kPng)};
}

// Runs a reader; the exceptions a reader documents for bad input are fine, others escape and
// libFuzzer reports them (uncaught exception -> abort). IMR_FUZZ_VERBOSE=1 prints the message
// (to see how far a seed gets: `IMR_FUZZ_VERBOSE=1 build/fuzz/x_fuzz -runs=0 corpus/x`).
template <typename F>
void ExpectOnlyDocumentedErrors(F&& f) {
  static const bool verbose = std::getenv("IMR_FUZZ_VERBOSE") != nullptr;
  try {
    f();
    if (verbose) std::fprintf(stderr, "fuzz: read without error\n");
  } catch (const std::runtime_error& e) {
    if (verbose) std::fprintf(stderr, "fuzz: runtime_error: %s\n", e.what());
  } catch (const std::invalid_argument& e) {
    if (verbose) std::fprintf(stderr, "fuzz: invalid_argument: %s\n", e.what());
  }
}

}  // namespace imr::fuzz
