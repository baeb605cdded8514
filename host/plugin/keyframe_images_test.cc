#include "host/plugin/keyframe_images.h"

#include "host/plugin/host_services.h"

#include <imr/sdk/plugin.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sys/stat.h>
#include <unistd.h>

namespace imr::plugin {
namespace {

namespace fs = std::filesystem;

// Three small PNGs (gray 8x4, BGR 6x5, BGR 6x5) in a scratch folder.
class KeyframeImages : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("imr-kfimages-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    for (int i = 0; i < 3; ++i) {
      io::Image im;
      im.width = i == 0 ? 8 : 6;
      im.height = i == 0 ? 4 : 5;
      im.channels = i == 0 ? 1 : 3;
      im.stride_bytes = im.width * im.channels;
      for (int k = 0; k < im.height * im.stride_bytes; ++k)
        im.pixels.push_back(static_cast<uint8_t>(10 * i + k));
      paths_.push_back((dir_ / ("kf" + std::to_string(i) + ".png")).string());
      io::WriteImage(paths_.back(), im);
    }
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::vector<std::string> paths_;
};

TEST_F(KeyframeImages, DecodesOnceAndKeepsWhileTheBudgetHasRoom) {
  KeyframeImageStore store(paths_);
  std::string error;
  imr_image_view v{};
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;
  EXPECT_EQ(v.width, 6);
  EXPECT_EQ(v.height, 5);
  EXPECT_EQ(v.channels, 3);
  EXPECT_EQ(v.pixels[4], 10 + 4);
  store.Release(1);
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;
  store.Release(1);
  EXPECT_EQ(store.stats().decodes, 1);
  EXPECT_EQ(store.stats().requests, 2);
}

TEST_F(KeyframeImages, EvictsReleasedImagesToStayWithinTheBudget) {
  // 90 bytes each for the BGR images: a budget of 100 keeps one.
  KeyframeImageStore store(paths_, {.budget_bytes = 100});
  std::string error;
  imr_image_view v{};
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;
  // Held: the second one does not fit beside it.
  EXPECT_EQ(store.Acquire(2, &v, &error), IMR_ERROR);
  EXPECT_NE(error.find("budget"), std::string::npos) << error;
  store.Release(1);
  ASSERT_EQ(store.Acquire(2, &v, &error), IMR_OK) << error;  // evicts 1
  EXPECT_EQ(store.stats().evictions, 1);
  EXPECT_LE(store.cached_bytes(), 100u);
  EXPECT_LE(store.stats().peak_bytes, 100u);
  store.ReleaseAll();
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;  // decoded again
  EXPECT_EQ(store.stats().decodes, 3);
}

// Between two export calls the host frees what no plugin holds; a held image stays.
TEST_F(KeyframeImages, DropDecodedFreesReleasedImagesOnly) {
  KeyframeImageStore store(paths_);
  std::string error;
  imr_image_view v{};
  ASSERT_EQ(store.Acquire(0, &v, &error), IMR_OK) << error;  // 32 bytes, released below
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;  // 90 bytes, still held
  store.Release(0);
  EXPECT_EQ(store.cached_bytes(), 32u + 90u);
  store.DropDecoded();
  EXPECT_EQ(store.cached_bytes(), 90u);
  EXPECT_EQ(v.pixels[4], 10 + 4);  // the held one untouched
  store.ReleaseAll();
  store.DropDecoded();
  EXPECT_EQ(store.cached_bytes(), 0u);
  ASSERT_EQ(store.Acquire(1, &v, &error), IMR_OK) << error;  // decoded again
  EXPECT_EQ(store.stats().decodes, 3);
  EXPECT_EQ(store.stats().evictions, 2);
}

TEST_F(KeyframeImages, OutOfRangeAndUndecodableAreClearErrors) {
  std::vector<std::string> paths = paths_;
  paths.push_back((dir_ / "missing.png").string());
  KeyframeImageStore store(paths);
  std::string error;
  imr_image_view v{};
  EXPECT_EQ(store.Acquire(4, &v, &error), IMR_INVALID_ARGUMENT);
  EXPECT_EQ(error, "keyframe image 4 is out of range: this export has 4 keyframes (0..3)");
  EXPECT_EQ(store.Acquire(3, &v, &error), IMR_ERROR);
  EXPECT_NE(error.find("keyframe image 3: "), std::string::npos) << error;
  EXPECT_NE(error.find("missing.png"), std::string::npos) << error;
}

// The open rule (issue 44): a keyframe image that is a FIFO, or a PNG cut short, fails at once
// naming the file, not waiting on the FIFO or letting libpng print its own "Read Error".
TEST_F(KeyframeImages, AFifoOrATruncatedPngIsRefusedNamingIt) {
  std::vector<std::string> paths = paths_;
  const fs::path fifo = dir_ / "fifo.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  paths.push_back(fifo.string());
  const fs::path cut = dir_ / "cut.png";
  fs::copy_file(paths_[1], cut);
  fs::resize_file(cut, fs::file_size(cut) - 20);  // inside IDAT or IEND
  paths.push_back(cut.string());
  KeyframeImageStore store(paths);
  std::string error;
  imr_image_view v{};
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(store.Acquire(3, &v, &error), IMR_ERROR);
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  EXPECT_EQ(error, "keyframe image 3: " + fifo.string() +
                       ": is not a regular file (a FIFO), expected an image file (PNG, JPEG)");
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(store.Acquire(4, &v, &error), IMR_ERROR);
  const std::string printed = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(printed, "");  // nothing from libpng itself
  EXPECT_NE(error.find("keyframe image 4: cannot decode " + cut.string()), std::string::npos) << error;
  EXPECT_NE(error.find("(truncated)"), std::string::npos) << error;
  // A byte of the pixel data flipped: IDAT's CRC says so, before libpng would.
  const fs::path flipped = dir_ / "flipped.png";
  std::string bytes;
  {
    std::ifstream in(paths_[1], std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::size_t idat = bytes.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  bytes[idat + 6] = static_cast<char>(bytes[idat + 6] ^ 0x55);
  std::ofstream(flipped, std::ios::binary) << bytes;
  KeyframeImageStore one({flipped.string()});
  ::testing::internal::CaptureStderr();
  EXPECT_EQ(one.Acquire(0, &v, &error), IMR_ERROR);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
  EXPECT_NE(error.find("chunk at byte " + std::to_string(idat - 4) + " fails its CRC (corrupted)"),
            std::string::npos) << error;
}

// Through the services table as a plugin sees it (the SDK's Host wrapper).
TEST_F(KeyframeImages, ServicesServeTheInstalledStoreOnly) {
  const imr::sdk::Host host(HostServices());
  ASSERT_TRUE(host.HasKeyframeImages());
  try {
    host.GetKeyframeImage(0);
    FAIL() << "no store installed: expected an error";
  } catch (const imr::sdk::InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("no keyframe images here"), std::string::npos) << e.what();
  }
  KeyframeImageStore store(paths_);
  {
    ScopedKeyframeImages scope(&store);
    EXPECT_THROW(ScopedKeyframeImages again(&store), std::logic_error);
    imr::sdk::KeyframeImage image = host.GetKeyframeImage(0);
    EXPECT_EQ(image.width(), 8);
    EXPECT_EQ(image.channels(), 1);
    EXPECT_EQ(image.Row(1)[0], 8);
    try {
      host.GetKeyframeImage(3);
      FAIL() << "expected an out-of-range error";
    } catch (const imr::sdk::InvalidArgument& e) {
      EXPECT_STREQ(e.what(), "keyframe image 3 is out of range: this export has 3 keyframes (0..2)");
    }
  }  // the scope ends: every hold is dropped, nothing dangles
  EXPECT_EQ(CurrentKeyframeImages(), nullptr);
  // A 1.0 host's table (40 bytes) has no images: the wrapper says so instead of reading past it.
  imr_host_services old = *HostServices();
  old.struct_size = 40;
  EXPECT_FALSE(imr::sdk::Host(&old).HasKeyframeImages());
  EXPECT_THROW(imr::sdk::Host(&old).GetKeyframeImage(0), std::runtime_error);
}

}  // namespace
}  // namespace imr::plugin
