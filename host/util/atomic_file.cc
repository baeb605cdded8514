#include "host/util/atomic_file.h"

#include "host/util/sha256.h"
#include "host/util/write_rule.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <random>
#include <stdexcept>
#include <system_error>

namespace imr {
namespace fs = std::filesystem;
namespace {

std::string RandomSuffix() {
  static thread_local std::mt19937_64 rng{std::random_device{}() ^
                                          static_cast<uint64_t>(::getpid())};
  static const char* kHex = "0123456789abcdef";
  std::string s(12, '0');
  for (char& c : s) c = kHex[rng() & 15];
  return s;
}

[[noreturn]] void Fail(const fs::path& path, const std::string& what) {
  throw std::runtime_error(path.string() + ": " + what);
}

}  // namespace

namespace {

// A temporary beside `path` for its atomic write: ".<name>.tmp-<12 hex>", 18 bytes more than the
// name, which may itself be near NAME_MAX (255); a long name is cut in the temporary (the random
// suffix keeps it unique).
fs::path TemporaryFor(const fs::path& path) {
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  std::string name = path.filename().string();
  if (name.size() > 200) name.resize(200);
  return dir / ("." + name + ".tmp-" + RandomSuffix());
}

// Writes `size` bytes to fd; on failure closes it, removes `tmp` and throws naming `path`.
void WriteAll(int fd, const char* p, std::size_t size, const fs::path& tmp, const fs::path& path) {
  while (size > 0) {
    const ssize_t n = ::write(fd, p, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      Fail(path, std::string("write failed: ") + std::strerror(err));
    }
    p += n;
    size -= static_cast<std::size_t>(n);
  }
}

// Flushes and closes fd, records the bytes in imr's ledger (host/util/write_rule.h) and renames
// `tmp` to `path`; on failure removes `tmp` and throws.
void Finish(int fd, const fs::path& tmp, const fs::path& path, const std::string& sha256,
            uint64_t bytes) {
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    Fail(path, std::string("write failed: ") + std::strerror(err));
  }
  try {
    RecordWritten(path, sha256, bytes);
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    Fail(path, std::string("rename failed: ") + std::strerror(err));
  }
}

}  // namespace

void WriteFileAtomically(const fs::path& path, std::string_view contents) {
  CheckWriteTarget(path);
  const fs::path tmp = TemporaryFor(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) Fail(path, std::string("cannot write: ") + std::strerror(errno));
  WriteAll(fd, contents.data(), contents.size(), tmp, path);
  Finish(fd, tmp, path, Sha256Hex(contents), contents.size());
}

void CopyFileAtomically(const fs::path& from, const fs::path& to) {
  CheckWriteTarget(to);
  const int in = ::open(from.c_str(), O_RDONLY | O_CLOEXEC);
  if (in < 0) Fail(from, std::string("cannot read: ") + std::strerror(errno));
  const fs::path tmp = TemporaryFor(to);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int err = errno;
    ::close(in);
    Fail(to, std::string("cannot write: ") + std::strerror(err));
  }
  std::vector<char> buffer(1 << 20);
  Sha256 hash;
  uint64_t bytes = 0;
  for (;;) {
    const ssize_t n = ::read(in, buffer.data(), buffer.size());
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(in);
      ::close(fd);
      ::unlink(tmp.c_str());
      Fail(from, std::string("read failed: ") + std::strerror(err));
    }
    hash.Update(buffer.data(), static_cast<std::size_t>(n));
    bytes += static_cast<uint64_t>(n);
    try {
      WriteAll(fd, buffer.data(), static_cast<std::size_t>(n), tmp, to);
    } catch (...) {
      ::close(in);
      throw;
    }
  }
  ::close(in);
  Finish(fd, tmp, to, hash.HexDigest(), bytes);
}

void EnsureWritableDirectory(const fs::path& dir) {
  CheckWriteFolder(dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) Fail(dir, "cannot create folder: " + ec.message());
  if (!fs::is_directory(dir)) Fail(dir, "not a folder");
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    Fail(dir, std::string("folder not writable: ") + std::strerror(errno));
}

StagingDirectory::StagingDirectory(const fs::path& destination) : destination_(destination) {
  EnsureWritableDirectory(destination_);
  staging_ = destination_ / (".imr-staging-" + RandomSuffix());
  std::error_code ec;
  if (!fs::create_directory(staging_, ec) || ec)
    Fail(staging_, "cannot create staging folder: " + ec.message());
}

StagingDirectory::~StagingDirectory() {
  std::error_code ec;
  fs::remove_all(staging_, ec);  // best effort; nothing under a final name is touched
}

std::vector<fs::path> StagingDirectory::Staged(const std::vector<std::string>& last) const {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(staging_))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  // 0 for a name not in `last`, else 1 + its place there.
  auto rank = [&](const fs::path& p) {
    const auto it = std::find(last.begin(), last.end(), p.filename().string());
    return it == last.end() ? 0 : 1 + (it - last.begin());
  };
  std::stable_sort(files.begin(), files.end(),
                   [&](const fs::path& a, const fs::path& b) { return rank(a) < rank(b); });
  return files;
}

std::vector<fs::path> StagingDirectory::Commit(const std::vector<std::string>& last) {
  const std::vector<fs::path> files = Staged(last);
  // Every target first: a refusal leaves all of them as they were.
  for (const auto& f : files) CheckWriteTarget(destination_ / f.filename());
  std::vector<fs::path> out;
  for (const auto& f : files) {
    const fs::path target = destination_ / f.filename();
    RecordWrittenFile(f, target);
    std::error_code ec;
    fs::rename(f, target, ec);
    if (ec) Fail(target, "cannot move into place: " + ec.message());
    out.push_back(target);
  }
  committed_ = true;
  return out;
}

}  // namespace imr
