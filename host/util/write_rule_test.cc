#include "host/util/write_rule.h"

#include "host/util/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace imr {
namespace {
namespace fs = std::filesystem;

class WriteRule : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("imr-write-rule-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  static std::string Read(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  static void Write(const fs::path& p, const std::string& text) {
    std::ofstream(p, std::ios::binary) << text;
  }
  // Runs `write`, expects WriteRefused whose message holds `path` and `why`.
  template <typename F>
  static void ExpectRefused(F write, const fs::path& path, const std::string& why) {
    try {
      write();
      ADD_FAILURE() << "not refused: " << path;
    } catch (const WriteRefused& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(path.string()), std::string::npos) << m;
      EXPECT_NE(m.find(why), std::string::npos) << m;
    }
  }
  fs::path dir_;
};

TEST_F(WriteRule, ImrReplacesWhatItWroteButNotAUsersFile) {
  WriteFileAtomically(dir_ / "mesh.ply", "first");
  EXPECT_TRUE(WrittenByImr(dir_ / "mesh.ply"));
  WriteFileAtomically(dir_ / "mesh.ply", "second");
  EXPECT_EQ(Read(dir_ / "mesh.ply"), "second");

  Write(dir_ / "report.json", "the user's own");
  EXPECT_FALSE(WrittenByImr(dir_ / "report.json"));
  ExpectRefused([&] { WriteFileAtomically(dir_ / "report.json", "imr's"); }, dir_ / "report.json",
                "a file imr did not write");
  EXPECT_EQ(Read(dir_ / "report.json"), "the user's own");
}

TEST_F(WriteRule, AFileTheUserChangedIsTheirsAgain) {
  WriteFileAtomically(dir_ / "mesh.ply", "imr's mesh");
  Write(dir_ / "mesh.ply", "edited in MeshLab");
  EXPECT_FALSE(WrittenByImr(dir_ / "mesh.ply"));
  ExpectRefused([&] { WriteFileAtomically(dir_ / "mesh.ply", "again"); }, dir_ / "mesh.ply",
                "changed since imr wrote it");
  EXPECT_EQ(Read(dir_ / "mesh.ply"), "edited in MeshLab");
}

TEST_F(WriteRule, InputsAndWhatLiesInsideInputFoldersAreNeverWritten) {
  fs::create_directories(dir_ / "seq" / "image_2");
  Write(dir_ / "seq" / "image_2" / "000003.png", "pixels");
  Write(dir_ / "in.json", "{}");
  {
    InputScope inputs;
    inputs.Add(dir_ / "seq", "the sequence");
    inputs.Add(dir_ / "in.json", "the job file");
    ExpectRefused([&] { WriteFileAtomically(dir_ / "seq" / "image_2" / "000003.png", "x"); },
                  dir_ / "seq" / "image_2" / "000003.png", "a folder this run reads from");
    ExpectRefused([&] { WriteFileAtomically(dir_ / "seq" / "new.png", "x"); }, dir_ / "seq" / "new.png",
                  "inside");
    ExpectRefused([&] { WriteFileAtomically(dir_ / "in.json", "x"); }, dir_ / "in.json",
                  "the job file, an input of this run");
    // A link to an input is the input; so is a path spelled another way.
    fs::create_symlink(dir_ / "in.json", dir_ / "link.json");
    EXPECT_NE(WhyNotWritable(dir_ / "link.json"), "");
    EXPECT_NE(WhyNotWritable(dir_ / "seq" / ".." / "in.json"), "");
    ExpectRefused([&] { StagingDirectory s(dir_ / "seq" / "colmap"); }, dir_ / "seq" / "colmap",
                  "inside");
    EXPECT_FALSE(fs::exists(dir_ / "seq" / "colmap"));
    EXPECT_EQ(WhyNotWritable(dir_ / "out" / "mesh.ply"), "");
  }
  // The scope ended: they are no inputs any more (but still files imr did not write).
  EXPECT_EQ(WhyNotWritable(dir_ / "seq" / "new.png"), "");
  EXPECT_EQ(Read(dir_ / "in.json"), "{}");
  EXPECT_EQ(Read(dir_ / "seq" / "image_2" / "000003.png"), "pixels");
}

TEST_F(WriteRule, AHardLinkToAnInputIsTheInput) {
  Write(dir_ / "in.json", "{}");
  fs::create_hard_link(dir_ / "in.json", dir_ / "other.json");
  InputScope inputs;
  inputs.Add(dir_ / "in.json", "the stream");
  EXPECT_NE(WhyNotWritable(dir_ / "other.json").find("the stream"), std::string::npos);
}

TEST_F(WriteRule, NoteInputAddsToTheInnermostScopeAndIsIgnoredWithoutOne) {
  Write(dir_ / "a.ply", "a");
  NoteInput(dir_ / "a.ply", "nothing holds it");
  WriteFileAtomically(dir_ / "b.ply", "b");
  {
    InputScope outer;
    {
      InputScope inner;
      NoteInput(dir_ / "b.ply", "the mesh read");
      EXPECT_NE(WhyNotWritable(dir_ / "b.ply").find("the mesh read"), std::string::npos);
    }
    EXPECT_EQ(WhyNotWritable(dir_ / "b.ply"), "");
  }
}

TEST_F(WriteRule, OnlyRegularFilesAreReplaced) {
  fs::create_directories(dir_ / "mesh.ply");
  ExpectRefused([&] { WriteFileAtomically(dir_ / "mesh.ply", "x"); }, dir_ / "mesh.ply",
                "a folder");
  ASSERT_EQ(::mkfifo((dir_ / "fifo.ply").c_str(), 0600), 0);
  ExpectRefused([&] { WriteFileAtomically(dir_ / "fifo.ply", "x"); }, dir_ / "fifo.ply", "a FIFO");
  fs::create_symlink("/dev/null", dir_ / "null.ply");
  ExpectRefused([&] { WriteFileAtomically(dir_ / "null.ply", "x"); }, dir_ / "null.ply",
                "a symbolic link");
  EXPECT_TRUE(fs::is_symlink(dir_ / "null.ply"));
}

TEST_F(WriteRule, ACommitRefusedForOneFileMovesNone) {
  Write(dir_ / "mesh.bin", "the user's");
  StagingDirectory staging(dir_);
  Write(staging.path() / "mesh.gltf", "gltf");
  Write(staging.path() / "mesh.bin", "bin");
  ExpectRefused([&] { staging.Commit("mesh.gltf"); }, dir_ / "mesh.bin", "did not write");
  EXPECT_FALSE(fs::exists(dir_ / "mesh.gltf"));
  EXPECT_EQ(Read(dir_ / "mesh.bin"), "the user's");
}

TEST_F(WriteRule, CopiesAreRecordedToo) {
  Write(dir_ / "src.ply", "a mesh");
  CopyFileAtomically(dir_ / "src.ply", dir_ / "out.ply");
  EXPECT_TRUE(WrittenByImr(dir_ / "out.ply"));
  CopyFileAtomically(dir_ / "src.ply", dir_ / "out.ply");
  Write(dir_ / "user.ply", "mine");
  ExpectRefused([&] { CopyFileAtomically(dir_ / "src.ply", dir_ / "user.ply"); }, dir_ / "user.ply",
                "did not write");
}

TEST_F(WriteRule, RemovalTakesOnlyWhatImrWrote) {
  WriteFileAtomically(dir_ / "tile_000001.glb", "imr's tile");
  Write(dir_ / "tile_555555.glb", "the user's tile");
  std::string why;
  EXPECT_TRUE(RemoveWrittenFile(dir_ / "tile_000001.glb", &why)) << why;
  EXPECT_FALSE(fs::exists(dir_ / "tile_000001.glb"));
  EXPECT_FALSE(RemoveWrittenFile(dir_ / "tile_555555.glb", &why));
  EXPECT_NE(why.find("left in place"), std::string::npos) << why;
  EXPECT_TRUE(fs::exists(dir_ / "tile_555555.glb"));
  EXPECT_TRUE(RemoveWrittenFile(dir_ / "never-there.glb"));
}

TEST_F(WriteRule, AClaimWithoutItsRenameKeepsTheFileBeforeItImrs) {
  // A kill between the ledger's line and the rename: the old bytes are still claimed.
  WriteFileAtomically(dir_ / "tileset.json", "state 1");
  RecordWritten(dir_ / "tileset.json", std::string(64, 'a'), 7);
  EXPECT_TRUE(WrittenByImr(dir_ / "tileset.json"));
  // A half line at the end (killed mid-append) is no claim and breaks no other.
  std::ofstream(dir_ / kWriteLedgerName, std::ios::app) << "0123";
  EXPECT_TRUE(WrittenByImr(dir_ / "tileset.json"));
}

TEST_F(WriteRule, TheLedgerStaysSmallOverManyRewrites) {
  // A tileset rewritten after each of 20,000 tiles (the claims alone: the writes' fsyncs would
  // make this slow, not different).
  WriteFileAtomically(dir_ / "tile.glb", "a tile");
  for (int i = 0; i < 20000; ++i) RecordWritten(dir_ / "tileset.json", std::string(64, 'b'), i);
  WriteFileAtomically(dir_ / "tileset.json", "the last state");
  EXPECT_TRUE(WrittenByImr(dir_ / "tile.glb"));
  EXPECT_LT(fs::file_size(dir_ / kWriteLedgerName), 2u << 20);
  EXPECT_TRUE(WrittenByImr(dir_ / "tileset.json"));
}

TEST_F(WriteRule, ConcurrentWritersInOneFolderLoseNoClaim) {
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int i = 0; i < 50; ++i)
        WriteFileAtomically(dir_ / ("f" + std::to_string(t) + "_" + std::to_string(i)), "x");
    });
  for (auto& th : threads) th.join();
  for (int t = 0; t < 4; ++t)
    for (int i = 0; i < 50; ++i)
      EXPECT_TRUE(WrittenByImr(dir_ / ("f" + std::to_string(t) + "_" + std::to_string(i))));
}

TEST_F(WriteRule, FilesReadInsideAnInputFolderAreCoveredByIt) {
  fs::create_directories(dir_ / "seq" / "image_0");
  InputScope inputs;
  inputs.Add(dir_ / "seq", "the sequence");
  for (int i = 0; i < 1000; ++i) NoteInput(dir_ / "seq" / "image_0" / (std::to_string(i) + ".png"), "an image");
  EXPECT_NE(WhyNotWritable(dir_ / "seq" / "image_0" / "7.png").find("the sequence"), std::string::npos);
  Write(dir_ / "other.png", "x");
  NoteInput(dir_ / "other.png", "an image elsewhere");
  EXPECT_NE(WhyNotWritable(dir_ / "other.png").find("an image elsewhere"), std::string::npos);
}

}  // namespace
}  // namespace imr
