// Bytes as JSON text. Names on Linux are bytes (a Latin-1 folder name is no UTF-8) and JSON
// needs UTF-8, which nlohmann enforces when dumping (type_error 316). JsonText keeps valid UTF-8
// and writes every other byte as \xNN, for people to read; where the exact bytes must come back
// (a path read again by `imr report`), PutBytes stores them in base64 beside that text.
#pragma once

#include <nlohmann/json.hpp>

#include <string>
#include <string_view>

namespace imr {

// True when `s` is well-formed UTF-8 (no overlong forms, surrogates or code points past
// U+10FFFF), as JSON requires.
bool IsUtf8(std::string_view s);

// `bytes` with each byte that is not part of well-formed UTF-8 written as \xNN ("caf\xE9").
std::string JsonText(std::string_view bytes);

// `bytes` as one line of text, for messages, logs and the comments of scripts: JsonText, with
// each control character (newline, tab, NUL, DEL, ...) written as \n, \r, \t or \xNN, so that
// nothing a name holds can start a line of its own. Past `max_bytes` of input (0: no limit) the
// rest is cut and "... (N bytes)" says how long it was.
std::string OneLine(std::string_view bytes, std::size_t max_bytes = 0);

// j.dump(indent), with every string and key that is not UTF-8 shown as JsonText: never throws
// for the bytes of a string.
std::string DumpJson(const nlohmann::json& j, int indent = -1);

// obj[key] = JsonText(bytes); when that is not the bytes themselves, obj[key + "_base64"] too.
void PutBytes(nlohmann::json& obj, const std::string& key, std::string_view bytes);
// The bytes PutBytes stored. Throws nlohmann's errors when the key is missing or not a string.
std::string GetBytes(const nlohmann::json& obj, const std::string& key);

}  // namespace imr
