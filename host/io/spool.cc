#include "host/io/spool.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace imr::io {
namespace fs = std::filesystem;

namespace {

[[noreturn]] void Fail(const fs::path& path, const std::string& what, int err) {
  throw std::runtime_error(path.string() + ": " + what + ": " + std::strerror(err));
}

}  // namespace

SpoolWriter::SpoolWriter(fs::path path, bool sync) : path_(std::move(path)), sync_(sync) {
  fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) Fail(path_, "cannot write", errno);
  buffer_.reserve(kBufferBytes);
}

SpoolWriter::~SpoolWriter() {
  if (fd_ >= 0) ::close(fd_);  // a failed run: the owner removes the file
}

void SpoolWriter::Write(const void* data, std::size_t n) {
  if (fd_ < 0) throw std::logic_error(path_.string() + ": written after Close");
  bytes_ += n;
  if (buffer_.size() + n > kBufferBytes) Flush();
  if (n >= kBufferBytes) {  // a large block goes straight out: the buffer stays its size
    WriteAll(static_cast<const char*>(data), n);
    return;
  }
  buffer_.append(static_cast<const char*>(data), n);
}

void SpoolWriter::WriteAll(const char* data, std::size_t n) {
  std::size_t at = 0;
  while (at < n) {
    const ssize_t w = ::write(fd_, data + at, n - at);
    if (w < 0) {
      if (errno == EINTR) continue;
      Fail(path_, "write failed", errno);
    }
    at += static_cast<std::size_t>(w);
  }
}

void SpoolWriter::Flush() {
  WriteAll(buffer_.data(), buffer_.size());
  buffer_.clear();
}

void SpoolWriter::Close() {
  if (fd_ < 0) return;
  Flush();
  if (sync_ && ::fsync(fd_) != 0) Fail(path_, "cannot flush to disk", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) Fail(path_, "cannot close", errno);
  std::string().swap(buffer_);
}

SpoolReader::SpoolReader(fs::path path) : path_(std::move(path)), buffer_(SpoolWriter::kBufferBytes) {
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) Fail(path_, "cannot read", errno);
}

SpoolReader::~SpoolReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool SpoolReader::Fill() {
  for (;;) {
    const ssize_t r = ::read(fd_, buffer_.data(), buffer_.size());
    if (r < 0) {
      if (errno == EINTR) continue;
      Fail(path_, "read failed", errno);
    }
    at_ = 0;
    end_ = static_cast<std::size_t>(r);
    return r > 0;
  }
}

bool SpoolReader::Read(void* data, std::size_t n) {
  char* out = static_cast<char*>(data);
  std::size_t got = 0;
  while (got < n) {
    if (at_ == end_ && !Fill()) {
      if (got == 0) return false;
      throw std::runtime_error(path_.string() + ": ends within a record (" + std::to_string(got) +
                               " of " + std::to_string(n) + " bytes): the spool is damaged");
    }
    const std::size_t take = std::min(n - got, end_ - at_);
    std::memcpy(out + got, buffer_.data() + at_, take);
    at_ += take;
    got += take;
  }
  return true;
}

std::size_t SpoolReader::ReadUpTo(void* data, std::size_t n) {
  if (at_ == end_ && !Fill()) return 0;
  const std::size_t take = std::min(n, end_ - at_);
  std::memcpy(data, buffer_.data() + at_, take);
  at_ += take;
  return take;
}

}  // namespace imr::io
