// Helpers for integration tests: run a command and capture its output and exit status, and
// make scratch folders.
#pragma once

#include "host/io/testing/temp_dir.h"

#include <filesystem>
#include <string>

namespace imr::testing {

struct CommandResult {
  int status = -1;  // exit status, or 128 + signal
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs `command` with /bin/sh; stdout and stderr are captured separately.
CommandResult RunShell(const std::string& command);

// A fresh, empty folder under the system temp folder, removed by the destructor: the tests'
// one scratch folder (host/io/testing/temp_dir.h), named imr-test-<tag>-XXXXXX.
class ScratchDir : public io::testing::TempDir {
 public:
  explicit ScratchDir(const std::string& tag) : TempDir("imr-test-" + tag) {}
};

void WriteText(const std::filesystem::path& path, const std::string& text);
std::string ReadText(const std::filesystem::path& path);
std::string Quote(const std::string& s);  // for the shell
// Replaces line `index` (0-based) of a text file; the file keeps a final newline.
void ReplaceLine(const std::filesystem::path& path, std::size_t index, const std::string& text);

}  // namespace imr::testing
