// Advisory locks (flock(2)) that can say who holds them: two `imr run` of one batch folder, or
// two jobs writing one output folder, must not interleave. A lock is released when its holder
// closes it or dies (a killed run leaves no stale lock).
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>
#include <vector>

namespace imr {

class FileLock {
 public:
  FileLock() = default;
  ~FileLock();
  FileLock(FileLock&& other) noexcept;
  FileLock& operator=(FileLock&& other) noexcept;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

  // Tries to lock `path` without waiting: a file (created if missing) or a folder. Exclusive,
  // or shared (several shared holders, no exclusive one). On success the lock is held; when
  // another process holds it, held() is false and busy() true; when the file system cannot lock
  // (some network file systems), both are false and error() says why.
  static FileLock TryLock(const std::filesystem::path& path, bool exclusive);

  bool held() const { return fd_ >= 0; }
  bool busy() const { return busy_; }
  const std::string& error() const { return error_; }
  // Replaces the lock file's contents (who holds it, for a later reader); false on failure.
  bool Describe(const std::string& text) const;

 private:
  int fd_ = -1;
  bool busy_ = false;
  std::string error_;
};

// The processes holding a lock on `path`, from /proc/locks (this machine only).
std::vector<pid_t> LockHolders(const std::filesystem::path& path);

}  // namespace imr
