// The params schema language of plugin.h (a descriptor's params_schema), checked in one place:
// the host validates a job's params with it (`imr validate`, before anything runs) and the C++
// plugin wrapper (plugin.hpp) checks them again when an instance is created, so both accept and
// refuse the same values with the same words.
//
//   {"window": {"type": "integer", "default": 15, "minimum": 1, "unit": "cameras",
//               "description": "..."},
//    "mode":   {"type": "string", "enum": ["weights", "rays"], "default": "weights"},
//    "names":  {"type": "string_array", "default": []}}
//
// Types: integer (32-bit: hosts and plugins read them as int, so a larger value is refused, not
// truncated), number (finite), boolean, string, string_array. Keys not in the schema are errors.
// Header-only; needs nlohmann/json.
#pragma once

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace imr::sdk {

// One way a params object breaks its schema: `name` is the parameter ("" for the object itself),
// `message` what was expected and what was found ("expected integer >= 1, got 0").
struct ParamProblem {
  std::string name;
  std::string message;
};

// Whether `v` has the JSON type the schema type names (bounds and enum aside).
inline bool MatchesType(const std::string& type, const nlohmann::json& v) {
  if (type == "integer") return v.is_number_integer();
  if (type == "number") return v.is_number() && std::isfinite(v.get<double>());
  if (type == "boolean") return v.is_boolean();
  if (type == "string") return v.is_string();
  if (type == "string_array") {
    if (!v.is_array()) return false;
    for (const auto& e : v)
      if (!e.is_string()) return false;
    return true;
  }
  return false;
}

namespace schema_detail {

// dump()'s text of `value`, stopped soon after `budget` characters and 8 levels: dump() would
// recurse through the whole value, and a value nested 100000 deep overflows the stack.
inline void Preview(const nlohmann::json& value, std::size_t budget, int depth, std::string* out) {
  if (out->size() > budget) return;
  if (!value.is_structured()) {
    *out += value.dump();
    return;
  }
  const bool array = value.is_array();
  *out += array ? '[' : '{';
  if (depth >= 8 && !value.empty()) {
    *out += "...";
  } else {
    bool first = true;
    for (auto it = value.begin(); it != value.end() && out->size() <= budget; ++it) {
      if (!first) *out += ',';
      first = false;
      if (!array) *out += nlohmann::json(it.key()).dump() + ':';
      Preview(*it, budget, depth + 1, out);
    }
  }
  *out += array ? ']' : '}';
}

}  // namespace schema_detail

// The schema language's types and the keys a parameter's description may have.
inline const std::vector<std::string>& SchemaTypes() {
  static const std::vector<std::string> types = {"integer", "number", "boolean", "string",
                                                 "string_array"};
  return types;
}
inline const std::vector<std::string>& SchemaKeys() {
  static const std::vector<std::string> keys = {"type",    "default", "minimum",    "maximum",
                                                "enum",    "unit",    "description"};
  return keys;
}

// Short human form of a JSON value for messages: strings quoted, long values cut.
inline std::string DescribeJson(const nlohmann::json& value) {
  std::string s;
  schema_detail::Preview(value, 60, 0, &s);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

// "a, b or c" for listing alternatives in messages.
inline std::string JoinAlternatives(const std::vector<std::string>& items) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) {
    if (i > 0) out += (i + 1 == items.size()) ? " or " : ", ";
    out += items[i];
  }
  return out;
}

// What a parameter's schema accepts, for messages and listings: "integer >= 1",
// "number in [0.0, 0.25]", "string (one of \"skip\" or \"near_camera\")".
inline std::string ExpectedValue(const nlohmann::json& spec) {
  const std::string type = spec.value("type", "");
  std::string what = type == "string_array" ? "array of strings" : type;
  if (spec.contains("minimum") && spec.contains("maximum"))
    what += " in [" + spec["minimum"].dump() + ", " + spec["maximum"].dump() + "]";
  else if (spec.contains("minimum"))
    what += " >= " + spec["minimum"].dump();
  else if (spec.contains("maximum"))
    what += " <= " + spec["maximum"].dump();
  if (spec.contains("enum")) {
    std::vector<std::string> names;
    for (const auto& e : spec["enum"]) names.push_back(e.dump());
    what += " (one of " + JoinAlternatives(names) + ")";
  }
  return what;
}

// Every way in which `params` breaks `schema` (both JSON objects; `schema` is trusted to be well
// formed), in the order of the params' keys. Empty when `params` is acceptable.
inline std::vector<ParamProblem> ValidateParams(const nlohmann::json& schema,
                                                const nlohmann::json& params) {
  std::vector<ParamProblem> problems;
  if (!params.is_object()) {
    problems.push_back({"", "expected an object, got " + DescribeJson(params)});
    return problems;
  }
  for (const auto& [name, v] : params.items()) {
    auto it = schema.find(name);
    if (it == schema.end()) {
      std::vector<std::string> known;
      for (const auto& [k, _] : schema.items()) known.push_back(k);
      problems.push_back({name, known.empty() ? std::string("unknown key (no parameters accepted)")
                                              : "unknown key (expected " + JoinAlternatives(known) + ")"});
      continue;
    }
    const nlohmann::json& spec = *it;
    const std::string type = spec.value("type", "");
    const std::string got = ", got " + DescribeJson(v);
    if (!MatchesType(type, v)) {
      // A whole number written as a float beyond int (1e308, 1.2e29) gets the same hint as
      // 9223372036854775808: it is the size, not the form, that is wrong.
      const double x = v.is_number() ? v.get<double>() : 0.0;
      const bool too_large = type == "integer" && v.is_number_float() && std::isfinite(x) &&
                             std::trunc(x) == x && std::abs(x) > INT32_MAX;
      const std::string hint =
          too_large ? " (a 32-bit integer, at most " + std::to_string(INT32_MAX) + ")" : "";
      // A whole number written with a point or an exponent (1e9) is shown as an integer, not as
      // the float it was read as (1000000000.0).
      const bool whole = type == "integer" && v.is_number_float() && std::isfinite(x) &&
                         std::trunc(x) == x && std::abs(x) < 1e15;
      const std::string shown =
          whole ? ", got " + std::to_string(static_cast<long long>(x)) +
                      " written as a decimal number (an integer has no point or exponent)"
                : got;
      problems.push_back({name, "expected " + ExpectedValue(spec) + hint + shown});
      continue;
    }
    // Hosts and plugins read integers as int: a larger value would wrap silently.
    if (type == "integer" && (v.is_number_unsigned() ? v.get<uint64_t>() > INT32_MAX
                                                     : (v.get<int64_t>() > INT32_MAX ||
                                                        v.get<int64_t>() < INT32_MIN))) {
      problems.push_back({name, "expected " + ExpectedValue(spec) + " (a 32-bit integer, at most " +
                                    std::to_string(INT32_MAX) + ")" + got});
      continue;
    }
    if (v.is_number()) {
      const double x = v.get<double>();
      if ((spec.contains("minimum") && x < spec["minimum"].get<double>()) ||
          (spec.contains("maximum") && x > spec["maximum"].get<double>()))
        problems.push_back({name, "expected " + ExpectedValue(spec) + got});
    }
    if (spec.contains("enum")) {
      bool found = false;
      for (const auto& e : spec["enum"]) found |= e == v;
      if (!found) problems.push_back({name, "expected " + ExpectedValue(spec) + got});
    }
  }
  return problems;
}

// `params` with every missing key set to the schema's default.
inline nlohmann::json WithSchemaDefaults(const nlohmann::json& schema, const nlohmann::json& params) {
  nlohmann::json out = params.is_object() ? params : nlohmann::json::object();
  for (const auto& [name, spec] : schema.items())
    if (!out.contains(name) && spec.is_object() && spec.contains("default"))
      out[name] = spec["default"];
  return out;
}

}  // namespace imr::sdk
