// A small schema language for flat option objects: plugin params (the descriptor's
// params_schema), input-format options and engine options all use it, so `imr validate` reports
// every problem the same way: "<json path>: expected <what>, got <value>". The language and its
// validator are the SDK's (imr/sdk/params_schema.hpp), so the host and the plugin wrapper accept
// the same values; this file adds JSON paths.
//
//   {"window": {"type": "integer", "default": 15, "minimum": 1, "unit": "cameras",
//               "description": "..."},
//    "mode":   {"type": "string", "enum": ["weights", "rays"], "default": "weights"},
//    "names":  {"type": "string_array", "default": []}}
//
// Types: integer (32-bit: hosts and plugins read them as int), number (finite), boolean, string,
// string_array. Keys not in the schema are errors.
#pragma once

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace imr::io {

struct Problem {
  std::string path;     // JSON path, e.g. "pipeline[2].params.window"
  std::string message;  // what was expected and what was found
  std::string ToString() const { return path.empty() ? message : path + ": " + message; }
};

// Checks that `schema` itself is well formed (used on plugins' declared schemas). Returns the
// problems found; `path` names where the schema came from.
std::vector<Problem> CheckSchema(const nlohmann::json& schema, const std::string& path);

// Appends to `problems` every way in which `value` (must be an object) breaks `schema`.
void ValidateAgainstSchema(const nlohmann::json& schema, const nlohmann::json& value,
                           const std::string& path, std::vector<Problem>* problems);

// `value` with every missing key set to the schema's default.
nlohmann::json WithDefaults(const nlohmann::json& schema, const nlohmann::json& value);

// Short human form of a JSON value for messages: strings quoted, long values cut.
std::string Describe(const nlohmann::json& value);

// A listing of every key of `schema`: what it accepts (type, bounds, enum), its default, unit and
// description. Markdown: one table row per key (docs/engine.md's table is this output); text: a
// block per key for a terminal, each line after the first indented by `indent`.
std::string SchemaMarkdown(const nlohmann::json& schema);
std::string SchemaText(const nlohmann::json& schema, const std::string& indent = "  ");

// "a, b or c" for listing alternatives in messages.
std::string JoinAlternatives(const std::vector<std::string>& items);

}  // namespace imr::io
