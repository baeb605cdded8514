// The "synthetic" input format: a synthetic observation stream over a known scene (no images).
#pragma once

#include "host/io/keyframe_source.h"

namespace imr::io {

// `scene` is a scene name (street, room, plane); `options` follow the format's schema, defaults
// filled in.
std::unique_ptr<KeyframeSource> OpenSyntheticSource(const std::string& scene,
                                                    const nlohmann::json& options);

}  // namespace imr::io
