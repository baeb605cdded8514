// The one rule for opening inputs (docs/reliability.md, "Reading"): every file imr reads is a
// regular file, opened here. A FIFO, a device (a symlink to /dev/zero), a socket or a folder where
// a file is expected is refused by name without blocking: the file is opened with O_NONBLOCK (the
// open of a FIFO would wait for a writer), checked with fstat (a stat before the open would leave
// a window in which the name is swapped), and only then read, blocking again. On regular files a
// read always ends, so every reader is bounded by --stage-timeout, SIGTERM and Ctrl-C.
// Errors are std::runtime_error naming the file and what was expected there:
//   "<path>: no such file, expected <what>"
//   "<path>: is a folder, expected <what>"
//   "<path>: is not a regular file (a FIFO), expected <what>"
//   "<path>: is a symbolic link to nothing (<target>), expected <what>"
//   "<path>: cannot open for reading (<reason>), expected <what>"
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <streambuf>
#include <string>
#include <string_view>

namespace imr {

// Whether the file is an input of the run, which the write rule then protects
// (host/util/write_rule.h), or one the rule must not protect from imr itself: a file imr wrote
// and reads back to decide what to write (a report, a manifest, a tileset a re-run replaces), or
// a file only hashed (its reader notes it when it reads it).
enum class InputRole { kInput, kOwnOutput };

// What a reader reads at most when it names no bound: no input imr reads whole is near this.
inline constexpr uint64_t kDefaultMaxInputBytes = uint64_t{1} << 32;  // 4 GiB

// Why `path` cannot be opened as an input (the messages above, without "<path>: "), or "" when
// it is a regular file. Opens nothing (a stat): for listings and checks before a run; readers
// open through InputFile, which checks again on the open descriptor.
std::string InputFileProblem(const std::filesystem::path& path, std::string_view what);

// An open regular file. Move-only; closes on destruction.
class InputFile {
 public:
  // Opens `path` by the rule above, or throws naming it.
  static InputFile Open(const std::filesystem::path& path, std::string_view what,
                        InputRole role = InputRole::kInput);

  InputFile(InputFile&& other) noexcept;
  InputFile& operator=(InputFile&& other) noexcept;
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  ~InputFile();

  int fd() const { return fd_; }
  const std::filesystem::path& path() const { return path_; }
  const std::string& what() const { return what_; }
  // The size fstat gave at the open.
  uint64_t size() const { return size_; }

  // Up to `n` bytes at the current position; 0 at the end. Throws "<path>: cannot read (...)".
  std::size_t Read(void* buffer, std::size_t n);
  // The rest of the file, at most `max_bytes`; throws "<path>: more than <max_bytes> bytes,
  // expected <what>" beyond (a file that grows while read is cut there too).
  std::string ReadAll(uint64_t max_bytes = kDefaultMaxInputBytes);
  // At most `n` bytes from the current position: fewer only at the end of the file (a head to
  // sniff, or a bound plus one byte to tell a file beyond it).
  std::string ReadUpTo(std::size_t n);
  // Moves the position (lseek's whence); returns the new one, or -1.
  int64_t Seek(int64_t offset, int whence);

 private:
  InputFile(int fd, std::filesystem::path path, std::string what, uint64_t size);
  void Close();

  int fd_ = -1;
  std::filesystem::path path_;
  std::string what_;
  uint64_t size_ = 0;
};

// Throws as InputFile::Open would, opening and closing the file (no read).
void CheckInputFile(const std::filesystem::path& path, std::string_view what,
                    InputRole role = InputRole::kInput);

// The whole file, by the rule, at most `max_bytes` (then throws naming the bound).
std::string ReadInputFile(const std::filesystem::path& path, std::string_view what,
                          uint64_t max_bytes = kDefaultMaxInputBytes,
                          InputRole role = InputRole::kInput);

// A buffered, seekable streambuf over an InputFile, for readers that parse a stream (the SLAM
// JSON sequence is streamed, not read whole). A read error throws from the stream's read
// (std::runtime_error naming the file) rather than quietly ending it.
class InputFileBuf : public std::streambuf {
 public:
  explicit InputFileBuf(InputFile file, std::size_t buffer_bytes = std::size_t{1} << 16);
  const InputFile& file() const { return file_; }

 protected:
  int_type underflow() override;
  pos_type seekoff(off_type off, std::ios_base::seekdir dir,
                   std::ios_base::openmode which) override;
  pos_type seekpos(pos_type pos, std::ios_base::openmode which) override;

 private:
  InputFile file_;
  std::unique_ptr<char[]> buffer_;
  std::size_t buffer_bytes_;
  int64_t buffer_start_ = 0;  // the file offset of eback()
};

// An std::istream over a file opened by the rule: `InputStream in(path, "a JSON file")` throws
// where `std::ifstream in(path)` would have blocked or read a device.
class InputStream : public std::istream {
 public:
  InputStream(const std::filesystem::path& path, std::string_view what,
              InputRole role = InputRole::kInput);
  const InputFile& file() const { return buf_.file(); }

 private:
  InputFileBuf buf_;
};

}  // namespace imr
