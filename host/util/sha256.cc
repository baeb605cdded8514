#include "host/util/sha256.h"

#include "host/util/input_file.h"

#include <openssl/err.h>
#include <openssl/evp.h>

#include <cstdio>
#include <stdexcept>
#include <vector>

namespace imr {
namespace {

// Throws with OpenSSL's own reason (a failure here means libcrypto is broken or out of memory).
[[noreturn]] void Fail(const char* what) {
  char reason[256] = "no reason given";
  if (const unsigned long e = ERR_get_error(); e != 0) ERR_error_string_n(e, reason, sizeof(reason));
  throw std::runtime_error(std::string("SHA-256 (OpenSSL): ") + what + ": " + reason);
}

// The SHA-256 implementation, fetched once (an implicit fetch per digest costs a lookup).
const EVP_MD* Algorithm() {
  static const EVP_MD* const md = [] {
    EVP_MD* m = EVP_MD_fetch(nullptr, "SHA256", nullptr);
    if (m == nullptr) Fail("EVP_MD_fetch");
    return m;
  }();
  return md;
}

}  // namespace

struct Sha256::Context {
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx{EVP_MD_CTX_new(), &EVP_MD_CTX_free};
};

Sha256::Sha256() : context_(std::make_unique<Context>()) {
  if (context_->ctx == nullptr) Fail("EVP_MD_CTX_new");
  if (EVP_DigestInit_ex(context_->ctx.get(), Algorithm(), nullptr) != 1) Fail("EVP_DigestInit_ex");
}
Sha256::~Sha256() = default;
Sha256::Sha256(Sha256&&) noexcept = default;
Sha256& Sha256::operator=(Sha256&&) noexcept = default;

void Sha256::Update(const void* data, std::size_t size) {
  if (size > 0 && EVP_DigestUpdate(context_->ctx.get(), data, size) != 1) Fail("EVP_DigestUpdate");
}

std::string Sha256::HexDigest() {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (EVP_DigestFinal_ex(context_->ctx.get(), digest, &length) != 1) Fail("EVP_DigestFinal_ex");
  static constexpr char kHex[] = "0123456789abcdef";
  std::string hex(2 * length, '0');
  for (unsigned int i = 0; i < length; ++i) {
    hex[2 * i] = kHex[digest[i] >> 4];
    hex[2 * i + 1] = kHex[digest[i] & 15];
  }
  return hex;
}

std::string Sha256Hex(std::string_view data) {
  Sha256 s;
  s.Update(data);
  return s.HexDigest();
}

std::string Sha256File(const std::filesystem::path& file) {
  // The open rule (input_file.h): a FIFO or a device is refused by name, never read without end.
  // Hashing alone does not make a file an input (the readers note what they read).
  InputFile f = InputFile::Open(file, "a file to hash", InputRole::kOwnOutput);
  Sha256 s;
  std::vector<char> buf(1 << 16);
  for (std::size_t n; (n = f.Read(buf.data(), buf.size())) > 0;) s.Update(buf.data(), n);
  return s.HexDigest();
}

}  // namespace imr
