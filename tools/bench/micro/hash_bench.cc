// SHA-256 as a run pays it: `imr run` hashes every input file of a sequence for its report (the
// input checksums: every image, calibration and poses) and every output for the batch manifest.
// Over the KITTI raw sample (data/kitti-raw-2011_09_26-traffic: 78 PNGs and 78 Velodyne scans,
// read from the page cache after the first pass) and over a buffer in memory (the hash alone).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "host/util/sha256.h"

namespace {
namespace fs = std::filesystem;

void BM_Sha256KittiSample(benchmark::State& state) {
  const fs::path root = fs::path(IMR_SHARED_DIR) / "data" / "kitti-raw-2011_09_26-traffic";
  std::vector<fs::path> files;
  std::uintmax_t bytes = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(root, ec); !ec && it != fs::end(it); ++it)
    if (it->is_regular_file()) {
      files.push_back(it->path());
      bytes += it->file_size();
    }
  if (files.empty()) {
    state.SkipWithError((root.string() + " is absent: no KITTI sample to hash").c_str());
    return;
  }
  std::sort(files.begin(), files.end());
  for (auto _ : state)
    for (const fs::path& f : files) benchmark::DoNotOptimize(imr::Sha256File(f));
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes));
  state.counters["files"] = static_cast<double>(files.size());
  state.counters["MB"] = static_cast<double>(bytes) / 1e6;
}
BENCHMARK(BM_Sha256KittiSample)->Unit(benchmark::kMillisecond);

void BM_Sha256Memory(benchmark::State& state) {
  const std::string data(static_cast<std::size_t>(state.range(0)), 'x');
  for (auto _ : state) benchmark::DoNotOptimize(imr::Sha256Hex(data));
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * state.range(0));
}
BENCHMARK(BM_Sha256Memory)->Arg(64 << 20)->Unit(benchmark::kMillisecond);

}  // namespace
