// Incremental SLAM JSON (host/io/slam_json.h): open, then every keyframe update.
#include <cstddef>
#include <cstdint>

#include "host/io/slam_json.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto file = imr::fuzz::ScratchDir() / "slam.json";
  imr::fuzz::WriteFile(file, {reinterpret_cast<const char*>(data), size});
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    imr::io::SlamJsonOptions o;
    o.min_move = size % 2 == 0 ? 0.0 : 0.01;
    auto source = imr::io::OpenSlamJson(file, o);
    imr::engine::KeyframeUpdate u;
    imr::io::KeyframeInfo info;
    imr::io::CanonicalOrder order;
    while (source->Next(&u, &info)) order.Apply(&u);
    (void)source->Summary();
  });
  return 0;
}
