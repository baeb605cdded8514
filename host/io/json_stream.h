// Reading big JSON files (SfM/SLAM exports of hundreds of MB) without holding their whole DOM:
// a SAX pass over the file that builds one top-level member at a time, and for the members named
// in `streamed` (big arrays such as "views" or "structure") one array element at a time. Each is
// handed to a callback and dropped, so the peak is the largest single element plus what the
// caller keeps, never the file's DOM (which costs several times the file size).
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <set>
#include <string>

namespace imr::io {

// Deepest nesting of arrays and objects accepted in a JSON input (job files, SfM/SLAM exports,
// which need under 10): copying or printing a value recurses once per level, and 100000 levels
// overflow the stack.
inline constexpr std::size_t kMaxJsonDepth = 100;

// `member` is called for every top-level member not in `streamed` (key, whole value), and
// `element` for every element of a streamed member that is an array (key, index, element). A
// streamed member that is not an array goes to `member`. Throws std::runtime_error naming the
// file, with line and column, when it cannot be read or is not JSON (e.g. truncated), or when
// the top level is not an object, or when it nests deeper than kMaxJsonDepth (naming the member);
// exceptions from the callbacks pass through. Returns the
// top-level keys seen (so a caller can tell an empty streamed array from a missing one).
std::set<std::string> StreamJsonFile(const std::filesystem::path& file, const std::set<std::string>& streamed,
                    const std::function<void(const std::string& key, nlohmann::json&& value)>& member,
                    const std::function<void(const std::string& key, std::size_t index,
                                             nlohmann::json&& element)>& element);

// The same, with each streamed element's place in the file: the bytes [begin, end) hold its text
// (begin -1 for an element that is not an object or an array), so that a second pass can read
// one element again without parsing the file up to it (the SLAM JSON reader's views).
std::set<std::string> StreamJsonFile(
    const std::filesystem::path& file, const std::set<std::string>& streamed,
    const std::function<void(const std::string& key, nlohmann::json&& value)>& member,
    const std::function<void(const std::string& key, std::size_t index, nlohmann::json&& element,
                             int64_t begin, int64_t end)>& element);

}  // namespace imr::io
