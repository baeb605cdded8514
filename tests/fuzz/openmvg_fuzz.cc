// OpenMVG sfm_data.json (host/io/openmvg_reader.h), then the replay that feeds the engine.
#include <cstddef>
#include <cstdint>

#include "host/io/openmvg_reader.h"
#include "host/io/sfm_source.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto file = imr::fuzz::ScratchDir() / "sfm_data.json";
  imr::fuzz::WriteFile(file, {reinterpret_cast<const char*>(data), size});
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    imr::io::SfmReplayOptions o;
    o.replay = size % 2 == 0;
    o.order_by_name = size % 3 == 0;
    auto source = imr::io::MakeSfmSource(imr::io::ReadOpenMvg(file), o);
    imr::engine::KeyframeUpdate u;
    imr::io::KeyframeInfo info;
    while (source->Next(&u, &info)) {
    }
    (void)source->Summary();
  });
  return 0;
}
