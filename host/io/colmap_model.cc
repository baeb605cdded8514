#include "host/io/colmap_model.h"

#include "host/io/image_sequence.h"
#include "host/util/atomic_file.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <unordered_map>

namespace imr::io {
namespace fs = std::filesystem;

namespace {

[[noreturn]] void Fail(const std::string& where, const std::string& what) {
  throw std::runtime_error(where + ": " + what);
}

// ---------------------------------------------------------------------------------------------
// Text

std::vector<std::string_view> Tokens(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (j > i) out.push_back(line.substr(i, j - i));
    i = j;
  }
  return out;
}

constexpr const char* kTranslationNames[3] = {"TX", "TY", "TZ"};
constexpr const char* kCoordinateNames[3] = {"X", "Y", "Z"};

struct TextFile {
  // The open rule (host/util/input_file.h): a FIFO or a device is refused by name.
  explicit TextFile(const fs::path& p) : path(p), in(p, "a COLMAP text model file") {}
  // Next line; false at the end. `skip_blank`: comments and blank lines are skipped.
  bool Next(bool skip_blank, std::string* line) {
    while (std::getline(in, *line)) {
      if (++number == 1) SkipByteOrderMark(line);
      if (!skip_blank) return true;
      const auto t = Tokens(*line);
      if (t.empty() || t[0][0] == '#') continue;
      return true;
    }
    return false;
  }
  std::string Where() const { return path.string() + " line " + std::to_string(number); }

  // A number that is a position (a point, a translation), within the readers' one bound.
  double Coordinate(std::string_view tok, const char* what) const {
    const double v = Parse<double>(tok, what);
    if (const std::string p = CoordinateProblem(v); !p.empty()) Fail(Where(), std::string(what) + ": " + p);
    return v;
  }

  template <typename T>
  T Parse(std::string_view tok, const char* what) const {
    T v{};
    // Third-party writers: "+1.5" (printf's %+), "1e-005" and "1.0E+000" (from_chars reads the
    // exponents as they are).
    if (tok.size() > 1 && tok[0] == '+' && tok[1] != '-' && tok[1] != '+') tok.remove_prefix(1);
    const char* end = tok.data() + tok.size();
    auto r = std::from_chars(tok.data(), end, v);
    if (r.ec != std::errc() || r.ptr != end)
      Fail(Where(), std::string("expected ") + what + ", got \"" + JsonText(tok) + "\"");
    if constexpr (std::is_floating_point_v<T>)
      if (!std::isfinite(v)) Fail(Where(), std::string(what) + " is not finite");
    return v;
  }

  fs::path path;
  InputStream in;
  int number = 0;
};

void ReadCamerasText(const fs::path& p, ColmapModel* m) {
  TextFile f(p);
  std::string line;
  while (f.Next(true, &line)) {
    const auto t = Tokens(line);
    if (t.size() < 4) Fail(f.Where(), "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    ColmapModel::Camera c;
    c.id = f.Parse<uint32_t>(t[0], "CAMERA_ID (integer)");
    c.model = std::string(t[1]);
    c.width = f.Parse<uint64_t>(t[2], "WIDTH (integer)");
    c.height = f.Parse<uint64_t>(t[3], "HEIGHT (integer)");
    for (std::size_t i = 4; i < t.size(); ++i) c.params.push_back(f.Parse<double>(t[i], "a parameter (number)"));
    const int n = ColmapModelParamCount(c.model);
    if (n >= 0 && static_cast<std::size_t>(n) != c.params.size())
      Fail(f.Where(), "camera " + std::to_string(c.id) + ": model " + c.model + " takes " +
                          std::to_string(n) + " parameters, got " + std::to_string(c.params.size()));
    m->cameras.push_back(std::move(c));
  }
}

void ReadImagesText(const fs::path& p, ColmapModel* m) {
  TextFile f(p);
  std::string line;
  while (f.Next(true, &line)) {
    const auto t = Tokens(line);
    if (t.size() < 10)
      Fail(f.Where(), "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got " +
                          std::to_string(t.size()) + " fields");
    ColmapModel::Image im;
    im.id = f.Parse<uint32_t>(t[0], "IMAGE_ID (integer)");
    for (int i = 0; i < 4; ++i) im.qvec[i] = f.Parse<double>(t[1 + i], "a quaternion entry (number)");
    for (int i = 0; i < 3; ++i) im.tvec[i] = f.Coordinate(t[5 + i], kTranslationNames[i]);
    im.camera_id = f.Parse<uint32_t>(t[8], "CAMERA_ID (integer)");
    im.name = std::string(t[9]);
    // The next line lists the 2D points, and may be empty.
    if (!f.Next(false, &line))
      Fail(f.Where(), "image " + std::to_string(im.id) + ": the file ends before its POINTS2D line");
    const auto q = Tokens(line);
    if (q.size() % 3 != 0)
      Fail(f.Where(), "image " + std::to_string(im.id) + ": POINTS2D must be triples X Y POINT3D_ID, got " +
                          std::to_string(q.size()) + " numbers");
    im.points2d.reserve(q.size() / 3);
    for (std::size_t i = 0; i < q.size(); i += 3)
      im.points2d.push_back({f.Parse<double>(q[i], "X (number)"), f.Parse<double>(q[i + 1], "Y (number)"),
                             f.Parse<int64_t>(q[i + 2], "POINT3D_ID (integer)")});
    m->images.push_back(std::move(im));
  }
}

void ReadPointsText(const fs::path& p, ColmapModel* m) {
  TextFile f(p);
  std::string line;
  while (f.Next(true, &line)) {
    const auto t = Tokens(line);
    if (t.size() < 8 || (t.size() - 8) % 2 != 0)
      Fail(f.Where(), "expected POINT3D_ID X Y Z R G B ERROR then (IMAGE_ID POINT2D_IDX) pairs");
    ColmapModel::Point3D pt;
    pt.id = f.Parse<uint64_t>(t[0], "POINT3D_ID (integer)");
    for (int i = 0; i < 3; ++i) pt.xyz[i] = f.Coordinate(t[1 + i], kCoordinateNames[i]);
    for (int i = 0; i < 3; ++i) {
      const unsigned c = f.Parse<unsigned>(t[4 + i], "a colour (integer 0-255)");
      if (c > 255) Fail(f.Where(), "a colour above 255");
      pt.rgb[i] = static_cast<uint8_t>(c);
    }
    pt.error = f.Parse<double>(t[7], "ERROR (number)");
    for (std::size_t i = 8; i < t.size(); i += 2)
      pt.track.push_back({f.Parse<uint32_t>(t[i], "IMAGE_ID (integer)"),
                          f.Parse<uint32_t>(t[i + 1], "POINT2D_IDX (integer)")});
    m->points.push_back(std::move(pt));
  }
}

// ---------------------------------------------------------------------------------------------
// Binary (little-endian, as COLMAP writes it on every platform it supports)

struct BinaryFile {
  explicit BinaryFile(const fs::path& p) : path(p), in(p, "a COLMAP binary model file") {}
  template <typename T>
  T Read(const std::string& what) {
    unsigned char b[sizeof(T)];
    in.read(reinterpret_cast<char*>(b), sizeof(T));
    if (in.gcount() != static_cast<std::streamsize>(sizeof(T)))
      Fail(path.string(), "truncated: the file ends at byte " + std::to_string(offset + in.gcount()) +
                              " while reading " + what);
    offset += sizeof(T);
    uint64_t bits = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) bits |= static_cast<uint64_t>(b[i]) << (8 * i);
    T v;
    if constexpr (sizeof(T) == 8) {
      std::memcpy(&v, &bits, 8);
    } else {
      using U = std::conditional_t<sizeof(T) == 4, uint32_t, std::conditional_t<sizeof(T) == 2, uint16_t, uint8_t>>;
      const U u = static_cast<U>(bits);
      std::memcpy(&v, &u, sizeof(T));
    }
    return v;
  }
  double Finite(const std::string& what) {
    const double v = Read<double>(what);
    if (!std::isfinite(v)) Fail(Where(), what + " is not finite");
    return v;
  }
  double Coordinate(const std::string& what) {
    const double v = Finite(what);
    if (const std::string p = CoordinateProblem(v); !p.empty()) Fail(Where(), what + ": " + p);
    return v;
  }
  // A count that must fit in what is left of the file (each item at least `min_bytes`).
  uint64_t Count(const std::string& what, uint64_t min_bytes) {
    const uint64_t n = Read<uint64_t>(what);
    if (size == 0) size = in.file().size();
    if (min_bytes > 0 && n > (size - offset) / min_bytes)
      Fail(Where(), what + " says " + std::to_string(n) + ", more than the rest of the file holds "
                    "(truncated or not a COLMAP binary file)");
    return n;
  }
  std::string Where() const { return path.string() + " byte " + std::to_string(offset); }
  fs::path path;
  InputStream in;
  uint64_t offset = 0;
  uint64_t size = 0;
};

void ReadCamerasBinary(const fs::path& p, ColmapModel* m) {
  BinaryFile f(p);
  const uint64_t n = f.Count("the number of cameras", 24);
  for (uint64_t i = 0; i < n; ++i) {
    const std::string what = "camera #" + std::to_string(i);
    ColmapModel::Camera c;
    c.id = static_cast<uint32_t>(f.Read<int32_t>(what + " id"));
    const int model_id = f.Read<int32_t>(what + " model id");
    c.model = ColmapModelName(model_id);
    if (c.model.empty()) Fail(f.Where(), "camera " + std::to_string(c.id) + ": unknown COLMAP model id " + std::to_string(model_id));
    c.width = f.Read<uint64_t>(what + " width");
    c.height = f.Read<uint64_t>(what + " height");
    const int np = ColmapModelParamCount(c.model);
    for (int k = 0; k < np; ++k) c.params.push_back(f.Finite("camera " + std::to_string(c.id) + " parameter " + std::to_string(k)));
    m->cameras.push_back(std::move(c));
  }
}

void ReadImagesBinary(const fs::path& p, ColmapModel* m) {
  BinaryFile f(p);
  const uint64_t n = f.Count("the number of images", 64);
  for (uint64_t i = 0; i < n; ++i) {
    ColmapModel::Image im;
    im.id = static_cast<uint32_t>(f.Read<int32_t>("image #" + std::to_string(i) + " id"));
    const std::string what = "image " + std::to_string(im.id);
    for (int k = 0; k < 4; ++k) im.qvec[k] = f.Finite(what + " qvec");
    for (int k = 0; k < 3; ++k) im.tvec[k] = f.Coordinate(what + " tvec");
    im.camera_id = static_cast<uint32_t>(f.Read<int32_t>(what + " camera id"));
    for (;;) {
      const char c = static_cast<char>(f.Read<uint8_t>(what + " name"));
      if (c == '\0') break;
      im.name.push_back(c);
    }
    const uint64_t np = f.Count(what + " number of 2D points", 24);
    im.points2d.resize(np);
    for (auto& q : im.points2d) {
      q.x = f.Finite(what + " 2D point x");
      q.y = f.Finite(what + " 2D point y");
      q.point3d_id = f.Read<int64_t>(what + " 2D point's 3D point id");
    }
    m->images.push_back(std::move(im));
  }
}

void ReadPointsBinary(const fs::path& p, ColmapModel* m) {
  BinaryFile f(p);
  const uint64_t n = f.Count("the number of 3D points", 51);
  for (uint64_t i = 0; i < n; ++i) {
    ColmapModel::Point3D pt;
    pt.id = f.Read<uint64_t>("3D point #" + std::to_string(i) + " id");
    const std::string what = "3D point " + std::to_string(pt.id);
    for (int k = 0; k < 3; ++k) pt.xyz[k] = f.Coordinate(what + " xyz");
    for (int k = 0; k < 3; ++k) pt.rgb[k] = f.Read<uint8_t>(what + " colour");
    pt.error = f.Read<double>(what + " error");
    const uint64_t tl = f.Count(what + " track length", 8);
    pt.track.resize(tl);
    for (auto& e : pt.track) {
      e.image_id = static_cast<uint32_t>(f.Read<int32_t>(what + " track image id"));
      e.point2d_idx = static_cast<uint32_t>(f.Read<int32_t>(what + " track 2D point index"));
    }
    m->points.push_back(std::move(pt));
  }
}

}  // namespace

ColmapModel ReadColmapText(const fs::path& dir) {
  ColmapModel m;
  ReadCamerasText(dir / "cameras.txt", &m);
  ReadImagesText(dir / "images.txt", &m);
  ReadPointsText(dir / "points3D.txt", &m);
  m.ext = ".txt";
  CheckColmapModel(m, dir.string(), m.ext);
  return m;
}

ColmapModel ReadColmapBinary(const fs::path& dir) {
  ColmapModel m;
  ReadCamerasBinary(dir / "cameras.bin", &m);
  ReadImagesBinary(dir / "images.bin", &m);
  ReadPointsBinary(dir / "points3D.bin", &m);
  m.ext = ".bin";
  CheckColmapModel(m, dir.string(), m.ext);
  return m;
}

std::string ColmapFolderHint(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return "";
  auto is_model = [&](const fs::path& d) {
    for (const char* ext : {".bin", ".txt"})
      if (fs::exists(d / (std::string("cameras") + ext), ec) &&
          fs::exists(d / (std::string("images") + ext), ec))
        return true;
    return false;
  };
  std::vector<std::string> models;
  size_t images = 0;
  std::string first_image;
  fs::directory_iterator it(dir, ec), end;
  // At most 100,000 entries looked at: a hint, not a scan of a huge folder.
  for (size_t seen = 0; !ec && it != end && seen < 100000; it.increment(ec), ++seen) {
    const fs::path& p = it->path();
    std::error_code e2;
    if (fs::is_directory(p, e2)) {
      if (is_model(p)) models.push_back(p.filename().string());
      continue;
    }
    std::string ext = p.extension().string();
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".tif" || ext == ".tiff" ||
        ext == ".bmp" || ext == ".webp" || ext == ".heic" || ext == ".cr2" || ext == ".dng") {
      if (images++ == 0) first_image = p.filename().string();
    }
  }
  std::sort(models.begin(), models.end());
  if (!models.empty()) {
    std::string list;
    for (size_t i = 0; i < models.size() && i < 10; ++i) list += (i ? ", " : "") + models[i];
    if (models.size() > 10) list += ", ...";
    return "it holds " + std::to_string(models.size()) + " COLMAP sub-model" +
           (models.size() == 1 ? "" : "s") + " (" + list + "), as a mapper's sparse/ does: mesh one, e.g. " +
           (dir / models[0]).string() + " (the largest is usually the one to mesh)";
  }
  if (images > 0)
    return "it holds " + std::to_string(images) + " image" + (images == 1 ? "" : "s") + " (" +
           first_image + ", ...), not a model: an SfM run must make one first (COLMAP's "
           "automatic_reconstructor or feature_extractor, exhaustive_matcher and mapper), then "
           "mesh its sparse/0";
  return "";
}

ColmapModel ReadColmapModel(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    Fail(dir.string(), "expected a COLMAP model folder (cameras, images, points3D as .bin or .txt)");
  auto all = [&](const char* ext) {
    for (const char* n : {"cameras", "images", "points3D"})
      if (!fs::exists(dir / (std::string(n) + ext), ec)) return false;
    return true;
  };
  if (all(".bin")) return ReadColmapBinary(dir);
  if (all(".txt")) return ReadColmapText(dir);
  std::string missing;
  for (const char* n : {"cameras", "images", "points3D"})
    if (!fs::exists(dir / (std::string(n) + ".txt"), ec) && !fs::exists(dir / (std::string(n) + ".bin"), ec))
      missing += std::string(missing.empty() ? "" : ", ") + n + ".{txt,bin}";
  const std::string hint = ColmapFolderHint(dir);
  Fail(dir.string(), "not a complete COLMAP model: " +
                         (missing.empty() ? std::string("mixed .txt and .bin files (need all three of one kind)")
                                          : "missing " + missing) +
                         (hint.empty() ? "" : "; " + hint));
}

void CheckColmapModel(const ColmapModel& m, const std::string& where, const std::string& ext) {
  std::unordered_map<uint32_t, const ColmapModel::Camera*> cams;
  for (const auto& c : m.cameras)
    if (!cams.emplace(c.id, &c).second) Fail(where + "/cameras" + ext, "camera " + std::to_string(c.id) + " is listed twice");
  std::unordered_map<uint32_t, const ColmapModel::Image*> images;
  for (const auto& im : m.images) {
    if (!images.emplace(im.id, &im).second) Fail(where + "/images" + ext, "image " + std::to_string(im.id) + " is listed twice");
    if (!cams.count(im.camera_id))
      Fail(where + "/images" + ext, "image " + std::to_string(im.id) + " uses camera " +
                                  std::to_string(im.camera_id) + ", which cameras does not list");
    const double n = std::sqrt(im.qvec[0] * im.qvec[0] + im.qvec[1] * im.qvec[1] +
                               im.qvec[2] * im.qvec[2] + im.qvec[3] * im.qvec[3]);
    if (std::abs(n - 1.0) > 1e-3)
      Fail(where + "/images" + ext, "image " + std::to_string(im.id) + ": the quaternion (qw qx qy qz) has length " +
                                  std::to_string(n) + ", not 1: not a rotation");
  }
  std::unordered_map<uint64_t, const ColmapModel::Point3D*> points;
  for (const auto& p : m.points)
    if (!points.emplace(p.id, &p).second) Fail(where + "/points3D" + ext, "3D point " + std::to_string(p.id) + " is listed twice");
  for (const auto& p : m.points) {
    for (const auto& e : p.track) {
      auto it = images.find(e.image_id);
      const std::string who = "3D point " + std::to_string(p.id) + "'s track";
      if (it == images.end())
        Fail(where + "/points3D" + ext, who + " refers to image " + std::to_string(e.image_id) + ", which images does not list");
      if (e.point2d_idx >= it->second->points2d.size())
        Fail(where + "/points3D" + ext, who + " refers to 2D point " + std::to_string(e.point2d_idx) + " of image " +
                                      std::to_string(e.image_id) + ", which has " +
                                      std::to_string(it->second->points2d.size()) + " 2D points");
      const int64_t back = it->second->points2d[e.point2d_idx].point3d_id;
      if (back != static_cast<int64_t>(p.id))
        Fail(where + "/points3D" + ext, who + " refers to 2D point " + std::to_string(e.point2d_idx) + " of image " +
                                      std::to_string(e.image_id) + ", which belongs to 3D point " + std::to_string(back));
    }
  }
  for (const auto& im : m.images)
    for (std::size_t i = 0; i < im.points2d.size(); ++i) {
      const int64_t id = im.points2d[i].point3d_id;
      if (id >= 0 && !points.count(static_cast<uint64_t>(id)))
        Fail(where + "/images" + ext, "image " + std::to_string(im.id) + " 2D point " + std::to_string(i) +
                                    " refers to 3D point " + std::to_string(id) + ", which points3D does not list");
    }
}

SfmModel ColmapToSfm(const ColmapModel& m, const std::string& where) {
  SfmModel s;
  s.file = where;
  s.points_file = where + "/points3D" + m.ext;
  s.views_file = where + "/images" + m.ext;
  s.no_points_hint = " (COLMAP writes none when the mapper registered images but triangulated "
                     "nothing; with known poses, run colmap point_triangulator first)";
  std::unordered_map<uint32_t, const ColmapModel::Camera*> cams;
  for (const auto& c : m.cameras) cams[c.id] = &c;
  std::unordered_map<uint32_t, const ColmapModel::Image*> images;
  for (const auto& im : m.images) {
    images[im.id] = &im;
    CameraGeometry g;
    g.id = im.id;
    g.name = im.name;
    SetFromTranslation(QuaternionToRotation(im.qvec), im.tvec, &g);
    const ColmapModel::Camera& c = *cams.at(im.camera_id);
    std::string error;
    if (!IntrinsicsFromColmap(c.model, c.params, static_cast<int>(c.width), static_cast<int>(c.height),
                              &g.intrinsics, &error))
      Fail(where + "/cameras", "camera " + std::to_string(c.id) + ": " + error);
    g.has_intrinsics = true;
    s.views.push_back(std::move(g));
  }
  std::sort(s.views.begin(), s.views.end(),
            [](const CameraGeometry& a, const CameraGeometry& b) { return a.id < b.id; });
  for (const auto& p : m.points) {
    SfmPoint sp;
    sp.id = p.id;
    sp.position = p.xyz;
    sp.has_rgb = true;
    sp.rgb = p.rgb;
    for (const auto& e : p.track) {
      const auto& q = images.at(e.image_id)->points2d[e.point2d_idx];
      sp.observations.push_back({e.image_id, q.x, q.y});
    }
    s.points.push_back(std::move(sp));
  }
  std::sort(s.points.begin(), s.points.end(), [](const SfmPoint& a, const SfmPoint& b) { return a.id < b.id; });
  return s;
}

namespace {

// Little-endian bytes, as COLMAP writes them on every platform.
class LittleEndian {
 public:
  template <typename T>
  LittleEndian& Put(T v) {
    using U = std::conditional_t<sizeof(T) == 8, uint64_t,
                                 std::conditional_t<sizeof(T) == 4, uint32_t, uint8_t>>;
    static_assert(sizeof(T) == sizeof(U));
    U u;
    std::memcpy(&u, &v, sizeof(T));
    const uint64_t bits = u;
    for (std::size_t i = 0; i < sizeof(T); ++i) s_.push_back(static_cast<char>((bits >> (8 * i)) & 0xFF));
    return *this;
  }
  std::string& str() { return s_; }

 private:
  std::string s_;
};

}  // namespace

void WriteColmapBinary(const ColmapModel& m, const fs::path& dir) {
  fs::create_directories(dir);
  LittleEndian c;
  c.Put<uint64_t>(m.cameras.size());
  for (const auto& cam : m.cameras) {
    const int id = ColmapModelId(cam.model);
    if (id < 0 || ColmapModelParamCount(cam.model) != static_cast<int>(cam.params.size()))
      Fail((dir / "cameras.bin").string(), "camera " + std::to_string(cam.id) + ": model " + cam.model +
                                               " with " + std::to_string(cam.params.size()) +
                                               " parameters has no COLMAP binary form");
    c.Put<uint32_t>(cam.id).Put<int32_t>(id).Put<uint64_t>(cam.width).Put<uint64_t>(cam.height);
    for (double p : cam.params) c.Put(p);
  }
  LittleEndian i;
  i.Put<uint64_t>(m.images.size());
  for (const auto& im : m.images) {
    i.Put<uint32_t>(im.id);
    for (double q : im.qvec) i.Put(q);
    for (double t : im.tvec) i.Put(t);
    i.Put<uint32_t>(im.camera_id);
    i.str() += im.name;
    i.str().push_back('\0');
    i.Put<uint64_t>(im.points2d.size());
    for (const auto& q : im.points2d) i.Put(q.x).Put(q.y).Put<int64_t>(q.point3d_id);
  }
  LittleEndian p;
  p.Put<uint64_t>(m.points.size());
  for (const auto& pt : m.points) {
    p.Put<uint64_t>(pt.id);
    for (double x : pt.xyz) p.Put(x);
    for (uint8_t x : pt.rgb) p.Put(x);
    p.Put(pt.error).Put<uint64_t>(pt.track.size());
    for (const auto& e : pt.track) p.Put<uint32_t>(e.image_id).Put<uint32_t>(e.point2d_idx);
  }
  WriteFileAtomically(dir / "cameras.bin", c.str());
  WriteFileAtomically(dir / "images.bin", i.str());
  WriteFileAtomically(dir / "points3D.bin", p.str());
}

std::string ColmapCamerasText(const std::vector<ColmapModel::Camera>& cameras) {
  std::string s = "# Camera list with one line of data per camera:\n"
                  "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                  "# Number of cameras: " + std::to_string(cameras.size()) + "\n";
  for (const auto& c : cameras) {
    s += std::to_string(c.id) + " " + c.model + " " + std::to_string(c.width) + " " + std::to_string(c.height);
    for (double p : c.params) s += " " + ExactNumber(p);
    s += "\n";
  }
  return s;
}

std::string ColmapImagesHeader(std::size_t images, std::size_t observations) {
  return "# Image list with two lines of data per image:\n"
         "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         "# Number of images: " + std::to_string(images) +
         ", mean observations per image: " +
         (images == 0 ? std::string("0") : ExactNumber(double(observations) / double(images))) + "\n";
}

void AppendColmapImageHead(const ColmapModel::Image& im, std::string* s) {
  *s += std::to_string(im.id);
  for (double q : im.qvec) *s += " " + ExactNumber(q);
  for (double t : im.tvec) *s += " " + ExactNumber(t);
  *s += " " + std::to_string(im.camera_id) + " " + im.name + "\n";
}

void AppendColmapPoint2D(const ColmapModel::Point2D& q, bool first, std::string* s) {
  *s += (first ? "" : " ") + ExactNumber(q.x) + " " + ExactNumber(q.y) + " " + std::to_string(q.point3d_id);
}

std::string ColmapPointsHeader(std::size_t points, std::size_t track_entries) {
  return "# 3D point list with one line of data per point:\n"
         "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         "# Number of points: " + std::to_string(points) + ", mean track length: " +
         (points == 0 ? std::string("0") : ExactNumber(double(track_entries) / double(points))) + "\n";
}

void AppendColmapPoint3D(const ColmapModel::Point3D& p, std::string* s) {
  *s += std::to_string(p.id);
  for (double x : p.xyz) *s += " " + ExactNumber(x);
  for (uint8_t c : p.rgb) *s += " " + std::to_string(c);
  *s += " " + ExactNumber(p.error);
  for (const auto& e : p.track) *s += " " + std::to_string(e.image_id) + " " + std::to_string(e.point2d_idx);
  *s += "\n";
}

void WriteColmapText(const ColmapModel& m, const fs::path& dir) {
  fs::create_directories(dir);
  WriteFileAtomically(dir / "cameras.txt", ColmapCamerasText(m.cameras));

  std::size_t obs = 0;
  for (const auto& im : m.images) obs += im.points2d.size();
  std::string s = ColmapImagesHeader(m.images.size(), obs);
  for (const auto& im : m.images) {
    AppendColmapImageHead(im, &s);
    for (std::size_t i = 0; i < im.points2d.size(); ++i) AppendColmapPoint2D(im.points2d[i], i == 0, &s);
    s += "\n";
  }
  WriteFileAtomically(dir / "images.txt", s);

  std::size_t track = 0;
  for (const auto& p : m.points) track += p.track.size();
  s = ColmapPointsHeader(m.points.size(), track);
  for (const auto& p : m.points) AppendColmapPoint3D(p, &s);
  WriteFileAtomically(dir / "points3D.txt", s);
}

}  // namespace imr::io
