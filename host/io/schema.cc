#include "host/io/schema.h"

#include <imr/sdk/params_schema.hpp>

#include <algorithm>

namespace imr::io {

std::string Describe(const nlohmann::json& value) { return sdk::DescribeJson(value); }

std::string JoinAlternatives(const std::vector<std::string>& items) {
  return sdk::JoinAlternatives(items);
}

std::vector<Problem> CheckSchema(const nlohmann::json& schema, const std::string& path) {
  std::vector<Problem> problems;
  if (!schema.is_object()) {
    problems.push_back({path, "schema must be a JSON object, got " + Describe(schema)});
    return problems;
  }
  auto listed = [](const std::vector<std::string>& list, const std::string& s) {
    return std::find(list.begin(), list.end(), s) != list.end();
  };
  for (const auto& [name, spec] : schema.items()) {
    const std::string p = path + "." + name;
    if (!spec.is_object()) {
      problems.push_back({p, "expected an object describing the parameter"});
      continue;
    }
    for (const auto& [key, _] : spec.items())
      if (!listed(sdk::SchemaKeys(), key)) problems.push_back({p + "." + key, "unknown schema key"});
    if (spec.contains("unit") && !spec["unit"].is_string())
      problems.push_back({p + ".unit", "expected a string, got " + Describe(spec["unit"])});
    const std::string type = spec.value("type", "");
    if (!listed(sdk::SchemaTypes(), type)) {
      problems.push_back({p + ".type", "expected one of integer, number, boolean, string, "
                                       "string_array, got " + Describe(spec.value("type", nlohmann::json()))});
      continue;
    }
    if (spec.contains("default") && !sdk::MatchesType(type, spec["default"]))
      problems.push_back({p + ".default", "does not match type " + type});
  }
  return problems;
}

void ValidateAgainstSchema(const nlohmann::json& schema, const nlohmann::json& value,
                           const std::string& path, std::vector<Problem>* problems) {
  for (const sdk::ParamProblem& p : sdk::ValidateParams(schema, value))
    problems->push_back({p.name.empty() ? path : path + "." + p.name, p.message});
}

namespace {

// A listing's words for one key: what it accepts, its default and its unit.
struct Listed {
  std::string accepts, default_value, unit, description;
};
Listed ListedOf(const nlohmann::json& spec) {
  return {sdk::ExpectedValue(spec), spec.contains("default") ? spec["default"].dump() : "",
          spec.value("unit", ""), spec.value("description", "")};
}

}  // namespace

std::string SchemaMarkdown(const nlohmann::json& schema) {
  auto cell = [](std::string s) {
    for (std::size_t i = 0; (i = s.find('|', i)) != std::string::npos; i += 2) s.insert(i, "\\");
    return s;
  };
  std::string out = "| option | accepts | default | unit | description |\n|---|---|---|---|---|\n";
  for (const auto& [name, spec] : schema.items()) {
    const Listed l = ListedOf(spec);
    out += "| `" + name + "` | " + cell(l.accepts) + " | " +
           (l.default_value.empty() ? "(none)" : "`" + cell(l.default_value) + "`") + " | " +
           cell(l.unit) + " | " + cell(l.description) + " |\n";
  }
  return out;
}

std::string SchemaText(const nlohmann::json& schema, const std::string& indent) {
  std::string out;
  for (const auto& [name, spec] : schema.items()) {
    const Listed l = ListedOf(spec);
    out += indent + name + "  " + l.accepts;
    if (!l.default_value.empty()) out += ", default " + l.default_value;
    if (!l.unit.empty()) out += ", unit: " + l.unit;
    out += "\n";
    if (!l.description.empty()) out += indent + "    " + l.description + "\n";
  }
  return out;
}

nlohmann::json WithDefaults(const nlohmann::json& schema, const nlohmann::json& value) {
  return sdk::WithSchemaDefaults(schema, value);
}

}  // namespace imr::io
