// COLMAP binary model (host/io/colmap_model.h): cameras.bin, images.bin, points3D.bin, given as
// one input cut by "@@@@" lines; then the checks and the conversion that feed the engine.
#include <cstddef>
#include <cstdint>

#include "host/io/colmap_model.h"
#include "host/io/sfm_source.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto dir = imr::fuzz::ScratchDir() / "sparse";
  const auto parts = imr::fuzz::SplitParts(data, size, 3);
  imr::fuzz::WriteFile(dir / "cameras.bin", parts[0]);
  imr::fuzz::WriteFile(dir / "images.bin", parts[1]);
  imr::fuzz::WriteFile(dir / "points3D.bin", parts[2]);
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    const imr::io::ColmapModel m = imr::io::ReadColmapBinary(dir);
    imr::io::CheckColmapModel(m, dir.string());
    auto source = imr::io::MakeSfmSource(imr::io::ColmapToSfm(m, dir.string()), {});
    imr::engine::KeyframeUpdate u;
    imr::io::KeyframeInfo info;
    while (source->Next(&u, &info)) {
    }
  });
  return 0;
}
