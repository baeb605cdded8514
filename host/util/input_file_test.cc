#include "host/util/input_file.h"

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <future>
#include <string>

namespace imr {
namespace {
namespace fs = std::filesystem;

class InputFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("imr-input-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path Write(const std::string& name, const std::string& bytes) {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
    return dir_ / name;
  }
  fs::path Fifo(const std::string& name) {
    const fs::path p = dir_ / name;
    EXPECT_EQ(::mkfifo(p.c_str(), 0600), 0);
    return p;
  }
  // The message `f` throws, run on a thread so that a blocking open fails the test in 5 s
  // instead of hanging it (the thread is then left behind: the test process ends anyway).
  template <typename F>
  std::string ErrorWithin5s(F f) {
    auto result = std::async(std::launch::async, [f]() -> std::string {
      try {
        f();
      } catch (const std::runtime_error& e) {
        return e.what();
      }
      return "(no error)";
    });
    if (result.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
      ADD_FAILURE() << "still blocked after 5 s";
      std::_Exit(1);  // the blocked thread cannot be joined
    }
    return result.get();
  }
  fs::path dir_;
};

TEST_F(InputFileTest, ReadsARegularFileWhole) {
  const fs::path p = Write("a.txt", std::string("line 1\nline 2\n\0tail", 19));
  const std::string text = ReadInputFile(p, "a text file");
  EXPECT_EQ(text, std::string("line 1\nline 2\n\0tail", 19));
  InputFile f = InputFile::Open(p, "a text file");
  EXPECT_EQ(f.size(), 19u);
  EXPECT_EQ(f.path(), p);
  EXPECT_NO_THROW(CheckInputFile(p, "a text file"));
  EXPECT_EQ(InputFileProblem(p, "a text file"), "");
}

TEST_F(InputFileTest, RefusesAFifoWithoutBlocking) {
  const fs::path p = Fifo("in.json");
  const std::string e = ErrorWithin5s([p] { ReadInputFile(p, "a SLAM JSON file"); });
  EXPECT_EQ(e, p.string() + ": is not a regular file (a FIFO), expected a SLAM JSON file");
  EXPECT_EQ(ErrorWithin5s([p] { InputStream in(p, "x"); }),
            p.string() + ": is not a regular file (a FIFO), expected x");
  EXPECT_EQ(InputFileProblem(p, "x"), "is not a regular file (a FIFO), expected x");
}

TEST_F(InputFileTest, RefusesADeviceBehindASymlink) {
  const fs::path p = dir_ / "tileset.json";
  fs::create_symlink("/dev/zero", p);
  EXPECT_EQ(ErrorWithin5s([p] { ReadInputFile(p, "a tileset"); }),
            p.string() + ": is not a regular file (a character device), expected a tileset");
}

TEST_F(InputFileTest, RefusesAFolderASocketAndNothing) {
  const fs::path folder = dir_ / "tile_000001.glb";
  fs::create_directories(folder);
  EXPECT_EQ(ErrorWithin5s([folder] { ReadInputFile(folder, "a GLB tile"); }),
            folder.string() + ": is a folder, expected a GLB tile");

  const fs::path sock = dir_ / "s";
  const int s = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(s, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(sock.string().size(), sizeof(addr.sun_path));
  std::strncpy(addr.sun_path, sock.c_str(), sizeof(addr.sun_path) - 1);
  ASSERT_EQ(::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  EXPECT_EQ(ErrorWithin5s([sock] { ReadInputFile(sock, "a mesh"); }),
            sock.string() + ": is not a regular file (a socket), expected a mesh");
  ::close(s);

  const fs::path none = dir_ / "none.ply";
  EXPECT_EQ(ErrorWithin5s([none] { ReadInputFile(none, "a mesh"); }),
            none.string() + ": no such file, expected a mesh");
  const fs::path dangling = dir_ / "dangling.ply";
  fs::create_symlink(dir_ / "gone.ply", dangling);
  EXPECT_EQ(ErrorWithin5s([dangling] { ReadInputFile(dangling, "a mesh"); }),
            dangling.string() + ": is a symbolic link to nothing (" + (dir_ / "gone.ply").string() +
                "), expected a mesh");
}

TEST_F(InputFileTest, BoundsTheBytesRead) {
  const fs::path p = Write("big.json", std::string(1000, 'x'));
  EXPECT_EQ(ReadInputFile(p, "a job file", 1000).size(), 1000u);
  EXPECT_EQ(ErrorWithin5s([p] { ReadInputFile(p, "a job file", 999); }),
            p.string() + ": more than 999 bytes, expected a job file");
}

TEST_F(InputFileTest, StreamsLinesAndSeeks) {
  std::string text;
  for (int i = 0; i < 20000; ++i) text += "line " + std::to_string(i) + "\n";
  const fs::path p = Write("lines.txt", text);
  InputStream in(p, "lines");
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ASSERT_EQ(line, "line " + std::to_string(n));
    ++n;
  }
  EXPECT_EQ(n, 20000);
  // Seeks past the buffer, within it, and from the end.
  in.clear();
  in.seekg(static_cast<std::streamoff>(text.find("line 15000")));
  std::getline(in, line);
  EXPECT_EQ(line, "line 15000");
  in.seekg(-11, std::ios::cur);
  std::getline(in, line);
  EXPECT_EQ(line, "line 15000");
  in.seekg(-11, std::ios::end);
  std::getline(in, line);
  EXPECT_EQ(line, "line 19999");
  in.seekg(0);
  char head[6] = {};
  in.read(head, 5);
  EXPECT_EQ(std::string(head), "line ");
  EXPECT_EQ(in.tellg(), 5);
}

}  // namespace
}  // namespace imr
