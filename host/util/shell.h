// Quoting for /bin/sh: the one rule for every command line imr writes or runs (Slurm scripts, the
// command a report records, benchmarks and tests that run imr).
#pragma once

#include <string>

namespace imr {

// `word` as one word for /bin/sh: bare when it holds only characters the shell takes literally,
// else in single quotes (a quote inside written '\'').
inline std::string ShellQuote(const std::string& word) {
  if (!word.empty() && word.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                              "0123456789_-./=:,+@%") == std::string::npos)
    return word;
  std::string q = "'";
  for (char c : word) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace imr
