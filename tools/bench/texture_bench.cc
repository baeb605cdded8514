// imr-bench texture: what colouring and texturing a mesh from its keyframe images costs (issue 17).
// The exporter plugin (org.imr.exporter.assimp, the real .so) is driven in this process as `imr
// run` drives it — the host's keyframe-image service (KeyframeImageStore) decodes the images —
// on a reconstructed mesh and its colour image sequence: once plain (no colour, no texture), once
// with vertex colours only, once with the texture atlas. Figures: texturing time (textured minus
// plain export) per keyframe and per megapixel of atlas, the atlas (pages, pixels, bytes), the
// images decoded, and the resident memory the textured export adds (peak RSS during the export
// minus RSS before it, each export in a forked child; the peak is reset through
// /proc/self/clear_refs). Input: --sequence DIR (a
// KITTI odometry folder with colour images) and --mesh FILE (its mesh, PLY/OBJ/glTF), or neither:
// imr-synth renders a colour street and `imr run` reconstructs it first. Prints a table, then one
// JSON object as the last line.
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/eval/mesh_io.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/pipeline/front_end.h"
#include "host/plugin/host_services.h"
#include "host/plugin/keyframe_images.h"
#include "host/plugin/registry.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/subprocess.h"
#include "host/util/clock.h"

namespace imr::bench {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

struct TextureArgs {
  std::string sequence;   // KITTI odometry folder (colour images)
  std::string mesh;       // its mesh; both empty: made here
  int frames = 200;       // synthetic frames when the input is made here
  int keyframe_every = 5; // as the front end picks keyframes (job input option)
  int repeat = 3;         // timed exports per setting (median reported)
  int atlas_size = 4096;
  double seam_penalty = 1.0;  // the exporter's default
  std::string work;
  bool keep = false;
};

long StatusKb(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::size_t n = std::strlen(key);
  while (std::getline(in, line))
    if (line.compare(0, n, key) == 0) return std::atol(line.c_str() + n + 1);
  return 0;
}

// Resets the peak RSS (VmHWM) to the current RSS; false when the kernel refuses.
bool ResetPeakRss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  out.close();
  return static_cast<bool>(out);
}

struct Export {
  double seconds = 0.0;
  long rss_before_kb = 0, peak_kb = 0;
  plugin::KeyframeImageStoreStats images;
  int pages = 0;
  int64_t atlas_pixels = 0;
  uint64_t atlas_bytes = 0;
  uint64_t file_bytes = 0;
};

int Main(const TextureArgs& a) {
  const fs::path work = a.work.empty() ? fs::temp_directory_path() / ("imr-bench-texture-" + std::to_string(::getpid()))
                                       : fs::path(a.work);
  fs::create_directories(work);
  std::string sequence = a.sequence, mesh_file = a.mesh;
  if (sequence.empty() != mesh_file.empty()) {
    std::fprintf(stderr, "imr-bench texture: give both --sequence and --mesh, or neither\n");
    return 2;
  }
  if (sequence.empty()) {
    sequence = (work / "street").string();
    if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(sequence) + " --frames " +
           std::to_string(a.frames) + " --color --no-lidar --force -q") != 0)
      return 1;
    json job = ReadJson(fs::path(IMR_SOURCE_DIR) / "configs" / "default.json");
    job["sequences"] = {sequence};
    job["input"]["options"]["keyframe_every"] = a.keyframe_every;
    job["output"] = {{"directory", (work / "run").string()}, {"formats", {"ply"}}};
    job["pipeline"].back()["params"] = {{"texture", false}, {"vertex_colors", false}};
    std::ofstream(work / "job.json") << job.dump(2);
    if (Sh(Quote((ExeDir() / "imr").string()) + " run -q " + Quote((work / "job.json").string())) != 0)
      return 1;
    mesh_file = (work / "run" / "mesh.ply").string();
  }

  // The mesh, the keyframes (as the front end picks them: every n-th frame and the last), images.
  const eval::TriangleMesh m = eval::ReadMesh(mesh_file);
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  for (const auto& v : m.vertices) vertices.insert(vertices.end(), v.begin(), v.end());
  for (const auto& t : m.triangles) faces.insert(faces.end(), t.begin(), t.end());
  io::ImageSequenceOptions so;
  const io::ImageSequence seq = io::ReadKittiOdometry(sequence, so);
  std::vector<imr_camera> keyframes;
  std::vector<std::string> paths;
  const int frame_count = static_cast<int>(seq.frames.size());
  for (int f = 0; f < frame_count; ++f) {
    if (f % a.keyframe_every != 0 && f + 1 != frame_count) continue;
    const io::CameraGeometry& g = seq.frames[f].camera;
    keyframes.push_back(pipeline::ToPluginCamera(g, g.intrinsics.width, g.intrinsics.height));
    paths.push_back(seq.frames[f].image_path);
  }
  const int width = seq.frames.empty() ? 0 : seq.frames[0].camera.intrinsics.width;
  const int height = seq.frames.empty() ? 0 : seq.frames[0].camera.intrinsics.height;

  plugin::PluginRegistry registry;
  registry.Scan(plugin::PluginRegistry::DefaultSearchPaths());
  const plugin::PluginInfo* info = registry.Find("org.imr.exporter.assimp");
  if (info == nullptr) {
    std::fprintf(stderr, "imr-bench texture: org.imr.exporter.assimp not found\n");
    return 1;
  }

  imr_mesh_view view{};
  view.struct_size = sizeof(view);
  view.vertices = vertices.data();
  view.vertex_count = vertices.size() / 3;
  view.faces = faces.data();
  view.face_count = faces.size() / 3;
  const bool peak_resettable = ResetPeakRss();

  // One export as the host does it: a fresh image store (nothing decoded before), a fresh
  // instance (no cache from an earlier export), a fresh staging folder.
  auto measure = [&](const json& params, const std::string& tag, int round) {
    Export e;
    const fs::path dir = work / ("out-" + tag + "-" + std::to_string(round));
    fs::remove_all(dir);
    fs::create_directories(dir);
    plugin::LoadedInstance instance = plugin::CreateInstance(*info, params);
    plugin::KeyframeImageStore store(paths);
    const std::string d = dir.string(), stem = "mesh", format = "gltf";
    imr_export_request req{};
    req.mesh = &view;
    req.directory = d.c_str();
    req.stem = stem.c_str();
    req.format = format.c_str();
    req.keyframes = keyframes.data();
    req.keyframe_count = keyframes.size();
    req.keyframe_images = 1;
    ResetPeakRss();
    e.rss_before_kb = StatusKb("VmRSS:");
    const auto start = std::chrono::steady_clock::now();
    {
      const plugin::ScopedKeyframeImages scope(&store);
      instance.instance.ExportMesh(&req);
    }
    e.seconds = SecondsSince(start);
    e.peak_kb = StatusKb("VmHWM:");
    e.images = store.stats();
    for (const auto& f : fs::directory_iterator(dir)) {
      e.file_bytes += fs::file_size(f.path());
      if (f.path().filename().string().find("_atlas") == std::string::npos) continue;
      const io::ImageSize size = io::ReadImageSize(f.path().string());
      ++e.pages;
      e.atlas_pixels += int64_t{size.width} * size.height;
      e.atlas_bytes += fs::file_size(f.path());
    }
    if (!a.keep) fs::remove_all(dir);
    return e;
  };
  // Each export in a child process (fork): its peak RSS is its own, not memory an earlier export
  // freed and the allocator kept.
  auto run = [&](const json& params, const std::string& tag, int round) {
    int fds[2];
    if (::pipe(fds) != 0) throw std::runtime_error("pipe failed");
    const pid_t pid = ::fork();
    if (pid < 0) throw std::runtime_error("fork failed");
    if (pid == 0) {
      ::close(fds[0]);
      std::string out;
      try {
        const Export e = measure(params, tag, round);
        out = json{{"seconds", e.seconds}, {"rss_before_kb", e.rss_before_kb}, {"peak_kb", e.peak_kb},
                   {"pages", e.pages}, {"atlas_pixels", e.atlas_pixels}, {"atlas_bytes", e.atlas_bytes},
                   {"file_bytes", e.file_bytes}, {"decodes", e.images.decodes},
                   {"requests", e.images.requests}, {"peak_cached", e.images.peak_bytes},
                   {"decode_seconds", e.images.decode_seconds}}
                  .dump();
      } catch (const std::exception& ex) {
        out = json{{"error", ex.what()}}.dump();
      }
      const ssize_t n = ::write(fds[1], out.data(), out.size());
      ::_exit(n == static_cast<ssize_t>(out.size()) ? 0 : 1);
    }
    ::close(fds[1]);
    std::string text;
    char buf[4096];
    for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) text.append(buf, static_cast<std::size_t>(n));
    ::close(fds[0]);
    int status = 0;
    ::waitpid(pid, &status, 0);
    const json j = json::parse(text.empty() ? "{}" : text, nullptr, false);
    if (!j.is_object() || j.contains("error") || !j.contains("seconds"))
      throw std::runtime_error(tag + " export failed: " + (j.is_object() && j.contains("error") ? j["error"].get<std::string>() : text));
    Export e;
    e.seconds = j["seconds"];
    e.rss_before_kb = j["rss_before_kb"];
    e.peak_kb = j["peak_kb"];
    e.pages = j["pages"];
    e.atlas_pixels = j["atlas_pixels"];
    e.atlas_bytes = j["atlas_bytes"];
    e.file_bytes = j["file_bytes"];
    e.images.decodes = j["decodes"];
    e.images.requests = j["requests"];
    e.images.peak_bytes = j["peak_cached"];
    e.images.decode_seconds = j["decode_seconds"];
    return e;
  };
  struct Setting {
    std::string tag;
    json params;
    std::vector<Export> runs;
  };
  std::vector<Setting> settings = {
      {"plain", {{"texture", false}, {"vertex_colors", false}}, {}},
      {"colors", {{"texture", false}, {"vertex_colors", true}}, {}},
      {"texture", {{"texture", true}, {"vertex_colors", true}, {"atlas_size", a.atlas_size},
                   {"seam_penalty", a.seam_penalty}}, {}}};
  for (int r = 0; r < a.repeat; ++r)
    for (Setting& s : settings) s.runs.push_back(run(s.params, s.tag, r));
  auto median = [](const Setting& s, auto field) {
    std::vector<double> v;
    for (const Export& e : s.runs) v.push_back(static_cast<double>(field(e)));
    return Median(v);
  };
  auto secs = [](const Export& e) { return e.seconds; };
  auto added = [](const Export& e) { return static_cast<double>(e.peak_kb - e.rss_before_kb) / 1024.0; };
  const double plain = median(settings[0], secs), colors = median(settings[1], secs),
               textured = median(settings[2], secs);
  const Export& t = settings[2].runs.back();
  const double kf = static_cast<double>(keyframes.size());
  const double mpx = static_cast<double>(t.atlas_pixels) / 1e6;
  const double texturing = textured - plain;

  std::printf("%s\n", MachineLine().c_str());
  std::printf("mesh %s: %zu vertices, %zu triangles; %zu keyframes of %dx%d (every %d of %d frames)\n",
              mesh_file.c_str(), view.vertex_count, view.face_count, keyframes.size(), width, height,
              a.keyframe_every, frame_count);
  std::printf("%-9s %9s %12s %10s\n", "export", "seconds", "added MiB", "files MiB");
  for (const Setting& s : settings)
    std::printf("%-9s %9.3f %12.1f %10.2f\n", s.tag.c_str(), median(s, secs), median(s, added),
                median(s, [](const Export& e) { return static_cast<double>(e.file_bytes); }) / 1048576.0);
  std::printf("atlas: %d page(s), %.2f Mpx, %.2f MiB (JPEG); images: %lld decoded in %.3f s, %lld "
              "requests, %.1f MiB cached at most\n",
              t.pages, mpx, static_cast<double>(t.atlas_bytes) / 1048576.0,
              static_cast<long long>(t.images.decodes), t.images.decode_seconds,
              static_cast<long long>(t.images.requests), static_cast<double>(t.images.peak_bytes) / 1048576.0);
  std::printf("texturing (textured - plain export): %.3f s = %.1f ms per keyframe, %.1f ms per atlas Mpx\n",
              texturing, 1e3 * texturing / kf, mpx > 0 ? 1e3 * texturing / mpx : 0.0);
  std::printf("vertex colours only (colors - plain): %.3f s = %.1f ms per keyframe\n", colors - plain,
              1e3 * (colors - plain) / kf);
  if (!peak_resettable) std::printf("note: /proc/self/clear_refs refused: added RSS is an upper bound\n");

  json out = {{"bench", "texture"},
              {"mesh", {{"file", mesh_file}, {"vertices", view.vertex_count}, {"triangles", view.face_count}}},
              {"keyframes", keyframes.size()},
              {"image_size", {width, height}},
              {"seconds", {{"plain", plain}, {"colors", colors}, {"textured", textured}}},
              {"texturing_seconds", texturing},
              {"ms_per_keyframe", 1e3 * texturing / kf},
              {"ms_per_atlas_mpx", mpx > 0 ? 1e3 * texturing / mpx : 0.0},
              {"atlas", {{"pages", t.pages}, {"pixels", t.atlas_pixels}, {"bytes", t.atlas_bytes},
                         {"size", a.atlas_size}}},
              {"added_rss_mib", {{"plain", median(settings[0], added)},
                                 {"colors", median(settings[1], added)},
                                 {"textured", median(settings[2], added)}}},
              {"images", {{"decodes", t.images.decodes}, {"requests", t.images.requests},
                          {"decode_seconds", t.images.decode_seconds},
                          {"peak_cached_bytes", t.images.peak_bytes}}},
              {"repeat", a.repeat},
              {"load_average", LoadAverage()}};
  std::printf("%s\n", out.dump().c_str());
  if (!a.keep && a.work.empty()) fs::remove_all(work);
  return 0;
}

}  // namespace

int RunTextureBench(int argc, char** argv) {
  TextureArgs a;
  for (int i = 0; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "imr-bench texture: %s needs a value\n", k.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (k == "--sequence") a.sequence = next();
    else if (k == "--mesh") a.mesh = next();
    else if (k == "--frames") a.frames = std::stoi(next());
    else if (k == "--keyframe-every") a.keyframe_every = std::stoi(next());
    else if (k == "--repeat") a.repeat = std::stoi(next());
    else if (k == "--atlas-size") a.atlas_size = std::stoi(next());
    else if (k == "--seam-penalty") a.seam_penalty = std::stod(next());
    else if (k == "--work") a.work = next();
    else if (k == "--keep") a.keep = true;
    else {
      std::fprintf(stderr,
                   "usage: imr-bench texture [--sequence DIR --mesh FILE] [--frames N] "
                   "[--keyframe-every N] [--repeat N] [--atlas-size PX] [--seam-penalty X] [--work DIR] "
                   "[--keep]\n");
      return 2;
    }
  }
  if (a.frames < 2 || a.keyframe_every < 1 || a.repeat < 1) {
    std::fprintf(stderr, "imr-bench texture: --frames >= 2, --keyframe-every >= 1, --repeat >= 1\n");
    return 2;
  }
  try {
    return Main(a);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "imr-bench texture: %s\n", e.what());
    return 1;
  }
}

}  // namespace imr::bench
