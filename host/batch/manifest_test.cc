#include "host/batch/manifest.h"

#include "host/util/sha256.h"

#include <gtest/gtest.h>

#include <fstream>
#include <random>

namespace imr::batch {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

TEST(Sha256, KnownVectors) {  // FIPS 180-4 examples
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  Sha256 million;
  const std::string chunk(1000, 'a');
  for (int i = 0; i < 1000; ++i) million.Update(chunk);
  EXPECT_EQ(million.HexDigest(), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

class ManifestTest : public ::testing::Test {
 protected:
  ManifestTest() {
    dir_ = fs::temp_directory_path() / ("imr-manifest-test-" + std::to_string(std::random_device{}()));
    fs::create_directories(dir_ / "snapshots");
  }
  ~ManifestTest() override { fs::remove_all(dir_); }
  fs::path Write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name, std::ios::binary) << text;
    return dir_ / name;
  }
  json Identity(int window) const {
    return {{"imr", "0.1.0"}, {"engine", {{"window", window}}}, {"pipeline", json::array()}};
  }
  fs::path dir_;
};

TEST_F(ManifestTest, RoundTripAndMatch) {
  const auto a = Write("mesh.ply", "ply bytes");
  const auto b = Write("snapshots/mesh_kf000010.ply", "snapshot");
  const auto r = Write("report.json", "{}");
  const Manifest m = MakeManifest("street", Identity(15), {b, a, r}, dir_);
  ASSERT_EQ(m.files.size(), 3u);
  EXPECT_EQ(m.files[0].path, "snapshots/mesh_kf000010.ply");  // relative to the folder
  EXPECT_EQ(m.files[1].bytes, 9u);
  EXPECT_EQ(m.files[1].sha256, Sha256Hex("ply bytes"));
  WriteManifest(m, dir_);
  std::string error;
  const auto back = ReadManifest(dir_, &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->job_hash, HashIdentity(Identity(15)));
  EXPECT_EQ(back->files.size(), 3u);
  const ManifestCheck ok = CheckManifest(dir_, HashIdentity(Identity(15)));
  EXPECT_TRUE(ok.up_to_date) << ok.reason;
}

TEST_F(ManifestTest, AChangedJobOrFileIsNotUpToDate) {
  const auto a = Write("mesh.ply", "ply bytes");
  WriteManifest(MakeManifest("street", Identity(15), {a}, dir_), dir_);
  // Another job: the reason names what changed.
  ManifestCheck c = CheckManifest(dir_, HashIdentity(Identity(16)), Identity(16));
  EXPECT_FALSE(c.up_to_date);
  EXPECT_EQ(c.reason, "the job changed since the last run (engine)");
  // Same size, other bytes.
  Write("mesh.ply", "PLY BYTES");
  c = CheckManifest(dir_, HashIdentity(Identity(15)));
  EXPECT_FALSE(c.up_to_date);
  EXPECT_EQ(c.reason, "mesh.ply changed since it was written (checksum)");
  fs::remove(a);
  c = CheckManifest(dir_, HashIdentity(Identity(15)));
  EXPECT_EQ(c.reason, "mesh.ply is missing");
  fs::remove(dir_ / kManifestFile);
  c = CheckManifest(dir_, HashIdentity(Identity(15)));
  EXPECT_FALSE(c.up_to_date);
  EXPECT_NE(c.reason.find("no manifest"), std::string::npos);
  Write(kManifestFile, "{\"sequence\": ");
  c = CheckManifest(dir_, HashIdentity(Identity(15)));
  EXPECT_FALSE(c.up_to_date);
  EXPECT_NE(c.reason.find("unreadable manifest"), std::string::npos) << c.reason;
}

TEST_F(ManifestTest, FilesOutsideTheFolderAreAbsolute) {
  const fs::path outside = dir_.parent_path() / (dir_.filename().string() + "-stream.json");
  std::ofstream(outside) << "stream";
  const Manifest m = MakeManifest("s", Identity(1), {outside}, dir_);
  EXPECT_EQ(m.files[0].path, outside.string());
  EXPECT_EQ(EntryPath(m.files[0], dir_), outside);
  fs::remove(outside);
}

// Issue 47: the run's last lines name every file it wrote, a tiles folder as one entry.
TEST_F(ManifestTest, WrittenFilesForLogNamesEveryFileAndFoldsAFolderOfMany) {
  Manifest m;
  for (const char* p : {"/x/colmap/cameras.txt", "/x/colmap/images.txt", "/x/colmap/points3D.txt",
                        "/x/stream.json", "tiles/tile_000001.glb", "tiles/tile_000002.glb",
                        "tiles/tile_000003.glb", "tiles/tile_000004.glb", "tileset.json",
                        "mesh.ply", "report.json"})
    m.files.push_back({p, 1, ""});
  EXPECT_EQ(WrittenFilesForLog(m),
            std::vector<std::string>({"tileset.json", "mesh.ply", "report.json",
                                      "/x/colmap/cameras.txt", "/x/colmap/images.txt",
                                      "/x/colmap/points3D.txt", "/x/stream.json",
                                      "tiles/ (4 files)", "manifest.json"}));
}

TEST_F(ManifestTest, LeftoversOfAKilledRunGoFinalNamesStay) {
  Write("mesh.ply", "whole");
  Write(".mesh.ply.tmp-0123456789ab", "half");
  Write("snapshots/.mesh_kf000005.ply.tmp-abc", "half");
  fs::create_directories(dir_ / ".imr-staging-0123456789ab");
  Write(".imr-staging-0123456789ab/mesh.glb", "half");
  Write(".hidden-but-ours-not", "keep");
  EXPECT_EQ(RemoveLeftovers(dir_), 3);
  EXPECT_TRUE(fs::exists(dir_ / "mesh.ply"));
  EXPECT_TRUE(fs::exists(dir_ / ".hidden-but-ours-not"));
  EXPECT_FALSE(fs::exists(dir_ / ".imr-staging-0123456789ab"));
  EXPECT_FALSE(fs::exists(dir_ / "snapshots/.mesh_kf000005.ply.tmp-abc"));
  EXPECT_EQ(RemoveLeftovers(dir_ / "nonexistent"), 0);
}

}  // namespace
}  // namespace imr::batch
