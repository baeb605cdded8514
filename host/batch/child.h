// Child processes for isolation: each sequence of `imr run` runs in a child (the same imr
// executable with a hidden subcommand), so a plugin that segfaults, aborts or eats the memory
// fails that sequence only. The child's stdout+stderr come back on one pipe (its log, kept for
// the "last log lines" of a failure) and its progress and result on another (fd 3).
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "host/util/shell.h"

namespace imr::batch {

// The fd a child writes its messages (JSON lines) to.
inline constexpr int kChildMessageFd = 3;

struct ChildProcess {
  pid_t pid = -1;
  int output_fd = -1;   // read end: the child's stdout and stderr
  int message_fd = -1;  // read end: the child's fd 3
};

// Starts argv[0] (a path) with argv; stdin is /dev/null. Both read ends are non-blocking and
// close-on-exec. Throws std::runtime_error when the process cannot be started.
ChildProcess SpawnChild(const std::vector<std::string>& argv);

// Splits a byte stream into lines.
class LineBuffer {
 public:
  void Feed(const char* data, std::size_t size) { pending_.append(data, size); }
  // The next complete line (without '\n'); at end of stream, the unterminated rest.
  bool Next(std::string* line, bool end_of_stream = false);

 private:
  std::string pending_;
};

// Reads what is available from a non-blocking fd into `buffer`. Returns false at end of stream
// (or on an error other than EAGAIN/EINTR).
bool ReadAvailable(int fd, LineBuffer* buffer);

// The last `capacity` lines seen.
class LogTail {
 public:
  explicit LogTail(std::size_t capacity = 20) : capacity_(capacity) {}
  void Add(std::string line);
  std::vector<std::string> Lines() const { return {lines_.begin(), lines_.end()}; }

 private:
  std::size_t capacity_;
  std::deque<std::string> lines_;
};

// "SIGSEGV" (or "signal 77" for one without a name).
std::string SignalName(int signal);
// "signal SIGSEGV (Segmentation fault)".
std::string DescribeSignal(int signal);

// A process's resident set size in bytes (VmRSS); nullopt when it cannot be read.
std::optional<uint64_t> ResidentBytes(pid_t pid);

// "512M", "2G", "1.5G", "1000000" (bytes; K/M/G/T are powers of 1024). nullopt when malformed.
std::optional<uint64_t> ParseBytes(const std::string& text);
// 1536 -> "1.5 KiB".
std::string FormatBytes(uint64_t bytes);

// Runs argv (argv[0] searched in PATH) to completion with stdin from /dev/null and returns its
// exit status (128 + signal when killed); stdout and stderr are captured. Throws when it cannot
// be started (e.g. not installed), naming the program.
int RunAndCapture(const std::vector<std::string>& argv, std::string* out, std::string* err);

// Quotes a word for a POSIX shell when it needs it (host/util/shell.h).
using ::imr::ShellQuote;

}  // namespace imr::batch
