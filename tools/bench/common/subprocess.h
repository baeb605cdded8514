// Shared helpers of the imr-bench subcommands that run imr's executables as users do (pipeline,
// paper, peers): where the executables are, shell quoting, running a command (through the shell,
// or directly with its own wall time, peak RSS and a time limit), reading a report.
#pragma once

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/util/shell.h"

namespace imr::bench {

// The folder of the running executable (imr-bench sits beside imr and imr-synth), resolved once:
// main asks first, so a rebuild that relinks the binary during a long benchmark (then
// /proc/self/exe names a deleted file) no longer aborts it at its next subprocess.
inline const std::filesystem::path& ExeDir() {
  static const std::filesystem::path dir = std::filesystem::canonical("/proc/self/exe").parent_path();
  return dir;
}

// `s` as one word for /bin/sh.
inline std::string Quote(const std::string& s) { return ShellQuote(s); }

// Runs `command` with /bin/sh after echoing it to stderr; its exit status (128 when signalled).
inline int Sh(const std::string& command) {
  std::fprintf(stderr, "+ %s\n", command.c_str());
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

// What RunProcess measured of one process.
struct ProcessResult {
  bool started = false;      // fork and exec succeeded
  bool timed_out = false;    // killed (SIGKILL) at the time limit
  int exit_status = -1;      // when it exited; -1 otherwise
  int signal = 0;            // the signal that ended it, if one did
  double seconds = 0.0;      // wall time from fork to exit
  long peak_rss_kb = 0;      // its own peak resident set (wait4's rusage)
  std::string error;         // why it did not start, or how it ended badly; "" when it exited 0
  bool ok() const { return started && !timed_out && exit_status == 0; }
};

namespace detail {

// The child's side of RunProcess: into `work_dir`, stdout and stderr to `log`, then exec; on a
// failure it writes {step, errno} to `fail_fd` (1 chdir, 2 open the log, 3 exec) and exits 127.
[[noreturn]] inline void ExecChild(char* const* args, const std::filesystem::path& work_dir,
                                   const std::filesystem::path& log, int fail_fd) {
  int step = 0;
  if (!work_dir.empty() && chdir(work_dir.c_str()) != 0) step = 1;
  if (step == 0 && !log.empty()) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd < 0 || dup2(fd, 1) < 0 || dup2(fd, 2) < 0) step = 2;
    if (fd > 2) close(fd);
  }
  if (step == 0) {
    execv(args[0], args);
    step = 3;
  }
  const int report[2] = {step, errno};
  (void)!write(fail_fd, report, sizeof report);
  _exit(127);
}

// Waits for `pid`, killing it (SIGKILL) after `timeout_seconds` (<= 0: no limit); its status and
// rusage. False when wait4 failed (r->error says why).
inline bool WaitWithLimit(pid_t pid, std::chrono::steady_clock::time_point t0,
                          double timeout_seconds, int* status, rusage* u, ProcessResult* r) {
  for (;;) {
    const pid_t w = wait4(pid, status, timeout_seconds > 0 ? WNOHANG : 0, u);
    if (w == pid) return true;
    if (w < 0 && errno != EINTR) {
      r->error = std::string("wait4 failed: ") + std::strerror(errno);
      return false;
    }
    if (w == 0) {  // still running
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (t > timeout_seconds && !r->timed_out) {
        kill(pid, SIGKILL);
        r->timed_out = true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
}

// How the process ended, in words ("" when it exited 0).
inline void DescribeEnd(int status, double timeout_seconds, ProcessResult* r) {
  if (WIFEXITED(status)) r->exit_status = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r->signal = WTERMSIG(status);
  if (r->timed_out)
    r->error = "killed after the time limit of " +
               std::to_string(static_cast<long>(timeout_seconds)) + " s";
  else if (r->signal)
    r->error = "killed by signal " + std::to_string(r->signal) + " (" + strsignal(r->signal) + ")";
  else if (r->exit_status != 0)
    r->error = "exited with status " + std::to_string(r->exit_status);
}

}  // namespace detail

// Runs argv[0] (a path, no shell) with the other arguments in `work_dir` (unless empty), stdout
// and stderr appended to `log` (unless empty), killed after `timeout_seconds` (<= 0: no limit).
// Unlike Sh, the peak RSS is this process's own: getrusage(RUSAGE_CHILDREN) would give the
// largest child of the whole bench so far.
inline ProcessResult RunProcess(const std::vector<std::string>& argv,
                                const std::filesystem::path& work_dir,
                                const std::filesystem::path& log, double timeout_seconds) {
  ProcessResult r;
  if (argv.empty()) {
    r.error = "nothing to run";
    return r;
  }
  std::string shown;
  for (const std::string& a : argv) shown += (shown.empty() ? "" : " ") + Quote(a);
  if (!work_dir.empty()) shown = "(cd " + Quote(work_dir.string()) + " && " + shown + ")";
  if (!log.empty()) shown += " >>" + Quote(log.string()) + " 2>&1";
  std::fprintf(stderr, "+ %s\n", shown.c_str());
  std::fflush(nullptr);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  int fail_pipe[2];  // the child writes errno here when chdir, open or exec fails
  if (pipe2(fail_pipe, O_CLOEXEC) != 0) {
    r.error = std::string("pipe failed: ") + std::strerror(errno);
    return r;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid < 0) {
    r.error = std::string("fork failed: ") + std::strerror(errno);
    close(fail_pipe[0]);
    close(fail_pipe[1]);
    return r;
  }
  if (pid == 0) {
    close(fail_pipe[0]);
    detail::ExecChild(args.data(), work_dir, log, fail_pipe[1]);
  }
  close(fail_pipe[1]);
  int report[2] = {0, 0};
  const ssize_t n = read(fail_pipe[0], report, sizeof report);  // 0 bytes: exec succeeded
  close(fail_pipe[0]);
  int status = 0;
  rusage u{};
  if (!detail::WaitWithLimit(pid, t0, timeout_seconds, &status, &u, &r)) return r;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.peak_rss_kb = u.ru_maxrss;
  if (n == static_cast<ssize_t>(sizeof report)) {
    static const char* const kStep[] = {"", "cannot enter the folder ", "cannot open the log ",
                                        "cannot run "};
    const std::string what = report[0] == 1   ? work_dir.string()
                             : report[0] == 2 ? log.string()
                                              : argv[0];
    r.error = std::string(kStep[report[0] & 3]) + what + " (" + std::strerror(report[1]) + ")";
    return r;
  }
  r.started = true;
  detail::DescribeEnd(status, timeout_seconds, &r);
  return r;
}

// A shell command through RunProcess (its words as /bin/sh reads them; it execs the command, so
// the measured process is the command's): exit status (128 + signal when signalled, -1 when it
// did not start), wall time, peak RSS.
struct TimedRun {
  int status = -1;
  double seconds = 0.0;
  double peak_rss_mb = 0.0;
};
inline TimedRun RunTimed(const std::string& command, const std::filesystem::path& log,
                         double timeout_seconds = 0.0) {
  std::error_code ec;
  std::filesystem::remove(log, ec);  // a fresh log per run
  const ProcessResult p = RunProcess({"/bin/sh", "-c", "exec " + command}, "", log, timeout_seconds);
  TimedRun r;
  r.seconds = p.seconds;
  r.peak_rss_mb = static_cast<double>(p.peak_rss_kb) / 1024.0;
  r.status = !p.started ? -1 : p.signal ? 128 + p.signal : p.timed_out ? 137 : p.exit_status;
  return r;
}

// A JSON file's contents; null when it is missing or not JSON.
inline nlohmann::json ReadJson(const std::filesystem::path& p) {
  std::ifstream in(p);
  if (!in) return nlohmann::json();
  try {
    return nlohmann::json::parse(in);
  } catch (...) {
    return nlohmann::json();
  }
}

}  // namespace imr::bench
