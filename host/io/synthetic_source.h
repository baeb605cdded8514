// The "synthetic" input format: a synthetic observation stream over a known scene (no images).
#pragma once

#include "host/io/keyframe_source.h"

#include <memory>
#include <string>
#include <vector>

namespace imr::io {

// `scene` is a scene name (street, room, plane); `options` follow the format's schema, defaults
// filled in.
std::unique_ptr<KeyframeSource> OpenSyntheticSource(const std::string& scene,
                                                    const nlohmann::json& options);

// What the options break together (synthetic::StreamOptions::Check), for `imr validate`: empty,
// or one message.
std::vector<std::string> CheckSyntheticOptions(const nlohmann::json& options);

}  // namespace imr::io
