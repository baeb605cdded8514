#include "host/util/file_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

namespace imr {
namespace fs = std::filesystem;

FileLock::~FileLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

FileLock::FileLock(FileLock&& other) noexcept
    : fd_(other.fd_), busy_(other.busy_), error_(std::move(other.error_)) {
  other.fd_ = -1;
}

FileLock& FileLock::operator=(FileLock&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.fd_;
    busy_ = other.busy_;
    error_ = std::move(other.error_);
    other.fd_ = -1;
  }
  return *this;
}

FileLock FileLock::TryLock(const fs::path& path, bool exclusive) {
  FileLock lock;
  std::error_code ec;
  const bool folder = fs::is_directory(path, ec);
  const int fd = folder ? ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)
                        : ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    lock.error_ = path.string() + ": cannot open for locking: " + std::strerror(errno);
    return lock;
  }
  while (::flock(fd, (exclusive ? LOCK_EX : LOCK_SH) | LOCK_NB) != 0) {
    if (errno == EINTR) continue;
    const int err = errno;
    ::close(fd);
    if (err == EWOULDBLOCK) lock.busy_ = true;
    else lock.error_ = path.string() + ": cannot lock: " + std::strerror(err);
    return lock;
  }
  lock.fd_ = fd;
  return lock;
}

bool FileLock::Describe(const std::string& text) const {
  if (fd_ < 0 || ::ftruncate(fd_, 0) != 0) return false;
  return ::pwrite(fd_, text.data(), text.size(), 0) == static_cast<ssize_t>(text.size());
}

std::vector<pid_t> LockHolders(const fs::path& path) {
  // Lines like "1: FLOCK  ADVISORY  WRITE 4242 00:2e:1234567 0 EOF"; waiters have "->".
  std::vector<pid_t> pids;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return pids;
  std::ifstream in("/proc/locks");
  for (std::string line; std::getline(in, line);) {
    std::istringstream words(line);
    std::string number, type, mode, access, device;
    pid_t pid = 0;
    if (!(words >> number >> type)) continue;
    if (type == "->") continue;
    if (!(words >> mode >> access >> pid >> device)) continue;
    unsigned major_id = 0, minor_id = 0;
    unsigned long long inode = 0;
    if (std::sscanf(device.c_str(), "%x:%x:%llu", &major_id, &minor_id, &inode) != 3) continue;
    if (inode == st.st_ino && major_id == major(st.st_dev) && minor_id == minor(st.st_dev))
      pids.push_back(pid);
  }
  return pids;
}

}  // namespace imr
