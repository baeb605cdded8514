// The job's "engine" object <-> imr::engine::EngineOptions, declared once: one table of options
// (name, member, type, bounds, unit, default, description) gives the schema that `imr validate`
// checks a job's "engine" against, the reading of a job (EngineOptionsFromJson), the writing of
// a report (EngineOptionsToJson) and the listing of `imr options` (docs/engine.md's table is its output).
#pragma once

#include "host/engine/engine.h"
#include "host/io/schema.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace imr::io {

// One engine option as a job names it.
struct EngineOption {
  std::string name;       // the job key, e.g. "steiner_spacing"
  nlohmann::json schema;  // its entry in the schema language: type, default, bounds, enum,
                          // unit, description
  // Reads the option into / out of EngineOptions; empty for an option that is no field of the
  // engine ("scale": the pipeline reads it, host/pipeline/scale.h).
  std::function<void(const nlohmann::json&, engine::EngineOptions*)> read;
  std::function<nlohmann::json(const engine::EngineOptions&)> write;
};

// Every engine option a job may set, in the order of the listings.
const std::vector<EngineOption>& EngineOptionTable();

const nlohmann::json& EngineOptionsSchema();

// Validates `json` (path "engine") and fills *options; also runs EngineOptions::Check. Returns
// false with problems appended when anything is wrong.
bool EngineOptionsFromJson(const nlohmann::json& json, engine::EngineOptions* options,
                           std::vector<Problem>* problems);

nlohmann::json EngineOptionsToJson(const engine::EngineOptions& options);

}  // namespace imr::io
