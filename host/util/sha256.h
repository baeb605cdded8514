// SHA-256 (FIPS 180-4): manifests of finished sequences (a re-run trusts an output only
// when its bytes still hash to what was recorded) and the input checksums of reports. Computed
// by OpenSSL's EVP interface (libcrypto), which uses the CPU's SHA instructions where it has them:
// every run hashes every input image.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

namespace imr {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(Sha256&&) noexcept;
  Sha256& operator=(Sha256&&) noexcept;
  void Update(const void* data, std::size_t size);
  void Update(std::string_view s) { Update(s.data(), s.size()); }
  // The digest as 64 lowercase hex digits; the object must not be updated afterwards.
  std::string HexDigest();

 private:
  struct Context;  // OpenSSL's digest context, kept out of this header
  std::unique_ptr<Context> context_;
};

std::string Sha256Hex(std::string_view data);
// Hashes a file's contents; throws std::runtime_error naming the file when it cannot be read.
std::string Sha256File(const std::filesystem::path& file);

}  // namespace imr
