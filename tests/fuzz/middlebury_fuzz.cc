// Middlebury camera parameters (host/io/image_sequence.h ReadMiddlebury): a *_par.txt file beside
// two small PNGs (view0.png, view1.png) that the seeds name.
#include <cstddef>
#include <cstdint>

#include "host/io/image_sequence.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto dir = imr::fuzz::ScratchDir() / "middlebury";
  static const bool images = [&] {
    imr::fuzz::WriteFile(dir / "view0.png", imr::fuzz::TinyPng());
    imr::fuzz::WriteFile(dir / "view1.png", imr::fuzz::TinyPng());
    return true;
  }();
  (void)images;
  const auto file = dir / "scene_par.txt";
  imr::fuzz::WriteFile(file, {reinterpret_cast<const char*>(data), size});
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    imr::io::ImageSequenceOptions o;
    o.frame_step = 1 + static_cast<int>(size % 2);
    (void)imr::io::ReadMiddlebury(file.string(), o);
  });
  return 0;
}
