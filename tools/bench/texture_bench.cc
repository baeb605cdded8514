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
#include <functional>
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
#include "tools/bench/common/frame.h"
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

// The mesh as the exporter sees it and the keyframes with their images (as the front end picks
// them: every n-th frame and the last).
struct Input {
  std::string mesh_file;
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  std::vector<imr_camera> keyframes;
  std::vector<std::string> paths;
  int frame_count = 0, width = 0, height = 0;
  imr_mesh_view view{};
};

// No input given: imr-synth renders a colour street and `imr run` reconstructs it (no colour, no
// texture). False when either failed.
bool MakeInput(const TextureArgs& a, const fs::path& work, std::string* sequence,
               std::string* mesh_file) {
  *sequence = (work / "street").string();
  if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(*sequence) + " --frames " +
         std::to_string(a.frames) + " --color --no-lidar --force -q") != 0)
    return false;
  json job = ReadJson(fs::path(IMR_SOURCE_DIR) / "configs" / "default.json");
  job["sequences"] = {*sequence};
  job["input"]["options"]["keyframe_every"] = a.keyframe_every;
  job["output"] = {{"directory", (work / "run").string()}, {"formats", {"ply"}}};
  job["pipeline"].back()["params"] = {{"texture", false}, {"vertex_colors", false}};
  WriteJson(work / "job.json", job);
  if (Sh(Quote((ExeDir() / "imr").string()) + " run -q " + Quote((work / "job.json").string())) != 0)
    return false;
  *mesh_file = (work / "run" / "mesh.ply").string();
  return true;
}

void LoadInput(const std::string& mesh_file, const std::string& sequence, int keyframe_every,
               Input* in) {
  in->mesh_file = mesh_file;
  const eval::TriangleMesh m = eval::ReadMesh(mesh_file);
  for (const auto& v : m.vertices) in->vertices.insert(in->vertices.end(), v.begin(), v.end());
  for (const auto& t : m.triangles) in->faces.insert(in->faces.end(), t.begin(), t.end());
  io::ImageSequenceOptions so;
  const io::ImageSequence seq = io::ReadKittiOdometry(sequence, so);
  in->frame_count = static_cast<int>(seq.frames.size());
  for (int f = 0; f < in->frame_count; ++f) {
    if (f % keyframe_every != 0 && f + 1 != in->frame_count) continue;
    const io::CameraGeometry& g = seq.frames[f].camera;
    in->keyframes.push_back(pipeline::ToPluginCamera(g, g.intrinsics.width, g.intrinsics.height));
    in->paths.push_back(seq.frames[f].image_path);
  }
  in->width = seq.frames.empty() ? 0 : seq.frames[0].camera.intrinsics.width;
  in->height = seq.frames.empty() ? 0 : seq.frames[0].camera.intrinsics.height;
  in->view.struct_size = sizeof(in->view);
  in->view.vertices = in->vertices.data();
  in->view.vertex_count = in->vertices.size() / 3;
  in->view.faces = in->faces.data();
  in->view.face_count = in->faces.size() / 3;
}

// One export as the host does it: a fresh image store (nothing decoded before), a fresh instance
// (no cache from an earlier export), a fresh staging folder.
Export Measure(const plugin::PluginInfo& info, const Input& in, const json& params,
               const fs::path& dir, bool keep) {
  Export e;
  fs::remove_all(dir);
  fs::create_directories(dir);
  plugin::LoadedInstance instance = plugin::CreateInstance(info, params);
  plugin::KeyframeImageStore store(in.paths);
  const std::string d = dir.string(), stem = "mesh", format = "gltf";
  imr_export_request req{};
  req.mesh = &in.view;
  req.directory = d.c_str();
  req.stem = stem.c_str();
  req.format = format.c_str();
  req.keyframes = in.keyframes.data();
  req.keyframe_count = in.keyframes.size();
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
  if (!keep) fs::remove_all(dir);
  return e;
}

json ToJson(const Export& e) {
  return {{"seconds", e.seconds}, {"rss_before_kb", e.rss_before_kb}, {"peak_kb", e.peak_kb},
          {"pages", e.pages}, {"atlas_pixels", e.atlas_pixels}, {"atlas_bytes", e.atlas_bytes},
          {"file_bytes", e.file_bytes}, {"decodes", e.images.decodes},
          {"requests", e.images.requests}, {"peak_cached", e.images.peak_bytes},
          {"decode_seconds", e.images.decode_seconds}};
}

Export FromJson(const json& j) {
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
}

// Each export in a child process (fork): its peak RSS is its own, not memory an earlier export
// freed and the allocator kept. The child hands its figures back as JSON through a pipe.
Export MeasureInChild(const plugin::PluginInfo& info, const Input& in, const json& params,
                      const std::string& tag, const fs::path& dir, bool keep) {
  int fds[2];
  if (::pipe(fds) != 0) throw std::runtime_error("pipe failed");
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::close(fds[0]);
    std::string out;
    try {
      out = ToJson(Measure(info, in, params, dir, keep)).dump();
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
  return FromJson(j);
}

struct Setting {
  std::string tag;
  json params;
  std::vector<Export> runs;
};

double MedianOf(const Setting& s, const std::function<double(const Export&)>& field) {
  std::vector<double> v;
  for (const Export& e : s.runs) v.push_back(field(e));
  return Median(v);
}
double Secs(const Export& e) { return e.seconds; }
double AddedMib(const Export& e) { return static_cast<double>(e.peak_kb - e.rss_before_kb) / 1024.0; }

// The table and the figures; the JSON line's object.
json Report(const TextureArgs& a, const Input& in, const std::vector<Setting>& settings,
            bool peak_resettable) {
  const double plain = MedianOf(settings[0], Secs), colors = MedianOf(settings[1], Secs),
               textured = MedianOf(settings[2], Secs);
  const Export& t = settings[2].runs.back();
  const double kf = static_cast<double>(in.keyframes.size());
  const double mpx = static_cast<double>(t.atlas_pixels) / 1e6;
  const double texturing = textured - plain;
  std::printf("%s\n", MachineLine().c_str());
  std::printf("mesh %s: %zu vertices, %zu triangles; %zu keyframes of %dx%d (every %d of %d frames)\n",
              in.mesh_file.c_str(), in.view.vertex_count, in.view.face_count, in.keyframes.size(),
              in.width, in.height, a.keyframe_every, in.frame_count);
  std::printf("%-9s %9s %12s %10s\n", "export", "seconds", "added MiB", "files MiB");
  for (const Setting& s : settings)
    std::printf("%-9s %9.3f %12.1f %10.2f\n", s.tag.c_str(), MedianOf(s, Secs), MedianOf(s, AddedMib),
                MedianOf(s, [](const Export& e) { return static_cast<double>(e.file_bytes); }) / 1048576.0);
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
  return {{"bench", "texture"},
          {"mesh", {{"file", in.mesh_file}, {"vertices", in.view.vertex_count}, {"triangles", in.view.face_count}}},
          {"keyframes", in.keyframes.size()},
          {"image_size", {in.width, in.height}},
          {"seconds", {{"plain", plain}, {"colors", colors}, {"textured", textured}}},
          {"texturing_seconds", texturing},
          {"ms_per_keyframe", 1e3 * texturing / kf},
          {"ms_per_atlas_mpx", mpx > 0 ? 1e3 * texturing / mpx : 0.0},
          {"atlas", {{"pages", t.pages}, {"pixels", t.atlas_pixels}, {"bytes", t.atlas_bytes},
                     {"size", a.atlas_size}}},
          {"added_rss_mib", {{"plain", MedianOf(settings[0], AddedMib)},
                             {"colors", MedianOf(settings[1], AddedMib)},
                             {"textured", MedianOf(settings[2], AddedMib)}}},
          {"images", {{"decodes", t.images.decodes}, {"requests", t.images.requests},
                      {"decode_seconds", t.images.decode_seconds},
                      {"peak_cached_bytes", t.images.peak_bytes}}},
          {"repeat", a.repeat},
          {"load_average", LoadAverage()}};
}

int Main(const TextureArgs& a) {
  const WorkFolder work(a.work, "texture");
  std::string sequence = a.sequence, mesh_file = a.mesh;
  if (sequence.empty() != mesh_file.empty()) {
    std::fprintf(stderr, "imr-bench texture: give both --sequence and --mesh, or neither\n");
    return 2;
  }
  if (sequence.empty() && !MakeInput(a, work.path(), &sequence, &mesh_file)) return 1;
  Input in;
  LoadInput(mesh_file, sequence, a.keyframe_every, &in);
  plugin::PluginRegistry registry;
  registry.Scan(plugin::PluginRegistry::DefaultSearchPaths());
  const plugin::PluginInfo* info = registry.Find("org.imr.exporter.assimp");
  if (info == nullptr) {
    std::fprintf(stderr, "imr-bench texture: org.imr.exporter.assimp not found\n");
    return 1;
  }
  const bool peak_resettable = ResetPeakRss();
  std::vector<Setting> settings = {
      {"plain", {{"texture", false}, {"vertex_colors", false}}, {}},
      {"colors", {{"texture", false}, {"vertex_colors", true}}, {}},
      {"texture", {{"texture", true}, {"vertex_colors", true}, {"atlas_size", a.atlas_size},
                   {"seam_penalty", a.seam_penalty}}, {}}};
  for (int r = 0; r < a.repeat; ++r)
    for (Setting& s : settings)
      s.runs.push_back(MeasureInChild(*info, in, s.params, s.tag,
                                      work.path() / ("out-" + s.tag + "-" + std::to_string(r)), a.keep));
  std::printf("%s\n", Report(a, in, settings, peak_resettable).dump().c_str());
  work.Finish(!a.keep);
  return 0;
}

}  // namespace

int RunTextureBench(int argc, char** argv) {
  TextureArgs a;
  Options o("imr-bench texture",
            "usage: imr-bench texture [--sequence DIR --mesh FILE] [--frames N] "
            "[--keyframe-every N] [--repeat N] [--atlas-size PX] [--seam-penalty X] [--work DIR] "
            "[--keep]\n");
  o.String("--sequence", &a.sequence).String("--mesh", &a.mesh).Int("--frames", &a.frames);
  o.Int("--keyframe-every", &a.keyframe_every).Int("--repeat", &a.repeat);
  o.Int("--atlas-size", &a.atlas_size).Double("--seam-penalty", &a.seam_penalty);
  o.String("--work", &a.work).Flag("--keep", &a.keep);
  if (int status = 0; !o.Parse(argc, argv, &status)) return status;
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
