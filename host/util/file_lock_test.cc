#include "host/util/file_lock.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <random>

namespace imr {
namespace {
namespace fs = std::filesystem;

TEST(FileLock, ExclusiveAgainstEverythingSharedAgainstExclusive) {
  const fs::path dir = fs::temp_directory_path() / ("imr-lock-test-" + std::to_string(std::random_device{}()));
  fs::create_directories(dir);
  const fs::path file = dir / "lock";
  {
    FileLock a = FileLock::TryLock(file, true);
    ASSERT_TRUE(a.held()) << a.error();
    EXPECT_TRUE(a.Describe("pid 1 on h\n"));
    const FileLock b = FileLock::TryLock(file, false);  // another open file description
    EXPECT_FALSE(b.held());
    EXPECT_TRUE(b.busy());
    const auto holders = LockHolders(file);
    EXPECT_NE(std::find(holders.begin(), holders.end(), ::getpid()), holders.end());
    std::ifstream in(file);
    std::string text;
    std::getline(in, text);
    EXPECT_EQ(text, "pid 1 on h");
  }
  FileLock s1 = FileLock::TryLock(file, false), s2 = FileLock::TryLock(file, false);
  EXPECT_TRUE(s1.held() && s2.held());
  EXPECT_TRUE(FileLock::TryLock(file, true).busy());
  // Folders lock too.
  FileLock d = FileLock::TryLock(dir, true);
  EXPECT_TRUE(d.held()) << d.error();
  EXPECT_TRUE(FileLock::TryLock(dir, true).busy());
  s1 = FileLock();
  s2 = FileLock();
  EXPECT_TRUE(FileLock::TryLock(file, true).held());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace imr
