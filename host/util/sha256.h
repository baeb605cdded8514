// SHA-256 (FIPS 180-4): manifests of finished sequences (a re-run trusts an output only
// when its bytes still hash to what was recorded) and the input checksums of reports.
// Small and dependency-free on purpose.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace imr {

class Sha256 {
 public:
  Sha256();
  void Update(const void* data, std::size_t size);
  void Update(std::string_view s) { Update(s.data(), s.size()); }
  // The digest as 64 lowercase hex digits; the object must not be updated afterwards.
  std::string HexDigest();

 private:
  void Block(const uint8_t* p);
  std::array<uint32_t, 8> h_;
  std::array<uint8_t, 64> buffer_{};
  std::size_t buffered_ = 0;
  uint64_t bytes_ = 0;
};

std::string Sha256Hex(std::string_view data);
// Hashes a file's contents; throws std::runtime_error naming the file when it cannot be read.
std::string Sha256File(const std::filesystem::path& file);

}  // namespace imr
