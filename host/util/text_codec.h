// Text encodings that glTF files use (data URIs, percent-encoded file names), shared by the mesh
// readers of `imr evaluate` and the viewer page's GLB packing.
#pragma once

#include <string>
#include <string_view>

namespace imr {

// Standard base64 with '=' padding.
std::string Base64Encode(std::string_view bytes);
// Base64, standard or URL-safe alphabet, whitespace ignored, stops at '='; false (and *out
// partial) on any other character.
bool Base64Decode(std::string_view text, std::string* out);
// "%20" -> ' '; a '%' not followed by two hex digits is kept as it is.
std::string PercentDecode(std::string_view s);

}  // namespace imr
