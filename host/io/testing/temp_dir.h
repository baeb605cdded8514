// The one scratch folder of the tests (unit tests here and in host/eval, the end-to-end tests
// in tests/ through ScratchDir): a fresh folder under the system temp folder, made by mkdtemp
// (unique, mode 0700), removed with everything in it by the destructor.
#pragma once

#include <stdlib.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <system_error>

namespace imr::io::testing {

class TempDir {
 public:
  // Throws std::runtime_error naming the folder and the reason when it cannot be made.
  explicit TempDir(const std::string& tag = "imr-io") {
    std::string tmpl = (std::filesystem::temp_directory_path() / (tag + "-XXXXXX")).string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw std::runtime_error("cannot make a scratch folder " + tmpl + ": " + std::strerror(errno));
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::filesystem::path operator/(const std::string& p) const { return path_ / p; }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// Writes `text` to `p` (binary), creating its folder.
inline void Write(const std::filesystem::path& p, const std::string& text) {
  std::filesystem::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

}  // namespace imr::io::testing
