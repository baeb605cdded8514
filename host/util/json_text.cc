#include "host/util/json_text.h"

#include "host/util/text_codec.h"

#include <cstdint>
#include <cstdio>

namespace imr {
namespace {

// Length of the well-formed UTF-8 sequence at s[i], 0 when there is none (RFC 3629, table 3-7
// of the Unicode standard).
std::size_t SequenceAt(std::string_view s, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<uint8_t>(s[k]); };
  const uint8_t b = byte(i);
  if (b < 0x80) return 1;
  std::size_t n = 0;
  uint8_t lo = 0x80, hi = 0xbf;  // the allowed range of the second byte
  if (b >= 0xc2 && b <= 0xdf) n = 2;
  else if (b == 0xe0) n = 3, lo = 0xa0;
  else if (b >= 0xe1 && b <= 0xec) n = 3;
  else if (b == 0xed) n = 3, hi = 0x9f;  // no surrogates
  else if (b >= 0xee && b <= 0xef) n = 3;
  else if (b == 0xf0) n = 4, lo = 0x90;
  else if (b >= 0xf1 && b <= 0xf3) n = 4;
  else if (b == 0xf4) n = 4, hi = 0x8f;  // nothing past U+10FFFF
  else return 0;
  if (i + n > s.size()) return 0;
  if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
  for (std::size_t k = 2; k < n; ++k)
    if (byte(i + k) < 0x80 || byte(i + k) > 0xbf) return 0;
  return n;
}

nlohmann::json Sanitized(const nlohmann::json& j) {
  if (j.is_string()) return JsonText(j.get_ref<const std::string&>());
  if (j.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& e : j) out.push_back(Sanitized(e));
    return out;
  }
  if (j.is_object()) {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [key, value] : j.items()) out[JsonText(key)] = Sanitized(value);
    return out;
  }
  return j;
}

}  // namespace

bool IsUtf8(std::string_view s) {
  for (std::size_t i = 0; i < s.size();) {
    const std::size_t n = SequenceAt(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

std::string JsonText(std::string_view bytes) {
  std::string out;
  out.reserve(bytes.size());
  for (std::size_t i = 0; i < bytes.size();) {
    const std::size_t n = SequenceAt(bytes, i);
    if (n > 0) {
      out.append(bytes.substr(i, n));
      i += n;
      continue;
    }
    char hex[8];
    std::snprintf(hex, sizeof(hex), "\\x%02X", static_cast<unsigned>(static_cast<uint8_t>(bytes[i])));
    out += hex;
    ++i;
  }
  return out;
}

std::string OneLine(std::string_view bytes, std::size_t max_bytes) {
  const bool cut = max_bytes > 0 && bytes.size() > max_bytes;
  std::string out;
  for (const char c : JsonText(cut ? bytes.substr(0, max_bytes) : bytes)) {
    const auto u = static_cast<uint8_t>(c);
    if (c == '\n') out += "\\n";
    else if (c == '\r') out += "\\r";
    else if (c == '\t') out += "\\t";
    else if (u < 0x20 || u == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02X", static_cast<unsigned>(u));
      out += hex;
    } else {
      out += c;
    }
  }
  if (cut) out += "... (" + std::to_string(bytes.size()) + " bytes)";
  return out;
}

std::string DumpJson(const nlohmann::json& j, int indent) {
  try {
    return j.dump(indent);
  } catch (const nlohmann::json::type_error& e) {
    if (e.id != 316) throw;  // 316: a string that is not UTF-8
  }
  return Sanitized(j).dump(indent);
}

void PutBytes(nlohmann::json& obj, const std::string& key, std::string_view bytes) {
  obj[key] = JsonText(bytes);
  if (!IsUtf8(bytes)) obj[key + "_base64"] = Base64Encode(bytes);
}

std::string GetBytes(const nlohmann::json& obj, const std::string& key) {
  const auto it = obj.find(key + "_base64");
  std::string bytes;
  if (it != obj.end() && it->is_string() && Base64Decode(it->get<std::string>(), &bytes)) return bytes;
  return obj.at(key).get<std::string>();
}

}  // namespace imr
