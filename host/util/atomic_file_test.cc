#include "host/util/atomic_file.h"

#include "host/util/write_rule.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace imr {
namespace {
namespace fs = std::filesystem;

class AtomicFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("imr-atomic-" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "-" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  static std::string Read(const fs::path& p) {
    std::ifstream in(p);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  // Entries other than imr's ledger of what it wrote (host/util/write_rule.h).
  static int CountEntries(const fs::path& p) {
    int n = 0;
    for (const auto& e : fs::directory_iterator(p)) n += e.path().filename() != kWriteLedgerName;
    return n;
  }
  fs::path dir_;
};

TEST_F(AtomicFile, WritesAndReplacesWithoutLeavingTemporaries) {
  WriteFileAtomically(dir_ / "a.json", "first");
  WriteFileAtomically(dir_ / "a.json", "second");
  EXPECT_EQ(Read(dir_ / "a.json"), "second");
  EXPECT_EQ(CountEntries(dir_), 1);
}

TEST_F(AtomicFile, NamesUpToNameMaxFit) {
  // The temporary adds 18 bytes to the name: a 255-byte name used to fail ("File name too long").
  const std::string name(250, 'n');
  WriteFileAtomically(dir_ / (name + ".json"), "long");
  EXPECT_EQ(Read(dir_ / (name + ".json")), "long");
  EXPECT_EQ(CountEntries(dir_), 1);
}

TEST_F(AtomicFile, FailureNamesThePathAndKeepsTheOldFile) {
  WriteFileAtomically(dir_ / "keep.txt", "old");
  // Root ignores permission bits, so make the folder impossible instead: a file in its way.
  WriteFileAtomically(dir_ / "blocker", "x");
  try {
    WriteFileAtomically(dir_ / "blocker" / "out.txt", "new");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("blocker/out.txt"), std::string::npos) << e.what();
  }
  EXPECT_EQ(Read(dir_ / "keep.txt"), "old");
}

TEST_F(AtomicFile, EnsureWritableDirectoryRejectsAFile) {
  WriteFileAtomically(dir_ / "file", "x");
  EXPECT_THROW(EnsureWritableDirectory(dir_ / "file"), std::runtime_error);
  EXPECT_THROW(EnsureWritableDirectory(dir_ / "file" / "sub"), std::runtime_error);
  EXPECT_NO_THROW(EnsureWritableDirectory(dir_ / "new" / "deep"));
}

TEST_F(AtomicFile, StagingCommitMovesFilesAndCleansUp) {
  const fs::path out = dir_ / "out";
  {
    StagingDirectory staging(out);
    WriteFileAtomically(staging.path() / "mesh.bin", "bin");
    WriteFileAtomically(staging.path() / "mesh.gltf", "gltf");
    auto files = staging.Commit("mesh.gltf");
    ASSERT_EQ(files.size(), 2u);
    EXPECT_EQ(files.back().filename(), "mesh.gltf");  // the referencing file lands last
  }
  EXPECT_EQ(Read(out / "mesh.gltf"), "gltf");
  EXPECT_EQ(Read(out / "mesh.bin"), "bin");
  EXPECT_EQ(CountEntries(out), 2);  // staging folder gone
}

TEST_F(AtomicFile, StagingCommitsTheNamedFilesLastInTheirOrder) {
  // The pipeline stages report.json with the meshes: it lands after the glTF that needs the .bin.
  const fs::path out = dir_ / "out";
  StagingDirectory staging(out);
  for (const char* name : {"report.json", "mesh.gltf", "mesh.bin", "mesh.ply"})
    WriteFileAtomically(staging.path() / name, name);
  const std::vector<std::string> last = {"mesh.gltf", "report.json"};
  std::vector<std::string> staged;
  for (const auto& f : staging.Staged(last)) staged.push_back(f.filename().string());
  EXPECT_EQ(staged, (std::vector<std::string>{"mesh.bin", "mesh.ply", "mesh.gltf", "report.json"}));
  std::vector<std::string> committed;
  for (const auto& f : staging.Commit(last)) committed.push_back(f.filename().string());
  EXPECT_EQ(committed, staged);
  EXPECT_EQ(Read(out / "report.json"), "report.json");
}

TEST_F(AtomicFile, StagingWithoutCommitLeavesNothing) {
  const fs::path out = dir_ / "out";
  {
    StagingDirectory staging(out);
    WriteFileAtomically(staging.path() / "mesh.obj", "partial");
  }
  EXPECT_EQ(CountEntries(out), 0);
}

TEST_F(AtomicFile, CopyIsWholeOrAbsent) {
  const std::string big(3 << 20, 'm');  // more than one buffer
  WriteFileAtomically(dir_ / "mesh.ply", big);
  CopyFileAtomically(dir_ / "mesh.ply", dir_ / "Mesh.PLY");
  EXPECT_EQ(Read(dir_ / "Mesh.PLY"), big);
  // Onto a folder: refused by the write rule before anything is written, the folder kept.
  fs::create_directories(dir_ / "out.ply");
  try {
    CopyFileAtomically(dir_ / "mesh.ply", dir_ / "out.ply");
    ADD_FAILURE() << "copied onto a folder";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir_ / "out.ply").string() + ": a folder, not a file imr wrote"),
              std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(fs::is_directory(dir_ / "out.ply"));
  EXPECT_EQ(CountEntries(dir_), 3);  // mesh.ply, Mesh.PLY, out.ply: no temporary
  EXPECT_THROW(CopyFileAtomically(dir_ / "missing.ply", dir_ / "x.ply"), std::runtime_error);
}

}  // namespace
}  // namespace imr
