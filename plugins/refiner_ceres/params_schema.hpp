// Checks a plugin's params against its own kParamsSchema (the schema language of plugin.h) and
// reads values with the schema's defaults, so each default is written once, in the schema.
// The host validates jobs too; this is defence in depth for hosts (and tests) that do not.
#pragma once

#include <imr/sdk/plugin.hpp>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

namespace imr::ceres_refiner {

class SchemaParams {
 public:
  // Throws imr::sdk::InvalidArgument naming the first unknown, mistyped or out-of-range param.
  SchemaParams(const imr::sdk::Params& params, const char* schema_text)
      : params_(params.Json()), schema_(nlohmann::json::parse(schema_text)) {
    for (const auto& [name, value] : params_.items()) {
      auto it = schema_.find(name);
      if (it == schema_.end()) {
        std::string known;
        for (const auto& [k, v] : schema_.items()) known += (known.empty() ? "" : ", ") + k;
        throw imr::sdk::InvalidArgument("params." + name + ": unknown parameter (known: " + known +
                                        ")");
      }
      Check(name, value, *it);
    }
  }

  template <typename T>
  T Get(const std::string& name) const {
    auto it = params_.find(name);
    if (it != params_.end() && !it->is_null()) return it->get<T>();
    return schema_.at(name).at("default").get<T>();
  }

 private:
  static void Check(const std::string& name, const nlohmann::json& v, const nlohmann::json& s) {
    const std::string type = s.value("type", "");
    const auto fail = [&](const std::string& why) {
      throw imr::sdk::InvalidArgument("params." + name + ": " + why + " (got " + v.dump() + ")");
    };
    if (type == "integer") {
      const bool integral = v.is_number_integer() ||
                            (v.is_number_float() && std::floor(v.get<double>()) == v.get<double>());
      if (!integral) fail("expected an integer");
    } else if (type == "number") {
      if (!v.is_number() || !std::isfinite(v.get<double>())) fail("expected a finite number");
    } else if (type == "boolean") {
      if (!v.is_boolean()) fail("expected true or false");
    } else if (type == "string") {
      if (!v.is_string()) fail("expected a string");
    }
    if (v.is_number()) {
      const double x = v.get<double>();
      if (s.contains("minimum") && x < s["minimum"].get<double>())
        fail("below the minimum " + s["minimum"].dump());
      if (s.contains("maximum") && x > s["maximum"].get<double>())
        fail("above the maximum " + s["maximum"].dump());
    }
    if (s.contains("enum")) {
      bool found = false;
      for (const auto& e : s["enum"]) found = found || e == v;
      if (!found) fail("expected one of " + s["enum"].dump());
    }
  }

  nlohmann::json params_;
  nlohmann::json schema_;
};

}  // namespace imr::ceres_refiner
