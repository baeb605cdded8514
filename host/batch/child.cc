#include "host/batch/child.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <stdexcept>

extern char** environ;

namespace imr::batch {
namespace {

void SetNonBlocking(int fd) { ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK); }

struct Pipe {
  int read = -1, write = -1;
  Pipe() {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
      throw std::runtime_error(std::string("cannot create a pipe: ") + std::strerror(errno));
    read = fds[0];
    write = fds[1];
  }
};

std::vector<char*> Argv(const std::vector<std::string>& argv) {
  std::vector<char*> a;
  for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
  a.push_back(nullptr);
  return a;
}

}  // namespace

ChildProcess SpawnChild(const std::vector<std::string>& argv) {
  Pipe out, msg;
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, out.write, 1);
  posix_spawn_file_actions_adddup2(&actions, out.write, 2);
  posix_spawn_file_actions_adddup2(&actions, msg.write, kChildMessageFd);
  // The parent ignores nothing the child should not; reset the handlers it installed.
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t defaults;
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGINT);
  sigaddset(&defaults, SIGTERM);
  sigaddset(&defaults, SIGPIPE);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGDEF);
  pid_t pid = -1;
  auto args = Argv(argv);
  const int rc = ::posix_spawn(&pid, argv[0].c_str(), &actions, &attr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  ::close(out.write);
  ::close(msg.write);
  if (rc != 0) {
    ::close(out.read);
    ::close(msg.read);
    throw std::runtime_error("cannot start " + argv[0] + ": " + std::strerror(rc));
  }
  SetNonBlocking(out.read);
  SetNonBlocking(msg.read);
  return {pid, out.read, msg.read};
}

bool LineBuffer::Next(std::string* line, bool end_of_stream) {
  const auto nl = pending_.find('\n');
  if (nl == std::string::npos) {
    if (!end_of_stream || pending_.empty()) return false;
    *line = std::move(pending_);
    pending_.clear();
    return true;
  }
  *line = pending_.substr(0, nl);
  pending_.erase(0, nl + 1);
  return true;
}

bool ReadAvailable(int fd, LineBuffer* buffer) {
  char buf[8192];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof(buf));
    if (n > 0) {
      buffer->Feed(buf, static_cast<std::size_t>(n));
      continue;
    }
    if (n == 0) return false;
    if (errno == EINTR) continue;
    return errno == EAGAIN || errno == EWOULDBLOCK;
  }
}

void LogTail::Add(std::string line) {
  lines_.push_back(std::move(line));
  while (lines_.size() > capacity_) lines_.pop_front();
}

std::string SignalName(int signal) {
  const char* abbrev = ::sigabbrev_np(signal);
  return abbrev != nullptr ? std::string("SIG") + abbrev : "signal " + std::to_string(signal);
}

std::string DescribeSignal(int signal) {
  const char* what = ::sigdescr_np(signal);
  return "signal " + SignalName(signal) + (what != nullptr ? std::string(" (") + what + ")" : "");
}

std::optional<uint64_t> ResidentBytes(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("VmRSS:", 0) != 0) continue;
    return std::stoull(line.substr(6)) * 1024;  // "VmRSS:   1234 kB"
  }
  return std::nullopt;
}

std::optional<uint64_t> ParseBytes(const std::string& text) {
  if (text.empty()) return std::nullopt;
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  std::string unit = text.substr(used);
  if (!unit.empty() && (unit.back() == 'B' || unit.back() == 'b')) unit.pop_back();
  if (unit.size() == 2 && unit[1] == 'i') unit.pop_back();  // "GiB" -> "G"
  double scale = 1;
  if (unit.size() > 1) return std::nullopt;
  if (!unit.empty()) {
    const std::string units = "KMGT";
    const auto k = units.find(static_cast<char>(std::toupper(static_cast<unsigned char>(unit[0]))));
    if (k == std::string::npos) return std::nullopt;
    scale = std::pow(1024.0, static_cast<double>(k + 1));
  }
  // Past 2^62 bytes (4 EiB) no machine has it, and the conversion would overflow.
  if (!(value > 0) || !(value * scale < 0x1p62)) return std::nullopt;
  return static_cast<uint64_t>(value * scale);
}

std::string FormatBytes(uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double v = static_cast<double>(bytes);
  int u = 0;
  while (v >= 1024 && u < 4) {
    v /= 1024;
    ++u;
  }
  char buf[32];
  if (u == 0)
    std::snprintf(buf, sizeof(buf), "%llu B", static_cast<unsigned long long>(bytes));
  else
    std::snprintf(buf, sizeof(buf), v < 10 ? "%.1f %s" : "%.0f %s", v, units[u]);
  return buf;
}

int RunAndCapture(const std::vector<std::string>& argv, std::string* out, std::string* err) {
  Pipe o, e;
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, o.write, 1);
  posix_spawn_file_actions_adddup2(&actions, e.write, 2);
  pid_t pid = -1;
  auto args = Argv(argv);
  const int rc = ::posix_spawnp(&pid, argv[0].c_str(), &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(o.write);
  ::close(e.write);
  if (rc != 0) {
    ::close(o.read);
    ::close(e.read);
    throw std::runtime_error("cannot run " + argv[0] + ": " + std::strerror(rc));
  }
  // Drain both pipes (either may fill up) until both are closed.
  LineBuffer bo, be;
  pollfd fds[2] = {{o.read, POLLIN, 0}, {e.read, POLLIN, 0}};
  int open = 2;
  while (open > 0) {
    if (::poll(fds, 2, -1) < 0 && errno != EINTR) break;
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || fds[i].revents == 0) continue;
      char buf[4096];
      const ssize_t n = ::read(fds[i].fd, buf, sizeof(buf));
      if (n > 0) {
        (i == 0 ? bo : be).Feed(buf, static_cast<std::size_t>(n));
      } else if (n == 0 || errno != EINTR) {
        ::close(fds[i].fd);
        fds[i].fd = -1;
        --open;
      }
    }
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  std::string line;
  out->clear();
  err->clear();
  while (bo.Next(&line, true)) *out += line + "\n";
  while (be.Next(&line, true)) *err += line + "\n";
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

}  // namespace imr::batch
