// KITTI odometry and KITTI raw layouts -> ImageSequence (image_sequence.h), in the convention of
// camera_model.h. Both layouts give rectified cameras: P_k = K [I | b_k] in the rectified frame
// of camera 0, so the cameras of the rig differ only by the baseline b_k = K^-1 P_k[:, 3]
// (x_cam_k = x_rect + b_k), and a pose given for camera p serves camera k shifted by b_k - b_p.
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/util/geodesy.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <numbers>
#include <stdexcept>

namespace imr::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

[[noreturn]] void Fail(const std::string& message) { throw std::runtime_error(message); }

Mat34 ToMat34(const Rigid& a) {
  Mat34 m{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[i][j] = a.r[i][j];
    m[i][3] = a.t[i];
  }
  return m;
}

Rigid FromRowMajor12(const std::vector<double>& v) {
  Rigid a;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) a.r[i][j] = v[i * 4 + j];
    a.t[i] = v[i * 4 + 3];
  }
  return a;
}

Mat3 FromRowMajor9(const std::vector<double>& v) {
  Mat3 m{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m[i][j] = v[i * 3 + j];
  return m;
}

json ToJson(const Vec3& v) { return json::array({v[0], v[1], v[2]}); }

// "<root>" as an absolute, lexically normal path without a trailing separator: its parent is
// then the folder above (a symlinked drive folder keeps its date folder).
fs::path Normalized(const fs::path& p) {
  fs::path n = fs::absolute(p).lexically_normal();
  if (n.filename().empty() && n.has_parent_path()) n = n.parent_path();
  return n;
}

void RequireFolder(const fs::path& p, const std::string& what) {
  std::error_code ec;
  if (!fs::is_directory(p, ec)) Fail(p.string() + ": no such folder (" + what + ")");
}

std::string Numbered(int index, int digits, const std::string& extension) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%0*d", digits, index);
  return buf + extension;
}

// Whether anything is at `p`: an optional file that is there but no regular file (a FIFO, a
// folder) is read and refused by name by the open rule, not taken for absent.
bool Present(const fs::path& p) {
  std::error_code ec;
  return fs::exists(fs::symlink_status(p, ec));
}

int CountFiles(const fs::path& dir, const std::string& extension) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    // A FIFO or a device named like an image is counted: the open rule names it when it is read.
    if (!e.is_directory() && e.path().extension() == extension) ++n;
  return n;
}

// A "key: numbers" calibration file (KITTI calib.txt, calib_cam_to_cam.txt, ...).
class CalibFile {
 public:
  CalibFile(const fs::path& path, const std::string& what) : path_(path.string()) {
    const std::vector<std::string> lines = ReadTextLines(path_, what);
    for (std::size_t i = 0; i < lines.size(); ++i) {
      const std::size_t colon = lines[i].find(':');
      if (colon == std::string::npos) continue;
      std::string key = lines[i].substr(0, colon);
      key.erase(0, key.find_first_not_of(" \t"));
      key.erase(key.find_last_not_of(" \t") + 1);
      // The key blanked out, so that columns in messages are the file's.
      entries_.try_emplace(key, Entry{static_cast<int>(i + 1),
                                      std::string(colon + 1, ' ') + lines[i].substr(colon + 1)});
    }
  }
  const std::string& path() const { return path_; }
  bool Has(const std::string& key) const { return entries_.count(key) > 0; }

  // Exactly `count` numbers; `what` says what the entry is, for messages.
  std::vector<double> Numbers(const std::string& key, std::size_t count, const std::string& what,
                              int* line = nullptr) const {
    const auto it = entries_.find(key);
    if (it == entries_.end()) Fail(path_ + ": no line '" + key + ":' (" + what + ")");
    std::vector<double> v = ParseNumbers(it->second.text, path_, it->second.line);
    if (v.size() != count)
      Fail(FileLine(path_, it->second.line) + ": " + key + " has " + std::to_string(v.size()) +
           " numbers, expected " + std::to_string(count) + " (" + what + ")");
    if (line != nullptr) *line = it->second.line;
    return v;
  }

  Mat3 Rotation(const std::string& key, const std::string& what) const {
    int line = 0;
    Mat3 r = FromRowMajor9(Numbers(key, 9, what, &line));
    if (const std::string p = CheckRotation(&r); !p.empty())
      Fail(FileLine(path_, line) + ": " + key + " " + p);
    return r;
  }

  // R (9 numbers) and T (3) lines, e.g. calib_velo_to_cam.txt.
  Rigid RotationTranslation(const std::string& what) const {
    Rigid a;
    a.r = Rotation("R", what + ", rotation");
    const std::vector<double> t = Numbers("T", 3, what + ", translation");
    a.t = {t[0], t[1], t[2]};
    return a;
  }

  // A 3x4 [R | t] on one line, e.g. Tr in calib.txt.
  Rigid Transform34(const std::string& key, const std::string& what) const {
    int line = 0;
    Rigid a = FromRowMajor12(Numbers(key, 12, what + ", row-major 3x4", &line));
    if (const std::string p = CheckRotation(&a.r); !p.empty())
      Fail(FileLine(path_, line) + ": the rotation of " + key + " " + p);
    return a;
  }

 private:
  struct Entry {
    int line = 0;
    std::string text;
  };
  std::string path_;
  std::map<std::string, Entry> entries_;
};

// A rectified projection P = K [I | b] (KITTI P0..P3, P_rect_00..03).
struct RectifiedCamera {
  std::vector<double> projection;  // the 12 numbers, row-major
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Vec3 baseline{};  // b = K^-1 P[:, 3]: x_cam = x_rect + b
};

RectifiedCamera ReadProjection(const CalibFile& calib, const std::string& key, int camera) {
  const std::string what = "the rectified projection of camera " + std::to_string(camera);
  int line = 0;
  RectifiedCamera c;
  c.projection = calib.Numbers(key, 12, what + ", row-major 3x4", &line);
  const std::vector<double>& p = c.projection;
  const auto zero = [](double v) { return std::abs(v) <= 1e-9; };
  // Row 3 = (0 0 1 b_z), no skew, positive focal lengths: K [I | b] with K upper triangular.
  if (!zero(p[1]) || !zero(p[4]) || !zero(p[8]) || !zero(p[9]) || !zero(p[10] - 1.0) ||
      !(p[0] > 0) || !(p[5] > 0))
    Fail(FileLine(calib.path(), line) + ": " + key + " is not a rectified projection K [I | b] (" + what +
         "): expected fx 0 cx _ / 0 fy cy _ / 0 0 1 _ with fx, fy > 0");
  c.fx = p[0];
  c.fy = p[5];
  c.cx = p[2];
  c.cy = p[6];
  const double bz = p[11];
  const double by = (p[7] - c.cy * bz) / c.fy;
  const double bx = (p[3] - c.cx * bz) / c.fx;
  c.baseline = {bx, by, bz};
  return c;
}

// Poses file, KITTI odometry convention: line i = row-major 3x4 T, camera i -> world.
std::vector<Rigid> ReadPosesFile(const std::string& path) {
  std::vector<std::string> lines =
      ReadTextLines(path, "the poses file: 12 numbers a line, camera i -> world");
  while (!lines.empty() && IsBlankLine(lines.back())) lines.pop_back();
  std::vector<Rigid> poses;
  poses.reserve(lines.size());
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const int line = static_cast<int>(i + 1);
    const std::vector<double> v = ParseNumbers(lines[i], path, line);
    if (v.size() != 12)
      Fail(FileLine(path, line) + ": " + std::to_string(v.size()) +
           " numbers, expected 12 (row-major 3x4 [R | t], camera -> world)");
    poses.push_back(FromRowMajor12(v));
    if (const std::string p = CheckRotation(&poses.back().r); !p.empty())
      Fail(FileLine(path, line) + ": the rotation (numbers 1-3, 5-7, 9-11) " + p);
    for (int k : {3, 7, 11})
      if (const std::string p = CoordinateProblem(v[static_cast<std::size_t>(k)]); !p.empty())
        Fail(FileLine(path, line) + ": number " + std::to_string(k + 1) + " (the translation): " + p);
  }
  return poses;
}

// Images and their source numbers; checks every selected image exists.
struct FrameSource {
  fs::path image_dir;
  int digits = 6;  // file names: zero-padded source index (odometry 6, raw 10 digits)
  int count = 0;   // .png files in image_dir
};

// A file of one line (or record) per image, `lines` of them for the s.count images: `unit` names
// them ("poses (lines)"), `per_image` what is expected ("one pose per image"). More lines than
// images is a trimmed sequence (the first N images kept, times.txt and the poses left whole, the
// usual way to cut a sequence) when the images are 0..N-1 with none missing: the first N lines
// serve, said in the summary's "trimmed" (the run logs it, report.json lists it as a warning).
// An image missing among them (a gap), or fewer lines than images, is refused, naming the file
// and the line. (A last image lost by accident looks like a cut: the warning says what was used.)
void MatchLinesToImages(const std::string& path, std::size_t lines, const std::string& unit,
                        const std::string& per_image, const FrameSource& s, ImageSequence* seq) {
  const std::size_t images = static_cast<std::size_t>(s.count);
  const auto name = [&](std::size_t i) { return Numbered(static_cast<int>(i), s.digits, ".png"); };
  if (lines < images)
    Fail(path + ": " + std::to_string(lines) + " " + unit + ", but " + s.image_dir.string() +
         " has " + std::to_string(images) + " images (.png); expected " + per_image + " (" +
         name(lines) + (images - lines > 1 ? " .. " + name(images - 1) + " have" : " has") +
         (unit.rfind("oxts", 0) == 0 ? " no record)" : " no line)"));
  if (lines == images) return;
  // More lines than images: usually one image lost from the middle (name it), else a trim.
  for (std::size_t i = 0; i < images; ++i) {
    const fs::path image = s.image_dir / name(i);
    if (const std::string p = FileProblem(image.string(), "a .png image"); !p.empty())
      Fail(image.string() + ": " + p + " (the image of " +
           (unit.rfind("poses", 0) == 0 ? "pose line " : "line ") + std::to_string(i + 1) + " of " +
           path + "; " + s.image_dir.string() + " has " + std::to_string(images) + " images for " +
           std::to_string(lines) + " " + unit + ")");
  }
  const std::string note = path + ": " + std::to_string(lines) + " " + unit + " for the " +
                           std::to_string(images) + " images of " + s.image_dir.string() + " (" +
                           name(0) + " .. " + name(images - 1) +
                           "): a trimmed sequence; the first " + std::to_string(images) +
                           " are used";
  json& trimmed = seq->summary["trimmed"];
  if (!trimmed.is_array()) trimmed = json::array();
  trimmed.push_back(note);
}

// times.txt: one number (seconds) per line, one line per image (the first of more: trimmed).
std::vector<double> ReadTimesFile(const std::string& path, const FrameSource& s,
                                  ImageSequence* seq) {
  std::vector<std::string> lines = ReadTextLines(path, "timestamps: seconds, one line per image");
  while (!lines.empty() && IsBlankLine(lines.back())) lines.pop_back();
  MatchLinesToImages(path, lines.size(), "timestamps (lines)", "one per image", s, seq);
  lines.resize(static_cast<std::size_t>(s.count));
  std::vector<double> times;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const int line = static_cast<int>(i + 1);
    const std::vector<double> v = ParseNumbers(lines[i], path, line);
    if (v.size() != 1)
      Fail(FileLine(path, line) + ": " + std::to_string(v.size()) + " numbers, expected 1 (seconds)");
    times.push_back(v[0]);
  }
  return times;
}

// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's days_from_civil).
int64_t DaysFromCivil(int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<int64_t>(doe) - 719468;
}

// KITTI raw image_0X/timestamps.txt: "2011-09-26 13:02:25.964389445" a line, as seconds since
// the first line.
std::vector<double> ReadDateTimestamps(const std::string& path, const FrameSource& source,
                                       ImageSequence* seq) {
  std::vector<std::string> lines =
      ReadTextLines(path, "timestamps: 'YYYY-MM-DD hh:mm:ss.fraction', one line per image");
  while (!lines.empty() && IsBlankLine(lines.back())) lines.pop_back();
  MatchLinesToImages(path, lines.size(), "timestamps (lines)", "one per image", source, seq);
  lines.resize(static_cast<std::size_t>(source.count));
  std::vector<double> times;
  int64_t day0 = 0;
  double second0 = 0;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    int y = 0, mo = 0, d = 0, h = 0, mi = 0, used = 0;
    double s = 0;
    const int fields = std::sscanf(lines[i].c_str(), " %4d-%2d-%2d %2d:%2d:%lf%n", &y, &mo, &d, &h,
                                   &mi, &s, &used);
    if (fields != 6 || !IsBlankLine(lines[i].substr(static_cast<std::size_t>(used))) || mo < 1 ||
        mo > 12 || d < 1 || d > 31 || h < 0 || h > 23 || mi < 0 || mi > 59 || !(s >= 0) ||
        !(s < 61))
      Fail(FileLine(path, static_cast<int>(i + 1)) + ": '" + lines[i] +
           "' is not a date 'YYYY-MM-DD hh:mm:ss.fraction'");
    const int64_t day = DaysFromCivil(y, static_cast<unsigned>(mo), static_cast<unsigned>(d));
    const double second = h * 3600.0 + mi * 60.0 + s;
    if (i == 0) {
      day0 = day;
      second0 = second;
    }
    // Whole days and the second of the day apart, so the nanoseconds survive in a double.
    times.push_back(static_cast<double>(day - day0) * 86400.0 + (second - second0));
  }
  return times;
}

// The camera whose image folder is used: the requested one, else the lowest present.
int ChooseCamera(const fs::path& root, int requested, bool raw, std::string* chosen_by) {
  const auto folder = [&](int k) {
    return root / ((raw ? "image_0" : "image_") + std::to_string(k));
  };
  std::error_code ec;
  if (requested >= 0) {
    if (!fs::is_directory(folder(requested), ec))
      Fail(folder(requested).string() + ": no such folder (the images of camera " +
           std::to_string(requested) + ", named by the option camera)");
    *chosen_by = "option camera";
    return requested;
  }
  for (int k = 0; k <= 3; ++k) {
    if (fs::is_directory(folder(k), ec)) {
      *chosen_by = "the lowest-numbered image folder present";
      return k;
    }
  }
  Fail(root.string() + ": no image folder (expected " +
       (raw ? "image_00 .. image_03" : "image_0 .. image_3") + ")");
}

// "poses_cam2_lidar.txt" -> 2: the digit after the first "cam" in the name, -1 when none.
int CameraFromName(const std::string& filename) {
  const std::size_t pos = filename.find("cam");
  if (pos == std::string::npos || pos + 3 >= filename.size()) return -1;
  const char c = filename[pos + 3];
  return c >= '0' && c <= '3' ? c - '0' : -1;
}

struct PosesChoice {
  std::string path;         // "" for oxts
  std::string chosen_by;    // how the file was found
  int camera = 0;           // the camera the poses give
  std::string camera_from;  // how that camera was decided
};

void DecidePosesCamera(const ImageSequenceOptions& o, PosesChoice* pc) {
  if (o.poses_camera >= 0) {
    pc->camera = o.poses_camera;
    pc->camera_from = "option poses_camera";
  } else if (const int k = CameraFromName(fs::path(pc->path).filename().string()); k >= 0) {
    pc->camera = k;
    pc->camera_from = "the file name";
  } else {
    pc->camera = 0;
    pc->camera_from = "default (KITTI ground truth is camera 0)";
  }
}

FrameSource ReadFrameSource(const fs::path& image_dir, int digits) {
  RequireFolder(image_dir, "the images of the chosen camera");
  FrameSource s{image_dir, digits, CountFiles(image_dir, ".png")};
  if (s.count == 0) Fail(image_dir.string() + ": no .png images");
  return s;
}

// Frames with cameras: `camera_to_world[src]` is the pose (poses camera -> world) of source
// frame src; `offset` = b_k - b_p moves it to the chosen camera.
void AddFrames(const FrameSource& s, const std::vector<int>& selected,
               const std::vector<Rigid>& camera_to_world, const Vec3& offset,
               const std::vector<double>& times, const RectifiedCamera& rect,
               const ImageSequenceOptions& options, ImageSequence* seq) {
  for (const int src : selected) {
    const fs::path image = s.image_dir / Numbered(src, s.digits, ".png");
    if (const std::string p = FileProblem(image.string(), "a .png image"); !p.empty())
      Fail(image.string() + ": " + p + " (the image of source frame " + std::to_string(src) + ")");
  }
  Intrinsics k;
  k.source_model = "kitti_rectified";
  k.source_params = rect.projection;
  const ImageSize size = ReadImageSize((s.image_dir / Numbered(selected[0], s.digits, ".png")).string(),
                                       ImageLimitsFor(options, {}));
  seq->image_limits = ImageLimitsFor(options, size);
  k.width = size.width;
  k.height = size.height;
  k.fx = rect.fx;
  k.fy = rect.fy;
  k.cx = rect.cx;
  k.cy = rect.cy;
  k.projectable = true;

  for (std::size_t j = 0; j < selected.size(); ++j) {
    const int src = selected[j];
    ImageFrame f;
    f.index = static_cast<int>(j);
    f.source_index = src;
    f.timestamp = times[static_cast<std::size_t>(src)];
    const std::string name = Numbered(src, s.digits, ".png");
    f.image_path = (s.image_dir / name).string();
    const Rigid& wc = camera_to_world[static_cast<std::size_t>(src)];
    // x_world = T_R x_cam + T_t  =>  x_cam = T_R^T x_world - T_R^T T_t; then + b_k - b_p.
    const Mat3 r = Transpose(wc.r);
    const Vec3 rt = Mul(r, wc.t);
    f.camera.id = static_cast<uint64_t>(j);
    f.camera.name = name;
    SetFromTranslation(r, Add(Vec3{-rt[0], -rt[1], -rt[2]}, offset), &f.camera);
    f.camera.has_intrinsics = true;
    f.camera.intrinsics = k;
    seq->frames.push_back(std::move(f));
  }
}

// Velodyne scans (<dir>/<source index>.bin), "" for those missing.
void AddLidar(const fs::path& dir, int digits, const std::vector<int>& selected,
              const Rigid& velo_to_camera, ImageSequence* seq) {
  int found = 0;
  for (const int src : selected) {
    const fs::path p = dir / Numbered(src, digits, ".bin");
    std::error_code ec;
    const bool exists = Present(p);
    seq->lidar.scan_paths.push_back(exists ? p.string() : "");
    found += exists;
  }
  seq->lidar.velo_to_camera = ToMat34(velo_to_camera);
  seq->has_lidar = found > 0;
  seq->summary["lidar"] = {{"folder", dir.string()},
                           {"scans_found", found},
                           {"velo_to_camera", json::array({json(seq->lidar.velo_to_camera[0]),
                                                           json(seq->lidar.velo_to_camera[1]),
                                                           json(seq->lidar.velo_to_camera[2])})}};
}

void SummariseFrames(const FrameSource& s, const std::vector<int>& selected,
                     const ImageSequenceOptions& o, ImageSequence* seq) {
  json& j = seq->summary;
  j["images"] = s.image_dir.string();
  j["source_frames"] = s.count;
  j["frames"] = selected.size();
  j["first_frame"] = selected.front();
  j["last_frame"] = selected.back();
  j["frame_step"] = o.frame_step;
  const Intrinsics& k = seq->frames.front().camera.intrinsics;
  j["image_size"] = {k.width, k.height};
  j["intrinsics"] = {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}};
}

// --- oxts (GPS/IMU) poses, as the KITTI raw devkit's convertOxtsToPose.m ----------------------

constexpr double kEarthRadius = 6378137.0;  // the devkit's er (WGS84 equatorial radius)

struct OxtsRecord {
  double lat = 0, lon = 0, alt = 0, roll = 0, pitch = 0, yaw = 0;
};

OxtsRecord ReadOxts(const fs::path& path) {
  std::vector<std::string> lines =
      ReadTextLines(path.string(), "oxts record: 30 numbers, lat lon alt roll pitch yaw ...");
  std::size_t i = 0;
  while (i < lines.size() && IsBlankLine(lines[i])) ++i;
  if (i == lines.size()) Fail(path.string() + ": empty (expected one oxts record of 30 numbers)");
  const int line = static_cast<int>(i + 1);
  const std::vector<double> v = ParseNumbers(lines[i], path.string(), line);
  if (v.size() != 30)
    Fail(FileLine(path.string(), line) + ": " + std::to_string(v.size()) +
         " numbers, expected 30 (lat lon alt roll pitch yaw vn ve vf vl vu ax ay az af al au wx "
         "wy wz wf wl wu pos_accuracy vel_accuracy navstat numsats posmode velmode orimode)");
  if (!(std::abs(v[0]) < 90.0))
    Fail(FileLine(path.string(), line) + ": latitude " + std::to_string(v[0]) +
         " is not within (-90, 90) degrees");
  return {v[0], v[1], v[2], v[3], v[4], v[5]};
}

// IMU -> world (East-North-Up Mercator) of one record: t from Mercator with `scale` =
// cos(first latitude), R = Rz(yaw) Ry(pitch) Rx(roll).
Rigid OxtsToImuPose(const OxtsRecord& o, double scale) {
  const double pi = std::numbers::pi;
  Rigid a;
  a.t = {scale * o.lon * pi * kEarthRadius / 180.0,
         scale * kEarthRadius * std::log(std::tan((90.0 + o.lat) * pi / 360.0)), o.alt};
  const double cx = std::cos(o.roll), sx = std::sin(o.roll);
  const double cy = std::cos(o.pitch), sy = std::sin(o.pitch);
  const double cz = std::cos(o.yaw), sz = std::sin(o.yaw);
  const Mat3 rx = {{{1, 0, 0}, {0, cx, -sx}, {0, sx, cx}}};
  const Mat3 ry = {{{cy, 0, sy}, {0, 1, 0}, {-sy, 0, cy}}};
  const Mat3 rz = {{{cz, -sz, 0}, {sz, cz, 0}, {0, 0, 1}}};
  a.r = MatMul(rz, MatMul(ry, rx));
  return a;
}

}  // namespace

ImageSequence ReadKittiOdometry(const std::string& root_arg, const ImageSequenceOptions& o) {
  if (const std::string p = o.Check(); !p.empty()) Fail(root_arg + ": option " + p);
  const fs::path root(root_arg);
  RequireFolder(root, "a KITTI odometry sequence: image_0..image_3, calib.txt, times.txt");
  ImageSequence seq;
  seq.layout = "kitti_odometry";
  seq.root = root_arg;
  std::string camera_chosen_by;
  seq.camera = ChooseCamera(root, o.camera, false, &camera_chosen_by);
  const std::string k = std::to_string(seq.camera);
  const FrameSource source = ReadFrameSource(root / ("image_" + k), 6);

  const CalibFile calib(root / "calib.txt",
                        "KITTI odometry calibration: P0..P3, Tr = velodyne -> camera 0");
  const RectifiedCamera rect = ReadProjection(calib, "P" + k, seq.camera);

  PosesChoice pc;
  if (!o.poses.empty()) {
    pc.path = o.poses;
    pc.chosen_by = "option poses";
  } else {
    std::error_code ec;
    const fs::path beside = root / "poses.txt";
    const fs::path devkit = Normalized(root).parent_path().parent_path() / "poses" /
                            (Normalized(root).filename().string() + ".txt");
    if (Present(beside)) {
      pc.path = beside.string();
      pc.chosen_by = "poses.txt in the sequence folder";
    } else if (Present(devkit)) {
      pc.path = devkit.string();
      pc.chosen_by = "the devkit layout (dataset/poses/<sequence>.txt)";
    } else {
      Fail(root_arg + ": no poses file: the option poses is empty, and neither " + beside.string() +
           " nor " + devkit.string() +
           " exists (KITTI odometry has ground truth for sequences 00-10 only)");
    }
  }
  DecidePosesCamera(o, &pc);
  const RectifiedCamera poses_rect =
      pc.camera == seq.camera ? rect
                              : ReadProjection(calib, "P" + std::to_string(pc.camera), pc.camera);
  const std::vector<Rigid> poses = ReadPosesFile(pc.path);
  MatchLinesToImages(pc.path, poses.size(), "poses (lines)", "one pose per image", source, &seq);
  const std::string times_path = (root / "times.txt").string();
  const std::vector<double> times = ReadTimesFile(times_path, source, &seq);

  const std::vector<int> selected = SelectSourceFrames(source.count, o, root_arg);
  const Vec3 offset = Sub(rect.baseline, poses_rect.baseline);
  AddFrames(source, selected, poses, offset, times, rect, o, &seq);

  json& s = seq.summary;
  s["layout"] = seq.layout;
  s["root"] = seq.root;
  s["camera"] = seq.camera;
  s["camera_chosen_by"] = camera_chosen_by;
  s["calibration"] = calib.path();
  s["poses"] = {{"file", pc.path},
                {"chosen_by", pc.chosen_by},
                {"camera", pc.camera},
                {"camera_from", pc.camera_from}};
  s["baseline_applied"] = ToJson(offset);
  s["times"] = times_path;
  SummariseFrames(source, selected, o, &seq);

  // Tr maps Velodyne to the rectified frame of camera 0 (which P_k projects from).
  const fs::path velodyne = root / "velodyne";
  std::error_code ec;
  if (fs::is_directory(velodyne, ec)) {
    Rigid tr =
        calib.Transform34("Tr", "velodyne -> rectified camera 0, needed for " + velodyne.string());
    tr.t = Add(tr.t, rect.baseline);
    AddLidar(velodyne, 6, selected, tr, &seq);
  }
  s["has_lidar"] = seq.has_lidar;
  // A sequence rendered by imr-synth says what scene it shows (exact ground truth). Its world is
  // the frame of poses.txt (camera 0), so it applies only when the poses are the generator's own.
  const fs::path scene = root / "ground_truth" / "scene.json";
  if (Present(scene) && o.poses.empty() && pc.camera == 0) {
    seq.synthetic_scene = scene.string();
    s["ground_truth"] = scene.string();
  }
  return seq;
}

namespace {

// A raw drive's poses: the option, else poses*.txt in the drive folder (several: the one named
// for `camera`), else none (path "": oxts).
PosesChoice FindRawPoses(const fs::path& root, const std::string& root_arg, int camera,
                         const ImageSequenceOptions& o) {
  PosesChoice pc;
  if (!o.poses.empty()) {
    pc.path = o.poses;
    pc.chosen_by = "option poses";
    return pc;
  }
  std::vector<fs::path> found;
  for (const auto& e : fs::directory_iterator(root)) {
    const std::string name = e.path().filename().string();
    if (!e.is_directory() && name.rfind("poses", 0) == 0 && e.path().extension() == ".txt")
      found.push_back(e.path());
  }
  std::sort(found.begin(), found.end());
  if (found.size() > 1) {  // several: the one named for the chosen camera
    std::vector<fs::path> mine;
    for (const auto& p : found)
      if (CameraFromName(p.filename().string()) == camera) mine.push_back(p);
    if (mine.size() != 1) {
      std::string names;
      for (const auto& p : found) names += (names.empty() ? "" : ", ") + p.filename().string();
      Fail(root_arg + ": several poses files (" + names +
           ") and not exactly one named for "
           "camera " +
           std::to_string(camera) + " (poses_cam" + std::to_string(camera) +
           "*); name one with the option poses");
    }
    found = mine;
    pc.chosen_by = "the poses*.txt in the drive folder named for camera 0" + std::to_string(camera);
  } else {
    pc.chosen_by = "the only poses*.txt in the drive folder";
  }
  if (!found.empty()) pc.path = found.front().string();
  return pc;
}

// A raw drive's camera poses from its oxts records (one per image; world = the chosen camera
// at source frame 0), for the selected frames.
std::vector<Rigid> OxtsPoses(const fs::path& root, const std::string& root_arg, const fs::path& date,
                             const RectifiedCamera& rect, const std::function<Rigid()>& velo_to_rect,
                             const FrameSource& source, const std::vector<int>& selected,
                             ImageSequence* seq) {
  std::error_code ec;
  const fs::path oxts = root / "oxts" / "data";
  if (!fs::is_directory(oxts, ec))
    Fail(root_arg +
         ": no poses: the option poses is empty, there is no poses*.txt in the "
         "drive folder and no " +
         oxts.string() + " folder");
  MatchLinesToImages(oxts.string(), static_cast<std::size_t>(CountFiles(oxts, ".txt")),
                     "oxts records (.txt)", "one per image", source, seq);
  const CalibFile imu_to_velo(date / "calib_imu_to_velo.txt",
                              "KITTI raw calibration imu -> velodyne: R, T; needed for oxts");
  // IMU -> rectified camera k: [I | b_k] R_rect_00 T_velo_to_cam T_imu_to_velo.
  const Rigid cam_from_imu = Compose(Compose(Rigid{Identity3(), rect.baseline}, velo_to_rect()),
                                     imu_to_velo.RotationTranslation("imu -> velodyne"));
  const Rigid imu_from_cam = Inverse(cam_from_imu);
  const auto record = [&](int src) { return ReadOxts(oxts / Numbered(src, 10, ".txt")); };
  const OxtsRecord first = record(0);
  const double scale = std::cos(first.lat * std::numbers::pi / 180.0);
  const Rigid world0_from_world = Inverse(OxtsToImuPose(first, scale));
  std::vector<Rigid> camera_to_world(static_cast<std::size_t>(source.count));
  for (const int src : selected) {
    // IMU pose relative to the first (the devkit's pose{i}), then the camera's: world =
    // camera k of source frame 0.
    const Rigid imu = Compose(world0_from_world, OxtsToImuPose(record(src), scale));
    camera_to_world[static_cast<std::size_t>(src)] =
        Compose(cam_from_imu, Compose(imu, imu_from_cam));
  }
  seq->summary["poses"] = {{"file", oxts.string()},
                           {"chosen_by", "oxts (no poses option, no poses*.txt in the drive folder)"},
                           {"camera", seq->camera},
                           {"camera_from", "computed for the chosen camera through the calibration"},
                           {"mercator_scale", scale}};
  // Where the world (camera k at source frame 0) stands on the Earth. The Mercator frame's
  // axes at the first record are east, north, up at unit scale (the scale is its latitude's),
  // so the camera's offset from the IMU there is an ENU offset from the IMU's position.
  const Rigid merc_from_imu0 = OxtsToImuPose(first, scale);
  const Rigid merc_from_world = Compose(merc_from_imu0, imu_from_cam);
  const Vec3 offset_enu = Sub(merc_from_world.t, merc_from_imu0.t);
  const std::array<double, 3> imu_ecef = geo::EcefFromGeodetic({first.lat, first.lon, first.alt});
  const std::array<double, 9> enu = geo::EnuAxes(first.lat, first.lon);
  std::array<double, 3> camera_ecef = imu_ecef;
  for (int axis = 0; axis < 3; ++axis)
    for (int j = 0; j < 3; ++j) camera_ecef[axis] += enu[3 * j + axis] * offset_enu[j];
  geo::GeoAnchor anchor;
  anchor.origin = geo::GeodeticFromEcef(camera_ecef);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) anchor.enu_from_world[3 * r + c] = merc_from_world.r[r][c];
  anchor.source = (oxts / Numbered(0, 10, ".txt")).string() + " (GNSS/IMU of source frame 0)";
  seq->summary["geo_anchor"] = {{"latitude", anchor.origin.latitude},
                                {"longitude", anchor.origin.longitude},
                                {"height", anchor.origin.height},
                                {"source", anchor.source}};
  seq->geo = anchor;
  return camera_to_world;
}

// A raw drive's timestamps: image_0X/timestamps.txt (dates), else times.txt (seconds), else
// 10 Hz.
std::vector<double> DriveTimes(const fs::path& root, const std::string& k, const FrameSource& source,
                               ImageSequence* seq) {
  std::vector<double> times;
  const fs::path dates = root / ("image_" + k) / "timestamps.txt";
  const fs::path seconds = root / "times.txt";
  json& s = seq->summary;
  if (Present(dates)) {
    times = ReadDateTimestamps(dates.string(), source, seq);
    s["times"] = dates.string() + " (seconds since the first)";
  } else if (Present(seconds)) {
    times = ReadTimesFile(seconds.string(), source, seq);
    s["times"] = seconds.string();
  } else {
    for (int i = 0; i < source.count; ++i) times.push_back(0.1 * i);
    s["times"] = "none found: 0.1 s steps (KITTI's 10 Hz)";
  }
  return times;
}

}  // namespace

ImageSequence ReadKittiRaw(const std::string& root_arg, const ImageSequenceOptions& o) {
  if (const std::string p = o.Check(); !p.empty()) Fail(root_arg + ": option " + p);
  const fs::path root(root_arg);
  RequireFolder(root, "a KITTI raw drive folder: <date>/<date>_drive_NNNN_sync with image_0X/data");
  const fs::path date = Normalized(root).parent_path();
  ImageSequence seq;
  seq.layout = "kitti_raw";
  seq.root = root_arg;
  std::string camera_chosen_by;
  seq.camera = ChooseCamera(root, o.camera, true, &camera_chosen_by);
  const std::string k = "0" + std::to_string(seq.camera);
  const FrameSource source = ReadFrameSource(root / ("image_" + k) / "data", 10);
  const std::vector<int> selected = SelectSourceFrames(source.count, o, root_arg);

  const CalibFile cam_to_cam(date / "calib_cam_to_cam.txt",
                             "KITTI raw camera calibration: P_rect_00..03, R_rect_00; in the date "
                             "folder above the drive");
  const RectifiedCamera rect = ReadProjection(cam_to_cam, "P_rect_" + k, seq.camera);
  // Velodyne -> rectified camera 0, read when needed (oxts poses, Velodyne scans).
  const auto velo_to_rect = [&] {
    const CalibFile velo_to_cam(date / "calib_velo_to_cam.txt",
                                "KITTI raw calibration velodyne -> camera 0: R, T");
    const Rigid rrect{cam_to_cam.Rotation("R_rect_00", "rectifying rotation of camera 0"), {}};
    return Compose(rrect, velo_to_cam.RotationTranslation("velodyne -> camera 0"));
  };

  json& s = seq.summary;
  s["layout"] = seq.layout;
  s["root"] = seq.root;
  s["camera"] = seq.camera;
  s["camera_chosen_by"] = camera_chosen_by;
  s["calibration"] = cam_to_cam.path();

  PosesChoice pc = FindRawPoses(root, root_arg, seq.camera, o);

  std::vector<Rigid> camera_to_world(static_cast<std::size_t>(source.count));
  Vec3 offset{};
  std::error_code ec;
  if (!pc.path.empty()) {
    DecidePosesCamera(o, &pc);
    const RectifiedCamera poses_rect =
        pc.camera == seq.camera
            ? rect
            : ReadProjection(cam_to_cam, "P_rect_0" + std::to_string(pc.camera), pc.camera);
    camera_to_world = ReadPosesFile(pc.path);
    MatchLinesToImages(pc.path, camera_to_world.size(), "poses (lines)", "one pose per image",
                       source, &seq);
    offset = Sub(rect.baseline, poses_rect.baseline);
    s["poses"] = {{"file", pc.path},
                  {"chosen_by", pc.chosen_by},
                  {"camera", pc.camera},
                  {"camera_from", pc.camera_from}};
  } else {
    camera_to_world = OxtsPoses(root, root_arg, date, rect, velo_to_rect, source, selected, &seq);
  }

  const std::vector<double> times = DriveTimes(root, k, source, &seq);
  AddFrames(source, selected, camera_to_world, offset, times, rect, o, &seq);
  s["baseline_applied"] = ToJson(offset);
  SummariseFrames(source, selected, o, &seq);

  const fs::path velodyne = root / "velodyne_points" / "data";
  if (fs::is_directory(velodyne, ec))
    AddLidar(velodyne, 10, selected, Compose(Rigid{Identity3(), rect.baseline}, velo_to_rect()),
             &seq);
  s["has_lidar"] = seq.has_lidar;
  return seq;
}

}  // namespace imr::io
