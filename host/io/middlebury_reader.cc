// Middlebury multi-view stereo (Seitz et al. 2006) *_par.txt -> ImageSequence. The file already
// uses the convention of camera_model.h: P = K [R | t] with R world -> camera, world = the
// object's frame as the file gives it.
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace imr::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

[[noreturn]] void Fail(const std::string& message) { throw std::runtime_error(message); }

// The one *_par.txt in a folder, or the file itself.
fs::path FindParFile(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_directory(path, ec)) {
    if (!fs::exists(fs::symlink_status(path, ec)))
      Fail(path.string() + ": no such file or folder (a Middlebury *_par.txt or its folder)");
    return path;  // a file: read by the open rule, which refuses a FIFO or a device by name
  }
  std::vector<fs::path> found;
  for (const auto& e : fs::directory_iterator(path)) {
    const std::string name = e.path().filename().string();
    if (!e.is_directory() && name.size() > 8 && name.ends_with("_par.txt"))
      found.push_back(e.path());
  }
  std::sort(found.begin(), found.end());
  if (found.size() == 1) return found.front();
  std::string names;
  for (const auto& p : found) names += (names.empty() ? "" : ", ") + p.filename().string();
  Fail(path.string() + ": " +
       (found.empty() ? std::string("no *_par.txt file (Middlebury camera parameters)")
                      : "several *_par.txt files (" + names + "); name one"));
}

// A _par.txt file's lines, without trailing blank ones; the count on line `first`, one view
// per line after it (checked).
struct ParLines {
  std::vector<std::string> lines;
  std::size_t first = 0;
  int views = 0;
};

ParLines ReadParLines(const std::string& file) {
  ParLines p;
  p.lines = ReadTextLines(file,
                          "Middlebury camera parameters: a count, then per line: image name, "
                          "K (9), R (9), t (3)");
  std::vector<std::string>& lines = p.lines;
  while (!lines.empty() && IsBlankLine(lines.back())) lines.pop_back();
  while (p.first < lines.size() && IsBlankLine(lines[p.first])) ++p.first;
  if (p.first == lines.size()) Fail(file + ": empty (expected a count, then one line per view)");
  const int count_line = static_cast<int>(p.first + 1);
  const std::vector<double> count = ParseNumbers(lines[p.first], file, count_line);
  // The upper bound keeps the cast below defined (a count like 1e300 is a bad file, not UB; found
  // by tests/fuzz/middlebury_fuzz); the view lines must match it anyway.
  if (count.size() != 1 || count[0] != std::floor(count[0]) || count[0] < 1 || count[0] > 1e9)
    Fail(FileLine(file, count_line) + ": expected the number of views (one integer >= 1), got '" +
         lines[p.first] + "'");
  p.views = static_cast<int>(count[0]);
  const int view_lines = static_cast<int>(lines.size() - p.first - 1);
  if (view_lines != p.views)
    Fail(FileLine(file, count_line) + ": says " + std::to_string(p.views) + " views, but the file has " +
         std::to_string(view_lines) + " view lines after it");
  return p;
}

// One view line: the image name and K, R, t (21 numbers; K without skew, R a rotation, t finite).
struct ParView {
  std::string name;
  std::vector<double> v;
  Mat3 r{};
};

ParView ParseParView(const std::string& text, const std::string& file, int line) {
  ParView view;
  const std::size_t name_begin = text.find_first_not_of(" \t");
  if (name_begin == std::string::npos)
    Fail(FileLine(file, line) + ": empty, expected an image name and 21 numbers (K, R, t)");
  const std::size_t name_end = std::min(text.find_first_of(" \t", name_begin), text.size());
  view.name = text.substr(name_begin, name_end - name_begin);
  // The name blanked out, so that columns in messages are the file's.
  view.v = ParseNumbers(std::string(name_end, ' ') + text.substr(name_end), file, line);
  const std::vector<double>& v = view.v;
  if (v.size() != 21)
    Fail(FileLine(file, line) + ": " + std::to_string(v.size()) +
         " numbers after the image name, expected 21 (K 3x3, R 3x3, t 3; row-major)");
  const auto zero = [](double x) { return std::abs(x) <= 1e-9; };
  if (!zero(v[1]) || !zero(v[3]) || !zero(v[6]) || !zero(v[7]) || !zero(v[8] - 1.0) ||
      !(v[0] > 0) || !(v[4] > 0))
    Fail(FileLine(file, line) +
         ": K is not fx 0 cx / 0 fy cy / 0 0 1 with fx, fy > 0 (a skewed "
         "or scaled K is not supported)");
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) view.r[a][b] = v[9 + a * 3 + b];
  if (const std::string p = CheckRotation(&view.r); !p.empty())
    Fail(FileLine(file, line) + ": R (numbers 10-18) " + p);
  for (std::size_t k = 18; k < 21; ++k)
    if (const std::string p = CoordinateProblem(v[k]); !p.empty())
      Fail(FileLine(file, line) + ": number " + std::to_string(k + 1) + " (t): " + p);
  return view;
}

// Frame j (source view src) from its view line; the first frame reads its image's size, the
// others take it.
ImageFrame MiddleburyFrame(const ParView& view, int j, int src, const fs::path& image,
                           const ImageSequenceOptions& o, ImageSequence* seq) {
  const std::vector<double>& v = view.v;
  ImageFrame f;
  f.index = j;
  f.source_index = src;
  f.timestamp = src;
  f.image_path = image.string();
  f.camera.id = static_cast<uint64_t>(j);
  f.camera.name = view.name;
  SetFromTranslation(view.r, {v[18], v[19], v[20]}, &f.camera);
  f.camera.has_intrinsics = true;
  Intrinsics& k = f.camera.intrinsics;
  k.source_model = "middlebury_K";
  k.source_params.assign(v.begin(), v.begin() + 9);
  if (j == 0) {
    const ImageSize size = ReadImageSize(image.string(), ImageLimitsFor(o, {}));
    seq->image_limits = ImageLimitsFor(o, size);
    k.width = size.width;
    k.height = size.height;
  } else {
    k.width = seq->frames.front().camera.intrinsics.width;
    k.height = seq->frames.front().camera.intrinsics.height;
  }
  k.fx = v[0];
  k.fy = v[4];
  k.cx = v[2];
  k.cy = v[5];
  k.projectable = true;
  return f;
}

}  // namespace

ImageSequence ReadMiddlebury(const std::string& path, const ImageSequenceOptions& o) {
  if (const std::string p = o.Check(); !p.empty()) Fail(path + ": option " + p);
  if (o.camera != -1 || !o.poses.empty() || o.poses_camera != -1)
    Fail(path +
         ": the options camera, poses and poses_camera do not apply to Middlebury (each "
         "view has its own camera in the _par.txt file); leave them out");
  const fs::path par = FindParFile(path);
  const std::string file = par.string();
  const ParLines par_lines = ReadParLines(file);
  const int views = par_lines.views;

  // Every line is checked, the selected ones become frames.
  const std::vector<int> selected = SelectSourceFrames(views, o, file);
  std::vector<int> frame_of(static_cast<std::size_t>(views), -1);
  for (std::size_t j = 0; j < selected.size(); ++j)
    frame_of[static_cast<std::size_t>(selected[j])] = static_cast<int>(j);
  ImageSequence seq;
  seq.layout = "middlebury";
  seq.root = path;
  seq.camera = 0;
  const fs::path folder = par.parent_path();
  for (int src = 0; src < views; ++src) {
    const std::size_t i = par_lines.first + 1 + static_cast<std::size_t>(src);
    const int line = static_cast<int>(i + 1);
    const ParView view = ParseParView(par_lines.lines[i], file, line);
    const int j = frame_of[static_cast<std::size_t>(src)];
    if (j < 0) continue;
    const fs::path image = folder / view.name;
    if (const std::string p = FileProblem(image.string(), "an image file"); !p.empty())
      Fail(image.string() + ": " + p + " (the image of " + FileLine(file, line) + ")");
    seq.frames.push_back(MiddleburyFrame(view, j, src, image, o, &seq));
  }

  json& s = seq.summary;
  s["layout"] = seq.layout;
  s["root"] = seq.root;
  s["camera"] = seq.camera;
  s["poses"] = {{"file", file},
                {"chosen_by", path == file ? "the path named"
                                           : "the only "
                                             "*_par.txt in the folder"}};
  s["source_frames"] = views;
  s["frames"] = selected.size();
  s["first_frame"] = selected.front();
  s["last_frame"] = selected.back();
  s["frame_step"] = o.frame_step;
  const Intrinsics& k = seq.frames.front().camera.intrinsics;
  s["image_size"] = {k.width, k.height};
  s["has_lidar"] = false;
  return seq;
}

}  // namespace imr::io
