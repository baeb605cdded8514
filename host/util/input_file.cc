#include "host/util/input_file.h"

#include "host/util/write_rule.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <utility>

namespace imr {
namespace fs = std::filesystem;
namespace {

// What a file of mode `mode` is, in the words of the messages; "" for a regular file.
std::string KindProblem(mode_t mode) {
  if (S_ISREG(mode)) return {};
  if (S_ISDIR(mode)) return "is a folder";
  if (S_ISFIFO(mode)) return "is not a regular file (a FIFO)";
  if (S_ISCHR(mode)) return "is not a regular file (a character device)";
  if (S_ISBLK(mode)) return "is not a regular file (a block device)";
  if (S_ISSOCK(mode)) return "is not a regular file (a socket)";
  return "is not a regular file";
}

std::string Expected(std::string_view what) {
  return what.empty() ? std::string() : ", expected " + std::string(what);
}

// Why stat could not see `path` ("no such file", a dangling link, ...), from errno `err`.
std::string MissingProblem(const fs::path& path, int err) {
  if (err == ENOENT) {
    std::error_code ec;
    if (fs::is_symlink(fs::symlink_status(path, ec))) {
      const fs::path target = fs::read_symlink(path, ec);
      return "is a symbolic link to nothing" + (ec ? std::string() : " (" + target.string() + ")");
    }
    return "no such file";
  }
  if (err == ENOTDIR) return "no such file (a part of the path is not a folder)";
  return "cannot open for reading (" + std::string(std::strerror(err)) + ")";
}

[[noreturn]] void Fail(const fs::path& path, const std::string& problem, std::string_view what) {
  throw std::runtime_error(path.string() + ": " + problem + Expected(what));
}

}  // namespace

std::string InputFileProblem(const fs::path& path, std::string_view what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return MissingProblem(path, errno) + Expected(what);
  if (const std::string k = KindProblem(st.st_mode); !k.empty()) return k + Expected(what);
  return {};
}

InputFile InputFile::Open(const fs::path& path, std::string_view what, InputRole role) {
  if (path.empty()) throw std::runtime_error("no file named" + Expected(what));
  // A stat first refuses a device or a FIFO without opening it at all (opening some devices
  // acts); the fstat below is what holds, the name may change in between.
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) Fail(path, MissingProblem(path, errno), what);
  if (const std::string k = KindProblem(st.st_mode); !k.empty()) Fail(path, k, what);

  // O_NONBLOCK: the open of a FIFO returns at once instead of waiting for a writer.
  int fd = -1;
  do {
    fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  } while (fd < 0 && errno == EINTR);
  if (fd < 0) {
    const int err = errno;
    if (err == ENXIO) Fail(path, "is not a regular file (a socket)", what);
    Fail(path, MissingProblem(path, err), what);
  }
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    Fail(path, "cannot open for reading (" + std::string(std::strerror(err)) + ")", what);
  }
  if (const std::string k = KindProblem(st.st_mode); !k.empty()) {
    ::close(fd);
    Fail(path, k, what);
  }
  // A regular file: reads end by themselves, so they may block again as usual.
  if (const int flags = ::fcntl(fd, F_GETFL); flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);

  // The write rule learns of every input here: what a run read is never what it writes.
  if (role == InputRole::kInput) NoteInput(path, what);
  return InputFile(fd, path, std::string(what), static_cast<uint64_t>(st.st_size));
}

InputFile::InputFile(int fd, fs::path path, std::string what, uint64_t size)
    : fd_(fd), path_(std::move(path)), what_(std::move(what)), size_(size) {}

InputFile::InputFile(InputFile&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      path_(std::move(other.path_)),
      what_(std::move(other.what_)),
      size_(other.size_) {}

InputFile& InputFile::operator=(InputFile&& other) noexcept {
  if (this != &other) {
    Close();
    fd_ = std::exchange(other.fd_, -1);
    path_ = std::move(other.path_);
    what_ = std::move(other.what_);
    size_ = other.size_;
  }
  return *this;
}

InputFile::~InputFile() { Close(); }

void InputFile::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

std::size_t InputFile::Read(void* buffer, std::size_t n) {
  for (;;) {
    const ssize_t r = ::read(fd_, buffer, n);
    if (r >= 0) return static_cast<std::size_t>(r);
    if (errno == EINTR) continue;
    throw std::runtime_error(path_.string() + ": cannot read (" + std::strerror(errno) + ")");
  }
}

std::string InputFile::ReadAll(uint64_t max_bytes) {
  std::string text;
  // The size fstat gave, within the bound: one allocation for files that do not change.
  if (size_ > 0 && size_ <= max_bytes) text.reserve(static_cast<std::size_t>(size_));
  char chunk[1 << 16];
  for (;;) {
    const std::size_t n = Read(chunk, sizeof(chunk));
    if (n == 0) break;
    if (text.size() + n > max_bytes)
      Fail(path_, "more than " + std::to_string(max_bytes) + " bytes", what_);
    text.append(chunk, n);
  }
  return text;
}

std::string InputFile::ReadUpTo(std::size_t n) {
  std::string bytes(n, '\0');
  std::size_t got = 0;
  while (got < n) {
    const std::size_t r = Read(bytes.data() + got, n - got);
    if (r == 0) break;
    got += r;
  }
  bytes.resize(got);
  return bytes;
}

int64_t InputFile::Seek(int64_t offset, int whence) {
  return static_cast<int64_t>(::lseek(fd_, static_cast<off_t>(offset), whence));
}

void CheckInputFile(const fs::path& path, std::string_view what, InputRole role) {
  InputFile::Open(path, what, role);
}

std::string ReadInputFile(const fs::path& path, std::string_view what, uint64_t max_bytes,
                          InputRole role) {
  return InputFile::Open(path, what, role).ReadAll(max_bytes);
}

InputFileBuf::InputFileBuf(InputFile file, std::size_t buffer_bytes)
    : file_(std::move(file)),
      buffer_(new char[buffer_bytes > 0 ? buffer_bytes : 1]),
      buffer_bytes_(buffer_bytes > 0 ? buffer_bytes : 1) {
  setg(buffer_.get(), buffer_.get(), buffer_.get());
}

InputFileBuf::int_type InputFileBuf::underflow() {
  if (gptr() < egptr()) return traits_type::to_int_type(*gptr());
  buffer_start_ += egptr() - eback();
  const std::size_t n = file_.Read(buffer_.get(), buffer_bytes_);
  setg(buffer_.get(), buffer_.get(), buffer_.get() + n);
  if (n == 0) return traits_type::eof();
  return traits_type::to_int_type(*gptr());
}

InputFileBuf::pos_type InputFileBuf::seekoff(off_type off, std::ios_base::seekdir dir,
                                             std::ios_base::openmode which) {
  if (!(which & std::ios_base::in)) return pos_type(off_type(-1));
  const int64_t here = buffer_start_ + (gptr() - eback());
  if (dir == std::ios_base::cur && off == 0) return pos_type(off_type(here));
  int64_t target = 0;
  if (dir == std::ios_base::beg) {
    target = off;
  } else if (dir == std::ios_base::cur) {
    target = here + off;
  } else {
    struct stat st {};
    if (::fstat(file_.fd(), &st) != 0) return pos_type(off_type(-1));
    target = static_cast<int64_t>(st.st_size) + off;
  }
  if (target < 0) return pos_type(off_type(-1));
  // Within the buffer: no system call.
  if (target >= buffer_start_ && target <= buffer_start_ + (egptr() - eback())) {
    setg(eback(), eback() + (target - buffer_start_), egptr());
    return pos_type(off_type(target));
  }
  if (file_.Seek(target, SEEK_SET) < 0) return pos_type(off_type(-1));
  buffer_start_ = target;
  setg(buffer_.get(), buffer_.get(), buffer_.get());
  return pos_type(off_type(target));
}

InputFileBuf::pos_type InputFileBuf::seekpos(pos_type pos, std::ios_base::openmode which) {
  return seekoff(off_type(pos), std::ios_base::beg, which);
}

InputStream::InputStream(const fs::path& path, std::string_view what, InputRole role)
    : std::istream(nullptr), buf_(InputFile::Open(path, what, role)) {
  rdbuf(&buf_);
  // A read error reaches the reader as the streambuf's exception, naming the file.
  exceptions(std::ios_base::badbit);
}

}  // namespace imr
