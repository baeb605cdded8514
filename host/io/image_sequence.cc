// Options of the image-sequence formats and the text helpers the layout readers share; the
// readers are in kitti_reader.cc and middlebury_reader.cc.
#include "host/io/image_sequence.h"

#include "host/util/input_file.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>

namespace imr::io {
using nlohmann::json;

std::string ImageSequenceOptions::Check() const {
  if (camera < -1 || camera > 3) return "camera: " + std::to_string(camera) + " is not -1 or 0..3";
  if (poses_camera < -1 || poses_camera > 3)
    return "poses_camera: " + std::to_string(poses_camera) + " is not -1 or 0..3";
  if (first_frame < 0) return "first_frame: " + std::to_string(first_frame) + " is negative";
  if (frame_count == 0 || frame_count < -1)
    return "frame_count: " + std::to_string(frame_count) + " selects no frames (-1 = all)";
  if (frame_step < 1) return "frame_step: " + std::to_string(frame_step) + " is below 1";
  if (keyframe_every < 1)
    return "keyframe_every: " + std::to_string(keyframe_every) + " is below 1";
  if (!(max_image_megapixels > 0) || max_image_megapixels > 1e6)
    return "max_image_megapixels: " + std::to_string(max_image_megapixels) + " is not in (0, 1e6]";
  return "";
}

ImageLimits ImageLimitsFor(const ImageSequenceOptions& o, const ImageSize& first) {
  ImageLimits l;
  l.max_pixels = static_cast<int64_t>(o.max_image_megapixels * 1e6);
  std::ostringstream name;
  name << "input.options.max_image_megapixels (" << o.max_image_megapixels << ")";
  l.max_pixels_name = name.str();
  l.expected = first;
  l.expected_name = "the sequence's first";
  return l;
}

json ImageSequenceOptionsSchema() {
  const ImageSequenceOptions d;
  return {{"camera",
           {{"type", "integer"},
            {"default", d.camera},
            {"minimum", -1},
            {"maximum", 3},
            {"description",
             "KITTI camera 0..3 (0, 1 gray; 2, 3 colour); -1: the "
             "lowest-numbered image folder present"}}},
          {"poses",
           {{"type", "string"},
            {"default", d.poses},
            {"description",
             "poses file (12 numbers a line, camera i -> world); \"\": the "
             "layout's default (KITTI odometry: poses.txt or "
             "../../poses/<seq>.txt; KITTI raw: poses*.txt, else oxts)"}}},
          {"poses_camera",
           {{"type", "integer"},
            {"default", d.poses_camera},
            {"minimum", -1},
            {"maximum", 3},
            {"description",
             "the camera the poses file gives; -1: from its name "
             "(poses_cam2* -> 2), else 0"}}},
          {"first_frame",
           {{"type", "integer"},
            {"default", d.first_frame},
            {"minimum", 0},
            {"description", "first source frame used"}}},
          {"frame_count",
           {{"type", "integer"},
            {"default", d.frame_count},
            {"minimum", -1},
            {"description", "at most this many frames; -1: all to the end"}}},
          {"frame_step",
           {{"type", "integer"},
            {"default", d.frame_step},
            {"minimum", 1},
            {"description", "use every n-th source frame"}}},
          {"keyframe_every",
           {{"type", "integer"},
            {"default", d.keyframe_every},
            {"minimum", 1},
            {"description",
             "a keyframe every this many frames (paper: 5): tracks are replenished and points "
             "triangulated, refined and handed to the engine there"}}},
          {"max_image_megapixels",
           {{"type", "number"},
            {"default", d.max_image_megapixels},
            {"minimum", 1e-6},
            {"maximum", 1e6},
            {"description",
             "larger images are refused from their header, before decoding (a small file can "
             "declare a huge size)"}}}};
}

ImageSequenceOptions ImageSequenceOptionsFromJson(const json& o) {
  ImageSequenceOptions r;
  r.camera = o.at("camera");
  r.poses = o.at("poses").get<std::string>();
  r.poses_camera = o.at("poses_camera");
  r.first_frame = o.at("first_frame");
  r.frame_count = o.at("frame_count");
  r.frame_step = o.at("frame_step");
  r.keyframe_every = o.at("keyframe_every");
  r.max_image_megapixels = o.at("max_image_megapixels").get<double>();
  if (const std::string problem = r.Check(); !problem.empty())
    throw std::runtime_error("input.options." + problem);
  return r;
}

std::string FileProblem(const std::string& path, const std::string& expected) {
  return InputFileProblem(path, expected);  // the open rule's words (host/util/input_file.h)
}

void SkipByteOrderMark(std::string* first_line) {
  if (first_line->rfind("\xEF\xBB\xBF", 0) == 0) first_line->erase(0, 3);
}

std::vector<std::string> ReadTextLines(const std::string& path, const std::string& what) {
  InputStream in(path, what);  // regular files only: a FIFO or a device is refused by name
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();  // files written on Windows
    if (lines.empty()) SkipByteOrderMark(&line);
    lines.push_back(std::move(line));
  }
  return lines;
}

std::vector<double> ParseNumbers(const std::string& text, const std::string& file, int line) {
  std::vector<double> numbers;
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && blank(text[i])) ++i;
    if (i == text.size()) break;
    std::size_t end = i;
    while (end < text.size() && !blank(text[end])) ++end;
    const char* first = text.data() + i;
    if (*first == '+') ++first;  // from_chars takes no leading '+'
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(first, text.data() + end, v);
    if (ec != std::errc() || ptr != text.data() + end || !std::isfinite(v))
      throw std::runtime_error(file + ":" + std::to_string(line) + ": column " +
                               std::to_string(i + 1) + " (number " +
                               std::to_string(numbers.size() + 1) + "): '" +
                               text.substr(i, end - i) + "' is not a finite number");
    numbers.push_back(v);
    i = end;
  }
  return numbers;
}

std::vector<int> SelectSourceFrames(int source_count, const ImageSequenceOptions& o,
                                    const std::string& sequence) {
  if (source_count <= 0) throw std::runtime_error(sequence + ": the sequence has no frames");
  if (o.first_frame >= source_count)
    throw std::runtime_error(sequence + ": first_frame " + std::to_string(o.first_frame) +
                             " is past the last frame (the sequence has " +
                             std::to_string(source_count) + ", numbered from 0)");
  std::vector<int> frames;
  for (int i = o.first_frame; i < source_count; i += std::max(o.frame_step, 1)) {
    if (o.frame_count >= 0 && static_cast<int>(frames.size()) >= o.frame_count) break;
    frames.push_back(i);
  }
  return frames;
}

std::string FileLine(const std::string& file, int line) {
  return file + ":" + std::to_string(line);
}

bool IsBlankLine(const std::string& line) {
  return line.find_first_not_of(" \t\r") == std::string::npos;
}

bool ParseFrameSelection(const std::string& text, ImageSequenceOptions* options) {
  int v[3] = {0, -1, 1};
  std::stringstream ss(text);
  int n = 0;
  for (std::string item; std::getline(ss, item, ':'); ++n) {
    if (n == 3) return false;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), v[n]);
    if (r.ec != std::errc() || r.ptr != item.data() + item.size()) return false;
  }
  if (n == 0) return false;
  options->first_frame = v[0];
  options->frame_count = v[1];
  options->frame_step = v[2];
  return true;
}

}  // namespace imr::io
