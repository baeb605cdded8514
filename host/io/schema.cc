#include "host/io/schema.h"

#include <cmath>
#include <cstdint>

namespace imr::io {
namespace {

const char* const kTypes[] = {"integer", "number", "boolean", "string", "string_array"};
const char* const kSchemaKeys[] = {"type", "default", "minimum", "maximum", "enum", "description"};

bool Matches(const std::string& type, const nlohmann::json& v) {
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

std::string Expected(const nlohmann::json& spec) {
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

}  // namespace

namespace {

// dump()'s text of `value`, stopped soon after `budget` characters and 8 levels: dump() would
// recurse through the whole value, and a value nested 100000 deep overflows the stack.
void Preview(const nlohmann::json& value, std::size_t budget, int depth, std::string* out) {
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

}  // namespace

std::string Describe(const nlohmann::json& value) {
  std::string s;
  Preview(value, 60, 0, &s);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

std::string JoinAlternatives(const std::vector<std::string>& items) {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) {
    if (i > 0) out += (i + 1 == items.size()) ? " or " : ", ";
    out += items[i];
  }
  return out;
}

std::vector<Problem> CheckSchema(const nlohmann::json& schema, const std::string& path) {
  std::vector<Problem> problems;
  if (!schema.is_object()) {
    problems.push_back({path, "schema must be a JSON object, got " + Describe(schema)});
    return problems;
  }
  for (const auto& [name, spec] : schema.items()) {
    const std::string p = path + "." + name;
    if (!spec.is_object()) {
      problems.push_back({p, "expected an object describing the parameter"});
      continue;
    }
    for (const auto& [key, _] : spec.items()) {
      bool known = false;
      for (const char* k : kSchemaKeys) known |= key == k;
      if (!known) problems.push_back({p + "." + key, "unknown schema key"});
    }
    const std::string type = spec.value("type", "");
    bool known_type = false;
    for (const char* t : kTypes) known_type |= type == t;
    if (!known_type) {
      problems.push_back({p + ".type", "expected one of integer, number, boolean, string, "
                                       "string_array, got " + Describe(spec.value("type", nlohmann::json()))});
      continue;
    }
    if (spec.contains("default") && !Matches(type, spec["default"]))
      problems.push_back({p + ".default", "does not match type " + type});
  }
  return problems;
}

void ValidateAgainstSchema(const nlohmann::json& schema, const nlohmann::json& value,
                           const std::string& path, std::vector<Problem>* problems) {
  if (!value.is_object()) {
    problems->push_back({path, "expected an object, got " + Describe(value)});
    return;
  }
  for (const auto& [name, v] : value.items()) {
    const std::string p = path + "." + name;
    auto it = schema.find(name);
    if (it == schema.end()) {
      std::vector<std::string> known;
      for (const auto& [k, _] : schema.items()) known.push_back(k);
      problems->push_back({p, known.empty() ? std::string("unknown key (no parameters accepted)")
                                            : "unknown key (expected " + JoinAlternatives(known) + ")"});
      continue;
    }
    const nlohmann::json& spec = *it;
    const std::string type = spec.value("type", "");
    if (!Matches(type, v)) {
      problems->push_back({p, "expected " + Expected(spec) + ", got " + Describe(v)});
      continue;
    }
    // Hosts and plugins read integers as int: a larger value would wrap silently.
    if (type == "integer" && (v.is_number_unsigned() ? v.get<uint64_t>() > INT32_MAX
                                                     : (v.get<int64_t>() > INT32_MAX ||
                                                        v.get<int64_t>() < INT32_MIN))) {
      problems->push_back({p, "expected " + Expected(spec) + " (a 32-bit integer, at most " +
                                  std::to_string(INT32_MAX) + "), got " + Describe(v)});
      continue;
    }
    if (v.is_number()) {
      const double x = v.get<double>();
      if ((spec.contains("minimum") && x < spec["minimum"].get<double>()) ||
          (spec.contains("maximum") && x > spec["maximum"].get<double>()))
        problems->push_back({p, "expected " + Expected(spec) + ", got " + Describe(v)});
    }
    if (spec.contains("enum")) {
      bool found = false;
      for (const auto& e : spec["enum"]) found |= e == v;
      if (!found) problems->push_back({p, "expected " + Expected(spec) + ", got " + Describe(v)});
    }
  }
}

nlohmann::json WithDefaults(const nlohmann::json& schema, const nlohmann::json& value) {
  nlohmann::json out = value.is_object() ? value : nlohmann::json::object();
  for (const auto& [name, spec] : schema.items())
    if (!out.contains(name) && spec.is_object() && spec.contains("default"))
      out[name] = spec["default"];
  return out;
}

}  // namespace imr::io
