// Input formats a job can name in input.format. Each says what its `sequences` entries are
// (paths that must exist, or names) and which options it takes (a schema, like plugin params).
// Formats: synthetic, openmvg, colmap, slam_json (engine only: `open`); kitti_odometry,
// kitti_raw, middlebury (images: `open_images`, run through the front-end plugins).
#pragma once

#include "host/io/image_sequence.h"
#include "host/io/keyframe_source.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <memory>

#include <string>
#include <vector>

namespace imr::io {

struct InputFormat {
  std::string name;
  std::string description;
  bool sequences_are_paths = true;         // false: entries are names (e.g. synthetic scenes)
  std::vector<std::string> sequence_names;  // allowed names when !sequences_are_paths
  bool needs_front_end = true;             // true: needs features + refiner stages (images)
  nlohmann::json options_schema;
  // Optional: what only a combination of options breaks (the schema bounds each alone), checked
  // when the job is validated, on options that passed the schema, defaults filled in. Returns
  // the problems, each "what and what was expected" (the path is input.options); empty: none.
  std::function<std::vector<std::string>(const nlohmann::json& options)> check;
  // Opens one sequence: `source` is the resolved path (or the name), `options` have defaults.
  // Throws std::runtime_error naming the file and field when the input is unusable.
  std::function<std::unique_ptr<KeyframeSource>(const std::string& source,
                                                const nlohmann::json& options)>
      open;
  // Image formats (needs_front_end): reads the layout into frames with cameras; the pipeline
  // runs the features and refiner plugins over it. Throws like `open`.
  std::function<ImageSequence(const std::string& source, const nlohmann::json& options)>
      open_images;
};

const std::vector<InputFormat>& InputFormats();
const InputFormat* FindInputFormat(const std::string& name);

}  // namespace imr::io
