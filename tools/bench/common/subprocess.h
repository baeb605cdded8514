// Shared helpers of the imr-bench subcommands that run imr's executables as users do (pipeline,
// paper, peers): where the executables are, shell quoting, running a command, reading a report.
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

namespace imr::bench {

// The folder of the running executable (imr-bench sits beside imr and imr-synth).
inline std::filesystem::path ExeDir() {
  return std::filesystem::canonical("/proc/self/exe").parent_path();
}

// `s` as one word for /bin/sh.
inline std::string Quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Runs `command` with /bin/sh after echoing it to stderr; its exit status (128 when signalled).
inline int Sh(const std::string& command) {
  std::fprintf(stderr, "+ %s\n", command.c_str());
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

// A command's exit status (128 + signal when signalled, -1 when it could not start), wall time
// and the peak resident memory of its process tree's largest member (wait4's ru_maxrss).
struct TimedRun {
  int status = -1;
  double seconds = 0.0;
  double peak_rss_mb = 0.0;
};

// Runs `command` with /bin/sh, stdout and stderr to `log` (truncated), after echoing it to
// stderr; kills it (SIGKILL to its process group) after `timeout_s` seconds when > 0.
inline TimedRun RunTimed(const std::string& command, const std::filesystem::path& log,
                         double timeout_s = 0.0) {
  std::fprintf(stderr, "+ %s\n", command.c_str());
  TimedRun r;
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid < 0) return r;
  if (pid == 0) {
    setpgid(0, 0);
    const std::string full = "exec >" + Quote(log.string()) + " 2>&1; " + command;
    execl("/bin/sh", "sh", "-c", full.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  rusage usage{};
  for (;;) {
    const pid_t done = wait4(pid, &status, timeout_s > 0.0 ? WNOHANG : 0, &usage);
    if (done == pid) break;
    if (done < 0) return r;
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (elapsed > timeout_s) kill(-pid, SIGKILL);
    usleep(50000);
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  // wait4 reports the child with its reaped descendants (imr run's sequence processes).
  r.peak_rss_mb = static_cast<double>(usage.ru_maxrss) / 1024.0;
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
