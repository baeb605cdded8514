#include "test_util.h"

#include "host/util/shell.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

namespace imr::testing {
namespace fs = std::filesystem;

CommandResult RunShell(const std::string& command) {
  ScratchDir tmp("cmd");
  const fs::path out = tmp / "stdout", err = tmp / "stderr";
  const std::string full = "( " + command + " ) >" + Quote(out.string()) + " 2>" + Quote(err.string()) + " </dev/null";
  const int raw = std::system(full.c_str());
  CommandResult r;
  if (raw != -1 && WIFEXITED(raw)) r.status = WEXITSTATUS(raw);
  else if (raw != -1 && WIFSIGNALED(raw)) r.status = 128 + WTERMSIG(raw);
  r.out = ReadText(out);
  r.err = ReadText(err);
  return r;
}

void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream f(path, std::ios::binary);
  f << text;
  if (!f) throw std::runtime_error("cannot write " + path.string());
}

std::string ReadText(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string Quote(const std::string& s) { return ShellQuote(s); }

void ReplaceLine(const fs::path& path, std::size_t index, const std::string& text) {
  std::istringstream in(ReadText(path));
  std::string out;
  std::size_t i = 0;
  for (std::string line; std::getline(in, line); ++i) out += (i == index ? text : line) + "\n";
  if (index >= i) throw std::runtime_error(path.string() + " has no line " + std::to_string(index + 1));
  WriteText(path, out);
}

}  // namespace imr::testing
