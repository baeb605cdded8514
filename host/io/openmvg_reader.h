// OpenMVG sfm_data.json (sfm_data_version 0.2 / 0.3, cereal JSON archive): views (ptr_wrapper,
// id_view / id_intrinsic / id_pose), intrinsics (polymorphic: pinhole, pinhole_radial_k1,
// pinhole_radial_k3, pinhole_brown_t2; other models are kept but not projectable), extrinsics
// (rotation = R world -> camera, center = C) and structure (landmarks with X and observations
// keyed by view id). Converted to the convention of camera_model.h.
//
// Memory: the file is read in one SAX pass (json_stream.h); the large arrays (views,
// extrinsics, structure) are converted element by element, so the peak is the compact model
// (about 60 bytes per observation plus 50 per point), not the JSON DOM.
#pragma once

#include "host/io/json_fields.h"
#include "host/io/sfm_source.h"

#include <filesystem>

namespace imr::io {

// Throws std::runtime_error naming the file and the JSON path or id when the file is unusable:
// missing fields, dangling ids (an observation of a view the file does not list, a view whose
// intrinsic is missing), a rotation that is not one, malformed or truncated JSON.
SfmModel ReadOpenMvg(const std::filesystem::path& file);

// One OpenMVG intrinsic's "data" object (focal_length, principal_point, disto_*) of the type
// `name` (also used by SLAM JSON 0.3, which copies OpenMVG's intrinsics). With imr's extra
// fields colmap_model and colmap_params (its stream export), the COLMAP camera they name.
Intrinsics OpenMvgIntrinsicFromData(const JsonFields& f, const std::string& name,
                                    const nlohmann::json& data, const std::string& path);
// The OpenMVG type name and "data" fields (focal_length, principal_point, disto_*) nearest to
// `k`; fx is used when fx != fy (OpenMVG has one focal length), terms OpenMVG has no model for
// are dropped (FOV's omega, FULL_OPENCV's rational terms, thin prism). A COLMAP camera is also
// written whole in colmap_model and colmap_params, which other readers ignore.
void OpenMvgIntrinsicToData(const Intrinsics& k, std::string* name, nlohmann::json* data);

}  // namespace imr::io
