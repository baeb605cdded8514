// The job's "engine" object <-> imr::engine::EngineOptions, in one place. The schema carries a
// description and the default of every option, so `imr validate` checks them like plugin params.
#pragma once

#include "host/engine/engine.h"
#include "host/io/schema.h"

#include <nlohmann/json.hpp>

namespace imr::io {

const nlohmann::json& EngineOptionsSchema();

// Validates `json` (path "engine") and fills *options; also runs EngineOptions::Check. Returns
// false with problems appended when anything is wrong.
bool EngineOptionsFromJson(const nlohmann::json& json, engine::EngineOptions* options,
                           std::vector<Problem>* problems);

nlohmann::json EngineOptionsToJson(const engine::EngineOptions& options);

}  // namespace imr::io
