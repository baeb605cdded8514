#include "tools/synth/sequence.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <ostream>
#include <sstream>
#include <thread>
#include <vector>

#include "host/synthetic/stream.h"
#include "host/synthetic/texture.h"
#include "host/util/atomic_file.h"
#include "host/util/write_rule.h"
#include "tools/synth/raycaster.h"
#include "tools/synth/renderer.h"

namespace imr::synth {
namespace fs = std::filesystem;
using synthetic::Scene;
using synthetic::Vec3;

namespace {

std::string Name(const char* fmt, int frame) {
  char buf[32];
  std::snprintf(buf, sizeof buf, fmt, frame);
  return buf;
}

std::string Bad(const char* option, const std::string& expected, double value) {
  std::ostringstream s;
  s << option << ": expected " << expected << ", got " << value;
  return s.str();
}

// zlib level 1 (fast): rendered images are noisy, higher levels shrink them by a few percent only
// and cost several times more time.
const std::vector<int> kPngParams = {cv::IMWRITE_PNG_COMPRESSION, 1};

}  // namespace

std::string SynthOptions::Check() const {
  if (out.empty()) return "--out: expected an output folder";
  if (frames < 1 || frames > 1000000) return Bad("--frames", "1 .. 1000000", frames);
  if (width < 16 || width > 16384) return Bad("--width", "16 .. 16384", width);
  if (height < 16 || height > 16384) return Bad("--height", "16 .. 16384", height);
  if (!(std::isfinite(speed) && speed > 0.0 && speed <= 100.0))
    return Bad("--speed", "metres per frame in (0, 100]", speed);
  if (!(std::isfinite(noise) && noise >= 0.0 && noise <= 255.0))
    return Bad("--noise", "grey levels in [0, 255]", noise);
  if (lidar && !(std::isfinite(lidar_step) && lidar_step >= 0.01 && lidar_step <= 10.0))
    return Bad("--lidar-step", "degrees in [0.01, 10]", lidar_step);
  if (threads < 0 || threads > 1024)
    return Bad("--threads", "0 .. 1024 (0: one per core)", threads);
  if (!(half_width > 2.0 && facade_height > 2.0)) return "street size: expected > 2 m";
  return {};
}

Scene StreetScene(const SynthOptions& o) {
  return Scene::StreetCanyon(synthetic::StreetLength(o.frames, o.speed), o.seed, o.half_width,
                             o.facade_height);
}

Mat44 StreetWorldFromScene(const SynthOptions& o) {
  return WorldFromScene(synthetic::StreetCameraCenter(0, o.speed));
}

std::string SceneMeshPly(const Scene& scene, const Mat44& m) {
  const std::vector<synthetic::Rect>& rects = scene.rects();
  std::string out =
      "ply\nformat ascii 1.0\n"
      "comment imr-synth ground truth: scene " +
      scene.name() +
      ", in the poses' world frame (camera 0 at frame 0)\n"
      "comment faces 2i and 2i+1 are scene rect i; material: 0 plain, 1 ground, 2 facade, "
      "3 box side, 4 box end, 5 box top\n"
      "element vertex " +
      std::to_string(4 * rects.size()) +
      "\nproperty double x\nproperty double y\nproperty double z\n"
      "element face " +
      std::to_string(2 * rects.size()) +
      "\nproperty list uchar int vertex_indices\nproperty uchar material\nend_header\n";
  char buf[128];
  for (const synthetic::Rect& r : rects) {
    // Counter-clockwise around the rect's normal u x v.
    const double su[4] = {-1, 1, 1, -1}, sv[4] = {-1, -1, 1, 1};
    for (int k = 0; k < 4; ++k) {
      const Vec3 p =
          synthetic::Add(r.center, synthetic::Add(synthetic::Scale(r.u, su[k] * r.half_u),
                                                  synthetic::Scale(r.v, sv[k] * r.half_v)));
      double w[3];
      for (int i = 0; i < 3; ++i)
        w[i] = m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3] + 0.0;
      std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g\n", w[0], w[1], w[2]);
      out += buf;
    }
  }
  for (size_t i = 0; i < rects.size(); ++i) {
    const size_t v = 4 * i;
    const int mat = static_cast<int>(rects[i].material);
    std::snprintf(buf, sizeof buf, "3 %zu %zu %zu %d\n3 %zu %zu %zu %d\n", v, v + 1, v + 2, mat, v,
                  v + 2, v + 3, mat);
    out += buf;
  }
  return out;
}

std::string SceneJson(const SynthOptions& o) {
  const Mat44 m = StreetWorldFromScene(o);
  nlohmann::ordered_json j;
  j["scene"] = "street";
  j["length"] = synthetic::StreetLength(o.frames, o.speed);
  j["seed"] = o.seed;
  j["half_width"] = o.half_width;
  j["facade_height"] = o.facade_height;
  j["speed"] = o.speed;
  j["frames"] = o.frames;
  j["world_from_scene"] = nlohmann::ordered_json::array();
  for (const auto& row : m) j["world_from_scene"].push_back(row);
  j["generator"] = "imr-synth";
  j["description"] =
      "Scene::StreetCanyon(length, seed, half_width, facade_height) of host/synthetic; camera 0 "
      "of frame f at StreetCameraCenter(f, speed) = (0.6 sin(0.01 f), f speed, 1.65) in scene "
      "coordinates (z up), looking along +y; world_from_scene maps scene coordinates into the "
      "frame of poses.txt (camera 0 at frame 0, x right, y down, z forward).";
  j["image_size"] = {o.width, o.height};
  j["camera"] = o.color ? 2 : 0;
  return j.dump(2) + "\n";
}

SynthResult GenerateSequence(const SynthOptions& o, std::ostream& log,
                             const std::atomic<bool>* cancel) {
  const auto start = std::chrono::steady_clock::now();
  if (const std::string e = o.Check(); !e.empty()) throw std::invalid_argument(e);

  fs::path out = fs::path(o.out).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();
  if (out.empty() || out == "." || out == "..")
    throw std::invalid_argument("--out: expected a folder name, got '" + o.out + "'");
  std::error_code ec;
  if (fs::exists(fs::symlink_status(out, ec)) && !o.force)
    throw OutputExistsError(out.string() + ": already exists; pass --force to replace it");
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  EnsureWritableDirectory(parent);
  const std::string pid = std::to_string(::getpid());
  const fs::path partial = parent / (out.filename().string() + ".partial-" + pid);
  // Until the final rename, any failure (or cancellation) removes the partial folder.
  struct RemoveOnError {
    fs::path dir;
    bool armed = true;
    ~RemoveOnError() {
      std::error_code e;
      if (armed) fs::remove_all(dir, e);
    }
  } guard{partial};
  // imr's own folder until the rename puts it in place whole: no ledger of what is written in it
  // (host/util/write_rule.h), so the sequence holds exactly its files.
  InputScope private_folder;
  private_folder.Private(partial);
  fs::remove_all(partial, ec);  // A leftover of an earlier process with our pid.
  const char* image_dir = o.color ? "image_2" : "image_0";
  std::vector<fs::path> dirs = {partial / image_dir, partial / "ground_truth"};
  if (o.lidar) dirs.push_back(partial / "velodyne");
  for (const fs::path& d : dirs)
    if (!fs::create_directories(d, ec) && ec)
      throw std::runtime_error(d.string() + ": cannot create folder: " + ec.message());

  // The scene, its appearance, the rig.
  const Scene scene = StreetScene(o);
  const synthetic::SceneTexture texture(scene, o.seed);
  const RayCaster caster(scene);
  const Rig rig = Rig::Kitti(o.width, o.height);
  const int camera = o.color ? 2 : 0;
  RenderOptions ro;
  ro.color = o.color;
  ro.noise = o.noise;
  ro.seed = o.seed;
  ro.id_colors = o.id_colors;
  const Renderer renderer(scene, texture, caster, rig.camera, ro);
  LidarOptions lo;
  lo.horizontal_step_deg = o.lidar_step;

  // Text files and ground truth.
  const Vec3 c0 = synthetic::StreetCameraCenter(0, o.speed);
  std::string poses, times;
  for (int f = 0; f < o.frames; ++f) {
    poses += PoseLine(CameraPose(synthetic::StreetCameraCenter(f, o.speed), c0));
    times += TimeLine(0.1 * f);
  }
  WriteFileAtomically(partial / "calib.txt", CalibText(rig));
  WriteFileAtomically(partial / "times.txt", times);
  WriteFileAtomically(partial / "poses.txt", poses);
  WriteFileAtomically(partial / "ground_truth" / "scene.ply",
                      SceneMeshPly(scene, StreetWorldFromScene(o)));
  WriteFileAtomically(partial / "ground_truth" / "scene.json", SceneJson(o));

  // Frames, in parallel: each worker takes the next frame number; every output depends only on
  // its frame number, so the files do not depend on the schedule.
  const int threads = std::min(
      o.frames, o.threads > 0 ? o.threads
                              : std::max(1, static_cast<int>(std::thread::hardware_concurrency())));
  std::atomic<int> next{0}, done{0};
  std::atomic<bool> failed{false};
  std::atomic<uint64_t> lidar_points{0};
  std::exception_ptr error;
  std::mutex mutex;
  const int report_every = std::max(1, o.frames / 10);
  const Vec3 camera_offset = SceneFromCamera(rig.CameraOffset(camera));
  auto stopped = [&] { return failed.load() || (cancel && cancel->load()); };
  auto work = [&] {
    try {
      std::vector<uchar> png;
      for (int f = next++; f < o.frames && !stopped(); f = next++) {
        const Vec3 c = synthetic::StreetCameraCenter(f, o.speed);
        const cv::Mat image = renderer.Render(synthetic::Add(c, camera_offset), f);
        if (!cv::imencode(".png", image, png, kPngParams))
          throw std::runtime_error("frame " + std::to_string(f) + ": PNG encoding failed");
        WriteFileAtomically(
            partial / image_dir / Name("%06d.png", f),
            std::string_view(reinterpret_cast<const char*>(png.data()), png.size()));
        if (o.lidar) {
          const std::vector<float> scan = ScanVelodyne(caster, texture, rig, c, lo);
          WriteFileAtomically(partial / "velodyne" / Name("%06d.bin", f),
                              std::string_view(reinterpret_cast<const char*>(scan.data()),
                                               scan.size() * sizeof(float)));
          lidar_points += scan.size() / 4;
        }
        const int n = ++done;
        if (o.progress && (n % report_every == 0 || n == o.frames)) {
          std::lock_guard<std::mutex> lock(mutex);
          log << "[" << n << "/" << o.frames << "] frames" << std::endl;
        }
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  if (cancel && cancel->load()) throw CancelledError("cancelled; removed " + partial.string());

  // Publish the folder: one rename (an old folder is moved aside first, then deleted).
  if (fs::exists(fs::symlink_status(out, ec))) {
    if (!o.force) {
      guard.armed = false;
      throw OutputExistsError(out.string() + ": appeared during the run; output left in " +
                              partial.string());
    }
    const fs::path old = parent / (out.filename().string() + ".old-" + pid);
    fs::remove_all(old, ec);
    fs::rename(out, old, ec);
    if (ec) throw std::runtime_error(out.string() + ": cannot move aside: " + ec.message());
    fs::rename(partial, out, ec);
    if (ec)
      throw std::runtime_error(out.string() + ": cannot rename " + partial.string() +
                               " to it: " + ec.message());
    fs::remove_all(old, ec);
  } else {
    fs::rename(partial, out, ec);
    if (ec)
      throw std::runtime_error(out.string() + ": cannot rename " + partial.string() +
                               " to it: " + ec.message());
  }
  guard.armed = false;

  SynthResult r;
  r.out = out.string();
  r.frames = o.frames;
  r.width = o.width;
  r.height = o.height;
  r.lidar_points = lidar_points.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

}  // namespace imr::synth
