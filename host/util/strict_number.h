// Numbers from command-line text, strictly: the whole text must be the number ("12", "0.5",
// "1e-3"), so a garbled value is an error the caller reports, never a silent 0 (atoi, strtod).
#pragma once

#include <charconv>
#include <cmath>
#include <string_view>
#include <system_error>

namespace imr {

// An integer in T's range (no sign '+', no spaces); false otherwise.
template <typename T>
bool ParseWholeInteger(std::string_view text, T* out) {
  T v{};
  const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || r.ec != std::errc() || r.ptr != text.data() + text.size()) return false;
  *out = v;
  return true;
}

// A finite double; false otherwise.
inline bool ParseWholeDouble(std::string_view text, double* out) {
  double v = 0.0;
  const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
  if (text.empty() || r.ec != std::errc() || r.ptr != text.data() + text.size() || !std::isfinite(v))
    return false;
  *out = v;
  return true;
}

}  // namespace imr
