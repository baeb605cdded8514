// COLMAP text model (host/io/colmap_model.h): cameras.txt, images.txt, points3D.txt, given as one
// input cut by "@@@@" lines; then the checks and the conversion that feed the engine.
#include <cstddef>
#include <cstdint>

#include "host/io/colmap_model.h"
#include "host/io/sfm_source.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto dir = imr::fuzz::ScratchDir() / "sparse";
  const auto parts = imr::fuzz::SplitParts(data, size, 3);
  imr::fuzz::WriteFile(dir / "cameras.txt", parts[0]);
  imr::fuzz::WriteFile(dir / "images.txt", parts[1]);
  imr::fuzz::WriteFile(dir / "points3D.txt", parts[2]);
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    const imr::io::ColmapModel m = imr::io::ReadColmapText(dir);
    imr::io::CheckColmapModel(m, dir.string());
    imr::io::SfmReplayOptions o;
    o.replay = true;
    auto source = imr::io::MakeSfmSource(imr::io::ColmapToSfm(m, dir.string()), o);
    imr::engine::KeyframeUpdate u;
    imr::io::KeyframeInfo info;
    while (source->Next(&u, &info)) {
    }
  });
  return 0;
}
