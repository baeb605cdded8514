// Shared helpers of the imr-bench subcommands that run imr's executables as users do (pipeline,
// paper, peers): where the executables are, shell quoting, running a command, reading a report.
#pragma once

#include <sys/wait.h>

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
