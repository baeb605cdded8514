// imr-bench drive (issue 32): does memory stay flat on a long drive with the engine forgetting
// what the cameras left behind (engine.forget), and does the surface stay what it was? The real
// `imr run` on imr's dense synthetic street (configs/dense-street.json: the tracked stream at the
// street stream's density, moving points), three runs:
//   1. the first --reference-frames (2,000) without forgetting: the reference surface;
//   2. the same frames with forgetting and tiles: completeness and precision at 0.2 m beside the
//      reference, the merged mesh a manifold, time per frame beside the reference's;
//   3. --frames (20,000) with forgetting and tiles, the generator keeping only its live tracks:
//      peak RSS, RSS at the reference length and at the end, the RSS slope over the second half,
//      frames per second per tenth of the run, tiles written.
// And, when ../shared/data/street-stream is there, its SLAM stream with and without forgetting
// (the same mesh bytes, or the figures of both); and the README's default job (configs/default.json:
// imr-synth's street through the image pipeline, --synth-frames long) with and without forgetting,
// both against the scene's exact surface (`imr evaluate`), with the RSS at its middle and end.
// And drives read from a SLAM JSON file (--slam-frames, issue 46): the dense street written by
// `imr run --export-stream`, read back with forgetting and tiles, the engine's bytes (the trace's
// engine_bytes) beside the process's RSS per tenth, so that what the host holds beyond the engine
// shows. And drives from images (--image-frames, issue 46): imr-synth's street of that many frames
// through the README's default job (the image pipeline, its refinement and colours, tiles), with
// the same per-tenth figures. Prints the targets met or not, and a JSON line.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#ifdef IMR_BENCH_EVALUATE
#include <array>
#include <cstdint>

#include "host/eval/mesh_io.h"
#endif
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/frame.h"
#include "tools/bench/common/subprocess.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const char kUsage[] =
    "usage: imr-bench drive [--frames N] [--reference-frames N] [--keyframe-every K]\n"
    "                       [--work DIR] [--imr PATH] [--no-long] [--no-street]\n"
    "                       [--synth-frames N] [--no-default]\n"
    "                       [--slam-frames N,N] [--no-slam] [--slam-only]\n"
    "                       [--image-frames N,N] [--no-image] [--quick]\n"
    "  --frames N            the long drive (default 20000)\n"
    "  --reference-frames N  the stretch run with and without forgetting (default 2000)\n"
    "  --keyframe-every K    frames per keyframe of the dense street (default 5, as the config)\n"
    "  --work DIR            where the runs go (default: a new folder in /tmp)\n"
    "  --imr PATH            the imr to measure (default: beside imr-bench)\n"
    "  --no-long             only the reference stretch (and the street stream)\n"
    "  --no-street           skip ../shared/data/street-stream\n"
    "  --synth-frames N      frames of imr-synth's street for the default job (default 500)\n"
    "  --no-default          skip the default job\n"
    "  --slam-frames N,N     the drives read from a SLAM JSON file (default 1000,5000)\n"
    "  --no-slam             skip them\n"
    "  --slam-only           only them and the image drives (the generator's drives, the street\n"
    "                        stream and the default job skipped)\n"
    "  --image-frames N,N    drives from images: imr-synth's street of N frames through the\n"
    "                        default job with tiles (default 1000,5000)\n"
    "  --no-image            skip them\n"
    "  --quick               --slam-only with one SLAM JSON drive of 300 frames and one image\n"
    "                        drive of 150\n";

struct DriveArgs {
  int frames = 20000, reference = 2000, keyframe_every = 5, synth_frames = 500;
  bool long_run = true, street = true, default_job = true;
  std::vector<int> slam_frames = {1000, 5000};
  std::vector<int> image_frames = {1000, 5000};
  bool slam = true, slam_only = false, quick = false, image = true;
  fs::path work;
  std::string imr;
};

// The targets, each met or not (true when not measured).
struct DriveTargets {
  bool flat = true, peak_ok = true, steady = true, no_slower = true, same_quality = true;
  bool default_same = true, default_flat = true;
  bool slam_flat = true, slam_peak_ok = true, slam_host_flat = true;
  bool image_flat = true, image_peak_ok = true, image_host_flat = true;
  // The same during the drive (the trace's RSS at each keyframe, the end's exports left out),
  // and what the host holds beyond the engine over the longest drive (last tenth / first).
  bool slam_drive_flat = true, slam_drive_ok = true, slam_tenths_flat = true, slam_steady = true;
  bool image_drive_flat = true, image_drive_ok = true, image_tenths_flat = true, image_steady = true;
};

struct Run {
  std::string name;
  bool ok = false;
  json report;                  // report.json of its one sequence
  std::vector<json> trace;      // one object per keyframe
  double wall = 0.0;            // the whole imr run
};

// The dense street job (configs/dense-street.json's input), with forgetting and tiles or not.
json DenseJob(int frames, int keyframe_every, bool forget, bool keep_truth, const fs::path& out) {
  const json config = json::parse(ReadFileBytes(fs::path(IMR_SOURCE_DIR) / "configs/dense-street.json"));
  json job = {{"sequences", {"street"}}, {"input", config.at("input")}};
  job["input"]["options"]["frames"] = frames;
  job["input"]["options"]["keyframe_every"] = keyframe_every;
  job["input"]["options"]["keep_truth"] = keep_truth;
  job["engine"] = {{"forget", forget}};
  job["pipeline"] = json::array({{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}});
  job["output"] = {{"directory", out.string()}, {"formats", {"ply"}}};
  if (forget) job["output"]["tiles"] = json::object();
  return job;
}

Run RunJob(const std::string& name, const json& job, const fs::path& work, const std::string& imr,
           const std::vector<std::string>& extra = {}) {
  Run r;
  r.name = name;
  const fs::path dir = work / name;
  fs::create_directories(dir);
  const fs::path job_file = dir / "job.json", trace = dir / "trace.jsonl";
  std::ofstream(job_file) << job.dump(2) << "\n";
  std::vector<std::string> argv = {imr, "run", job_file.string(), "-q", "--no-viewer", "--force",
                                   "--trace", trace.string()};
  argv.insert(argv.end(), extra.begin(), extra.end());
  const ProcessResult p = RunProcess(argv, "", dir / "log.txt", 0);
  r.wall = p.seconds;
  const fs::path out = job["output"]["directory"].get<std::string>();
  const fs::path report = out / "report.json";
  r.ok = p.ok() && fs::exists(report);
  if (!r.ok) {
    std::fprintf(stderr, "drive: %s failed (%s); see %s\n", name.c_str(),
                 p.error.empty() ? "exit status" : p.error.c_str(), (dir / "log.txt").c_str());
    return r;
  }
  r.report = json::parse(ReadFileBytes(report));
  std::ifstream t(trace);
  for (std::string line; std::getline(t, line);)
    if (!line.empty()) r.trace.push_back(json::parse(line));
  return r;
}

double Get(const json& j, const std::vector<std::string>& path, double otherwise = NAN) {
  const json* x = &j;
  for (const std::string& k : path) {
    if (!x->is_object() || !x->contains(k) || (*x)[k].is_null()) return otherwise;
    x = &(*x)[k];
  }
  return x->is_number() ? x->get<double>() : otherwise;
}

// The trace's keyframes as (frame, value).
struct Series {
  std::vector<double> frame, rss, seconds, engine;
  std::vector<double> engine_bytes;  // NAN on the keyframes the trace did not measure them
  // The allocator's figures (trace heap_bytes), measured with engine_bytes; NAN where not.
  std::vector<double> heap_allocated, heap_resident;
};
Series SeriesOf(const Run& r) {
  Series s;
  for (const json& k : r.trace) {
    s.frame.push_back(k.value("frame", 0.0));
    s.rss.push_back(k.value("rss_bytes", 0.0));
    s.seconds.push_back(k.value("seconds", 0.0));
    s.engine.push_back(k.value("engine_seconds", 0.0));
    s.engine_bytes.push_back(k.contains("engine_bytes") ? k["engine_bytes"].get<double>() : NAN);
    const bool heap = k.contains("heap_bytes");
    s.heap_allocated.push_back(heap ? k["heap_bytes"]["allocated"].get<double>() : NAN);
    s.heap_resident.push_back(heap ? k["heap_bytes"]["resident"].get<double>() : NAN);
  }
  return s;
}

// Least-squares slope of y over x for the keyframes from `from` on.
double Slope(const std::vector<double>& x, const std::vector<double>& y, size_t from) {
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = from; i < x.size(); ++i) {
    n += 1, sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
  }
  const double d = n * sxx - sx * sx;
  return n > 1 && d != 0.0 ? (n * sxy - sx * sy) / d : 0.0;
}

// RSS at the first keyframe at or after `frame`.
double RssAt(const Series& s, double frame) {
  for (size_t i = 0; i < s.frame.size(); ++i)
    if (s.frame[i] >= frame) return s.rss[i];
  return s.rss.empty() ? 0.0 : s.rss.back();
}

std::string Mb(double bytes) {
  char b[32];
  std::snprintf(b, sizeof b, "%.0f MB", bytes / 1e6);
  return b;
}

std::string Md5(const fs::path& p) {
  const std::string cmd = "md5sum " + Quote(p.string()) + " 2>/dev/null";
  std::string out;
  if (FILE* f = popen(cmd.c_str(), "r")) {
    char buf[128];
    if (std::fgets(buf, sizeof buf, f)) out = buf;
    pclose(f);
  }
  return out.substr(0, out.find(' '));
}

// Two meshes with other bytes may hold the same surface in another order: the triangles that
// are in one only (oriented, by their corners' positions to 1e-5), -1 when it cannot tell.
long TrianglesNotShared(const fs::path& a, const fs::path& b) {
#ifdef IMR_BENCH_EVALUATE
  using Corner = std::array<long long, 3>;
  auto triangles = [](const fs::path& p) {
    const eval::TriangleMesh m = eval::ReadMesh(p);
    std::vector<std::array<Corner, 3>> out;
    for (const auto& t : m.triangles) {
      std::array<Corner, 3> c;
      for (int k = 0; k < 3; ++k)
        for (int d = 0; d < 3; ++d) c[k][d] = std::llround(m.vertices[t[k]][d] * 1e5);
      std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());  // keeps orientation
      out.push_back(c);
    }
    std::sort(out.begin(), out.end());
    return out;
  };
  try {
    const auto x = triangles(a), y = triangles(b);
    std::vector<std::array<Corner, 3>> d;
    std::set_symmetric_difference(x.begin(), x.end(), y.begin(), y.end(), std::back_inserter(d));
    return static_cast<long>(d.size());
  } catch (const std::exception&) {
    return -1;
  }
#else
  (void)a, (void)b;
  return -1;
#endif
}


bool ParseDriveArgs(int argc, char** argv, DriveArgs* a, int* status) {
  a->imr = (ExeDir() / "imr").string();
  Options o("drive", kUsage, 64);
  o.Int("--frames", &a->frames).Int("--reference-frames", &a->reference);
  o.Int("--keyframe-every", &a->keyframe_every).Int("--synth-frames", &a->synth_frames);
  o.Path("--work", &a->work).String("--imr", &a->imr);
  o.Flag("--no-long", &a->long_run, false).Flag("--no-street", &a->street, false);
  o.Flag("--no-default", &a->default_job, false);
  o.IntList("--slam-frames", &a->slam_frames, 50).Flag("--no-slam", &a->slam, false);
  o.Flag("--slam-only", &a->slam_only).Flag("--quick", &a->quick);
  o.IntList("--image-frames", &a->image_frames, 20).Flag("--no-image", &a->image, false);
  if (!o.Parse(argc, argv, status)) return false;
  if (a->quick) a->slam_only = true, a->slam_frames = {300}, a->image_frames = {150};
  if (a->slam_only) a->long_run = a->street = a->default_job = false;  // --no-slam: images only
  if (a->frames < a->reference || a->reference < 100 || a->keyframe_every < 1 ||
      a->synth_frames < 20) {
    std::fprintf(stderr, "drive: need 100 <= --reference-frames <= --frames, --keyframe-every >= 1, "
                         "--synth-frames >= 20\n");
    *status = 64;
    return false;
  }
  if (a->work.empty()) {
    char tmpl[] = "/tmp/imr-drive-XXXXXX";
    if (!mkdtemp(tmpl)) {
      std::perror("drive: mkdtemp");
      *status = 1;
      return false;
    }
    a->work = tmpl;
  }
  return true;
}

// 1 and 2: the reference stretch, without and with forgetting. False when a run failed.
bool ReferenceStretch(const DriveArgs& a, DriveTargets* t, json* out) {
  const int reference = a.reference;
  const Run off = RunJob("reference_off", DenseJob(reference, a.keyframe_every, false, true, a.work / "reference_off/out"), a.work, a.imr);
  const Run on = RunJob("reference_on", DenseJob(reference, a.keyframe_every, true, true, a.work / "reference_on/out"), a.work, a.imr);
  if (!off.ok || !on.ok) return false;
  auto acc = [](const Run& r, const char* k) { return Get(r.report, {"accuracy", k}); };
  const double c_off = acc(off, "completeness"), p_off = acc(off, "precision");
  const double c_on = acc(on, "completeness"), p_on = acc(on, "precision");
  const double ms_off = 1000.0 * Get(off.report, {"engine", "seconds", "total"}) / reference;
  const double ms_on = 1000.0 * Get(on.report, {"engine", "seconds", "total"}) / reference;
  const bool manifold_on = on.report["mesh"].value("manifold", false);
  std::printf("\nThe first %d frames (keyframe every %d), without and with forgetting:\n", reference,
              a.keyframe_every);
  MarkdownHeader({"run", "completeness 0.2 m", "precision 0.2 m", "engine ms/frame", "wall s",
                  "peak RSS", "faces", "manifold", "tiles"});
  for (const Run* r : {&off, &on})
    std::printf("| %s | %.4f | %.4f | %.1f | %.1f | %s | %.0f | %s | %.0f |\n",
                r == &off ? "forget off" : "forget on", acc(*r, "completeness"),
                acc(*r, "precision"), r == &off ? ms_off : ms_on, r->wall,
                Mb(Get(r->report, {"memory", "peak_rss_bytes"})).c_str(),
                Get(r->report, {"mesh", "faces"}),
                r->report["mesh"].value("manifold", false) ? "yes" : "no",
                Get(r->report, {"tiles", "count"}, 0.0));
  t->same_quality = c_on >= c_off - 0.01 && p_on >= p_off - 0.01 && manifold_on;
  // "No slower per frame than today": the whole run's wall time, what a user waits for (the
  // engine alone pays for forgetting what the smaller memory wins back elsewhere); 2 % is noise.
  const double wall_ms_off = 1000.0 * off.wall / reference, wall_ms_on = 1000.0 * on.wall / reference;
  t->no_slower = wall_ms_on <= wall_ms_off * 1.02;
  (*out)["reference"] = {{"completeness_off", c_off}, {"precision_off", p_off},
                         {"completeness_on", c_on}, {"precision_on", p_on},
                         {"engine_ms_per_frame_off", ms_off},
                         {"engine_ms_per_frame_on", ms_on},
                         {"wall_ms_per_frame_off", wall_ms_off},
                         {"wall_ms_per_frame_on", wall_ms_on}, {"manifold_on", manifold_on}};
  return true;
}

// The long drive's table: frames per second and RSS per tenth of its keyframes.
json PrintTenths(const Series& s, std::vector<double>* fps) {
  MarkdownHeader({"tenth", "frames", "frames/s (wall)", "frames/s (engine)", "RSS at its end"});
  const size_t n = s.frame.size();
  json tenths = json::array();
  for (int t = 0; t < 10 && n >= 10; ++t) {
    const size_t a = t * n / 10, b = (t + 1) * n / 10 - 1;
    const double f0 = a == 0 ? 0.0 : s.frame[a - 1], f1 = s.frame[b];
    const double w0 = a == 0 ? 0.0 : s.seconds[a - 1], w1 = s.seconds[b];
    double e = 0.0;
    for (size_t i = a; i <= b; ++i) e += s.engine[i];
    const double wall_fps = (f1 - f0) / std::max(1e-9, w1 - w0), engine_fps = (f1 - f0) / e;
    fps->push_back(wall_fps);
    std::printf("| %d | %.0f-%.0f | %.1f | %.1f | %s |\n", t + 1, f0, f1, wall_fps, engine_fps,
                Mb(s.rss[b]).c_str());
    tenths.push_back({{"frames", {f0, f1}}, {"fps_wall", wall_fps}, {"fps_engine", engine_fps},
                      {"rss_bytes", s.rss[b]}});
  }
  return tenths;
}

// 3: the long drive with forgetting. False when the run failed.
bool LongDrive(const DriveArgs& a, DriveTargets* t, json* out) {
  const Run lr = RunJob("long", DenseJob(a.frames, a.keyframe_every, true, false, a.work / "long/out"), a.work, a.imr);
  if (!lr.ok) return false;
  const Series s = SeriesOf(lr);
  const double peak = Get(lr.report, {"memory", "peak_rss_bytes"});
  // The process's peak may come after the drive: the last parts, tiles and the single mesh's
  // export (in blocks from the spool) and evaluation.
  double drive_peak = 0.0;
  for (double r : s.rss) drive_peak = std::max(drive_peak, r);
  const double at_ref = RssAt(s, a.reference), at_end = s.rss.empty() ? 0.0 : s.rss.back();
  const double slope = Slope(s.frame, s.rss, s.frame.size() / 2);  // bytes per frame
  std::printf("\nA drive of %d frames with forgetting (tiles on, the generator keeping its live "
              "tracks only):\n", a.frames);
  std::vector<double> fps;
  const json tenths = PrintTenths(s, &fps);
  const json& fg = lr.report["engine"]["forget"];
  std::printf("\npeak RSS %s (%s during the drive, at its keyframes; the rest at the end: the "
              "last tiles, the single mesh written and measured in blocks); RSS %s at frame %d, %s at the end (x%.2f); "
              "slope over the second half %.1f kB per frame (%.1f MB per 1,000 frames); tiles "
              "%.0f; mesh %.0f faces, manifold %s; rebuilds %d, vertices forgotten %d, changes "
              "refused %d\n",
              Mb(peak).c_str(), Mb(drive_peak).c_str(), Mb(at_ref).c_str(), a.reference, Mb(at_end).c_str(),
              at_ref > 0 ? at_end / at_ref : 0.0, slope / 1e3, slope * 1000 / 1e6,
              Get(lr.report, {"tiles", "count"}, 0.0), Get(lr.report, {"mesh", "faces"}),
              lr.report["mesh"].value("manifold", false) ? "yes" : "no", fg.value("rebuilds", 0),
              fg.value("vertices_forgotten", 0), fg.value("changes_refused_final", 0));
  t->flat = at_end <= 1.2 * at_ref;
  t->peak_ok = peak <= 400e6;
  t->steady = fps.size() == 10 && fps.back() >= 0.9 * fps.front();
  (*out)["long"] = {{"peak_rss_bytes", peak}, {"drive_peak_rss_bytes", drive_peak},
                    {"rss_at_reference", at_ref}, {"rss_at_end", at_end},
                    {"rss_slope_bytes_per_frame", slope}, {"tenths", tenths},
                    {"tiles", Get(lr.report, {"tiles", "count"}, 0.0)},
                    {"manifold", lr.report["mesh"].value("manifold", false)},
                    {"wall_seconds", lr.wall}, {"forget", fg}};
  (*out)["long"]["forget"].erase("live");
  return true;
}

// The independent street stream, without and with forgetting. False when a run failed.
bool StreetStream(const DriveArgs& a, json* out) {
  const fs::path stream = SharedDir() / "data/street-stream/slam.json";
  if (!fs::exists(stream)) {
    std::printf("\nStreet stream: %s not found (set IMR_SHARED_DIR); not measured\n", stream.c_str());
    return true;
  }
  std::string md5[2];
  double peak[2] = {0, 0};
  fs::path mesh[2];
  for (int f = 0; f < 2; ++f) {
    const fs::path o = a.work / (f ? "street_on" : "street_off") / "out";
    json job = {{"sequences", {stream.string()}},
                {"input", {{"format", "slam_json"}, {"options", {{"views_per_keyframe", 1}}}}},
                {"engine", {{"forget", f == 1}}},
                {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
                {"output", {{"directory", o.string()}, {"formats", {"ply"}}}}};
    const Run r = RunJob(f ? "street_on" : "street_off", job, a.work, a.imr);
    if (!r.ok) return false;
    mesh[f] = o / "mesh.ply";
    md5[f] = Md5(mesh[f]);
    peak[f] = Get(r.report, {"memory", "peak_rss_bytes"});
  }
  // With forgetting the mesh is put together from the parts in the order they became final.
  const long differ = md5[0] == md5[1] ? 0 : TrianglesNotShared(mesh[0], mesh[1]);
  const std::string same = md5[0] == md5[1] ? "the same bytes"
                           : differ == 0    ? "the same triangles in another order"
                           : differ > 0     ? std::to_string(differ) + " triangles not shared"
                                            : "other bytes";
  std::printf("\nStreet stream (%s, every view a keyframe): mesh md5 %s without, %s with "
              "forgetting (%s); peak RSS %s and %s\n", stream.c_str(), md5[0].c_str(),
              md5[1].c_str(), same.c_str(), Mb(peak[0]).c_str(), Mb(peak[1]).c_str());
  (*out)["street_stream"] = {{"same_mesh", md5[0] == md5[1]}, {"triangles_not_shared", differ},
                             {"md5_off", md5[0]},
                             {"md5_on", md5[1]}, {"peak_rss_off", peak[0]}, {"peak_rss_on", peak[1]}};
  return true;
}

// One run of the README's default job on imr-synth's street `seq`, and its completeness and
// precision at 0.2 m against the scene's exact surface. False when imr run or evaluate failed.
bool DefaultRun(const DriveArgs& a, const json& config, const fs::path& seq, bool forget, Run* run,
                double* completeness, double* precision) {
  const std::string name = forget ? "default_on" : "default_off";
  const fs::path o = a.work / name / "out";
  json job = config;
  job.erase("description");
  job["sequences"] = {seq.string()};
  job["engine"]["forget"] = forget;
  job["output"] = {{"directory", o.string()}, {"stem", "mesh"}, {"formats", {"ply"}}};
  if (forget) job["output"]["tiles"] = json::object();
  *run = RunJob(name, job, a.work, a.imr);
  if (!run->ok) return false;
  const fs::path eval = a.work / name / "evaluation.json";
  if (Sh(Quote(a.imr) + " evaluate " + Quote((o / "mesh.ply").string()) + " --truth " +
         Quote((seq / "ground_truth/scene.ply").string()) + " --velodyne-seq " +
         Quote(seq.string()) + " --tau 0.2 --out " + Quote(eval.string()) + " >" +
         Quote((a.work / name / "evaluate.log").string()) + " 2>&1") != 0) {
    std::fprintf(stderr, "drive: imr evaluate failed; see %s\n",
                 (a.work / name / "evaluate.log").c_str());
    return false;
  }
  const json e = json::parse(ReadFileBytes(eval));
  *completeness = e["completeness"][0].get<double>();
  *precision = e["precision"][0].get<double>();
  return true;
}

// The README's default job: the image pipeline (features, refiner, exporter) on imr-synth's
// street, without and with forgetting, against the scene's exact surface. False on a failure.
bool DefaultJobs(const DriveArgs& a, DriveTargets* t, json* out) {
  const fs::path seq = a.work / "synth-street";
  const std::string synth = (fs::path(a.imr).parent_path() / "imr-synth").string();
  if (Sh(Quote(synth) + " --out " + Quote(seq.string()) + " --frames " +
         std::to_string(a.synth_frames) + " --color --no-lidar --force -q >" +
         Quote((a.work / "synth.log").string()) + " 2>&1") != 0) {
    std::fprintf(stderr, "drive: imr-synth failed; see %s\n", (a.work / "synth.log").c_str());
    return false;
  }
  const json config = json::parse(ReadFileBytes(fs::path(IMR_SOURCE_DIR) / "configs/default.json"));
  Run runs[2];
  double c[2] = {NAN, NAN}, p[2] = {NAN, NAN};
  for (int f = 0; f < 2; ++f)
    if (!DefaultRun(a, config, seq, f == 1, &runs[f], &c[f], &p[f])) return false;
  const int half = a.synth_frames / 2;
  const Series s = SeriesOf(runs[1]);
  const double mid = RssAt(s, a.synth_frames / 2.0), end = s.rss.empty() ? 0.0 : s.rss.back();
  std::printf("\nThe README's default job (configs/default.json, imr-synth's street of %d frames, "
              "the image pipeline), without and with forgetting:\n", a.synth_frames);
  MarkdownHeader({"run", "completeness 0.2 m", "precision 0.2 m", "wall s", "peak RSS",
                  Format("RSS at frame %d", half), "RSS at the end", "faces", "manifold"});
  for (int f = 0; f < 2; ++f) {
    const Series sf = SeriesOf(runs[f]);
    std::printf("| %s | %.4f | %.4f | %.1f | %s | %s | %s | %.0f | %s |\n",
                f ? "forget on" : "forget off", c[f], p[f], runs[f].wall,
                Mb(Get(runs[f].report, {"memory", "peak_rss_bytes"})).c_str(),
                Mb(RssAt(sf, a.synth_frames / 2.0)).c_str(),
                Mb(sf.rss.empty() ? 0.0 : sf.rss.back()).c_str(),
                Get(runs[f].report, {"mesh", "faces"}),
                runs[f].report["mesh"].value("manifold", false) ? "yes" : "no");
  }
  t->default_same = c[1] >= c[0] - 0.01 && p[1] >= p[0] - 0.01 &&
                    runs[1].report["mesh"].value("manifold", false);
  t->default_flat = end <= 1.2 * mid;
  (*out)["default_job"] = {{"synth_frames", a.synth_frames}, {"completeness_off", c[0]},
                           {"precision_off", p[0]}, {"completeness_on", c[1]},
                           {"precision_on", p[1]}, {"wall_off", runs[0].wall},
                           {"wall_on", runs[1].wall}, {"rss_mid_on", mid}, {"rss_end_on", end},
                           {"peak_rss_off", Get(runs[0].report, {"memory", "peak_rss_bytes"})},
                           {"peak_rss_on", Get(runs[1].report, {"memory", "peak_rss_bytes"})}};
  return true;
}

// The last keyframe at or before `i` whose engine bytes the trace measured (i itself when none).
size_t MeasuredAt(const Series& s, size_t i) {
  for (size_t j = std::min(i + 1, s.engine_bytes.size()); j-- > 0;)
    if (!std::isnan(s.engine_bytes[j])) return j;
  return i;
}

json Tenths(const Run& r);

// One drive read from a SLAM JSON file: the dense street of `frames` frames written by imr run
// --export-stream (kept in the work folder and reused), read back with forgetting and tiles.
// Prints, per tenth, the RSS, the engine's bytes and what the host holds beyond them. False when
// a run failed.
bool SlamDrive(const DriveArgs& a, int frames, json* out) {
  const std::string name = "slam" + std::to_string(frames);
  const fs::path file = a.work / name / "drive.json";
  if (!fs::exists(file)) {
    json gen = DenseJob(frames, a.keyframe_every, true, false, a.work / (name + "_write/out"));
    gen["output"]["formats"] = json::array();  // tiles only: the stream is what is wanted
    fs::create_directories(file.parent_path());
    const Run g = RunJob(name + "_write", gen, a.work, a.imr, {"--export-stream", file.string()});
    if (!g.ok || !fs::exists(file)) return false;
  }
  const json job = {{"sequences", {file.string()}},
                    {"input", {{"format", "slam_json"}, {"options", json::object()}}},
                    {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
                    {"output", {{"directory", (a.work / name / "out").string()},
                                {"formats", {"ply"}}, {"tiles", json::object()}}}};
  const Run r = RunJob(name, job, a.work, a.imr);
  if (!r.ok) return false;
  const double file_mb = static_cast<double>(fs::file_size(file)) / 1e6;
  std::printf("\nA drive of %d frames read from a SLAM JSON file (%.0f MB; imr's dense street "
              "written by --export-stream), engine.forget auto, tiles:\n", frames, file_mb);
  json d = Tenths(r);
  d["frames"] = frames;
  d["file_bytes"] = fs::file_size(file);
  (*out)["slam"].push_back(d);
  return true;
}

// The run's RSS, the engine's bytes and what the host holds beyond them per tenth (printed), and
// report.json's figures at the end. With the allocator's figures, RSS - engine splits into what
// the heap holds beyond the engine (allocated - engine: a leak grows it), what freeing kept
// resident (resident - allocated) and the rest (code, libraries, stacks).
json Tenths(const Run& r) {
  const Series s = SeriesOf(r);
  MarkdownHeader({"tenth", "frame", "frames/s (wall)", "RSS", "engine bytes", "RSS - engine",
                  "heap allocated - engine", "heap resident - allocated"});
  const size_t n = s.frame.size();
  json tenths = json::array();
  double host_first = NAN, host_last = NAN, fps_first = NAN, fps_last = NAN;
  for (int t = 0; t < 10 && n >= 10; ++t) {
    const size_t b = MeasuredAt(s, (t + 1) * n / 10 - 1);  // RSS and engine bytes together
    const double e = s.engine_bytes[b], host = s.rss[b] - e;
    if (t == 0) host_first = host;
    host_last = host;
    // Frames through the whole pipeline per second of the run over the tenth's keyframes (the
    // first tenth from the first keyframe: the input's opening is not the drive's rate).
    const size_t a0 = t == 0 ? 0 : t * n / 10 - 1, a1 = (t + 1) * n / 10 - 1;
    const double fps = (s.frame[a1] - s.frame[a0]) / std::max(1e-9, s.seconds[a1] - s.seconds[a0]);
    if (t == 0) fps_first = fps;
    fps_last = fps;
    const double alloc = s.heap_allocated[b], resident = s.heap_resident[b];
    std::printf("| %d | %.0f | %.2f | %s | %s | %s | %s | %s |\n", t + 1, s.frame[b], fps,
                Mb(s.rss[b]).c_str(), Mb(e).c_str(), Mb(host).c_str(),
                std::isnan(alloc) ? "-" : Mb(alloc - e).c_str(),
                std::isnan(alloc) ? "-" : Mb(resident - alloc).c_str());
    json tenth = {{"frame", s.frame[b]}, {"fps_wall", fps}, {"rss_bytes", s.rss[b]}, {"engine_bytes", e}};
    if (!std::isnan(alloc)) tenth["heap_allocated_bytes"] = alloc, tenth["heap_resident_bytes"] = resident;
    tenths.push_back(tenth);
  }
  // Slope of RSS - engine bytes over the second half's measured keyframes.
  std::vector<double> x, y;
  for (size_t i = n / 2; i < n; ++i)
    if (!std::isnan(s.engine_bytes[i])) x.push_back(s.frame[i]), y.push_back(s.rss[i] - s.engine_bytes[i]);
  const double slope = Slope(x, y, 0);
  const double engine_end = Get(r.report, {"memory", "engine_bytes", "total"});
  const double final_rss = Get(r.report, {"memory", "final_rss_bytes"});
  const double peak = Get(r.report, {"memory", "peak_rss_bytes"});
  const double first_rss = s.rss.empty() ? NAN : s.rss.front();
  const double drive_max = s.rss.empty() ? NAN : *std::max_element(s.rss.begin(), s.rss.end());
  // The end (the last part, the single mesh's export and evaluation) against the drive itself.
  std::printf("the trace's largest RSS during the drive: %s; the run's peak (the end): %s\n",
              Mb(drive_max).c_str(), Mb(Get(r.report, {"memory", "peak_rss_bytes"})).c_str());
  std::printf("\nreport.json: engine bytes %s at the end, final RSS %s (%s beyond the engine), peak "
              "RSS %s; RSS %s after the first keyframe (the input opened); RSS - engine over the "
              "second half: %.1f kB per frame; wall %.1f s\n",
              Mb(engine_end).c_str(), Mb(final_rss).c_str(), Mb(final_rss - engine_end).c_str(),
              Mb(peak).c_str(), Mb(first_rss).c_str(), slope / 1e3, r.wall);
  const double heap_end = Get(r.report, {"memory", "final_heap_bytes", "allocated"});
  const double heap_resident_end = Get(r.report, {"memory", "final_heap_bytes", "resident"});
  if (!std::isnan(heap_end))
    std::printf("the allocator at the end: %s allocated (%s beyond the engine), %s resident\n",
                Mb(heap_end).c_str(), Mb(heap_end - engine_end).c_str(), Mb(heap_resident_end).c_str());
  return {{"peak_rss_bytes", peak}, {"final_rss_bytes", final_rss},
          {"engine_bytes_end", engine_end}, {"first_rss_bytes", first_rss},
          {"host_bytes_first_tenth", host_first}, {"host_bytes_last_tenth", host_last},
          {"fps_first_tenth", fps_first}, {"fps_last_tenth", fps_last},
          {"host_slope_bytes_per_frame", slope}, {"tenths", tenths}, {"wall_seconds", r.wall},
          {"drive_max_rss_bytes", drive_max},
          {"forget_on_from_update", Get(r.report, {"engine", "forget", "on_from_update"})},
          {"heap_allocated_end", heap_end}, {"heap_resident_end", heap_resident_end}};
}

// During the drive: the longest drive's largest RSS within 1.2 x the shortest's and 400 MB,
// what it holds beyond the engine's bytes at its last tenth within 1.2 x its first tenth's, and
// its frames/s over the last tenth at least 0.9 x the first tenth's.
void DuringTheDrive(const json& first, const json& last, bool* flat, bool* ok, bool* tenths_flat,
                    bool* steady) {
  const double longest = last["drive_max_rss_bytes"].get<double>();
  *flat = longest <= 1.2 * first["drive_max_rss_bytes"].get<double>();
  *ok = longest <= 400e6;
  *tenths_flat = last["host_bytes_last_tenth"].get<double>() <= 1.2 * last["host_bytes_first_tenth"].get<double>();
  *steady = last["fps_last_tenth"].get<double>() >= 0.9 * last["fps_first_tenth"].get<double>();
}

// The SLAM JSON drives, shortest first, and their targets: the longest's peak RSS within 1.2 x
// the shortest's and 400 MB, what the process holds at its end (the engine gone) within 1.2 x the
// shortest's.
bool SlamDrives(const DriveArgs& a, DriveTargets* t, json* out) {
  std::vector<int> lengths = a.slam_frames;
  std::sort(lengths.begin(), lengths.end());
  (*out)["slam"] = json::array();
  for (int f : lengths)
    if (!SlamDrive(a, f, out)) return false;
  const json& first = (*out)["slam"].front();
  const json& last = (*out)["slam"].back();
  // What the process still holds at its end, the engine gone (report.json's final RSS: taking the
  // engine's last bytes off it, as this did before 2026-12-07, subtracted a figure measured
  // before they were freed, which swings with the forgetting's rebuild cycle).
  auto host = [](const json& d) { return d["final_rss_bytes"].get<double>(); };
  t->slam_flat = last["peak_rss_bytes"].get<double>() <= 1.2 * first["peak_rss_bytes"].get<double>();
  t->slam_peak_ok = last["peak_rss_bytes"].get<double>() <= 400e6;
  t->slam_host_flat = host(last) <= 1.2 * host(first);
  DuringTheDrive(first, last, &t->slam_drive_flat, &t->slam_drive_ok, &t->slam_tenths_flat,
                 &t->slam_steady);
  return true;
}

// One drive from images: imr-synth's street of `frames` frames (kept in the work folder and
// reused) through the README's default job (configs/default.json: features, refiner, the
// photometric refinement, coloured exports; engine.forget at its default, auto) with tiles.
bool ImageDrive(const DriveArgs& a, int frames, json* out) {
  const std::string name = "image" + std::to_string(frames);
  const fs::path seq = a.work / name / "synth-street";
  if (!fs::exists(seq / "poses.txt")) {
    fs::create_directories(seq.parent_path());
    const std::string synth = (fs::path(a.imr).parent_path() / "imr-synth").string();
    if (Sh(Quote(synth) + " --out " + Quote(seq.string()) + " --frames " + std::to_string(frames) +
           " --color --no-lidar --force -q >" + Quote((a.work / name / "synth.log").string()) +
           " 2>&1") != 0) {
      std::fprintf(stderr, "drive: imr-synth failed; see %s\n", (a.work / name / "synth.log").c_str());
      return false;
    }
  }
  json job = json::parse(ReadFileBytes(fs::path(IMR_SOURCE_DIR) / "configs/default.json"));
  job.erase("description");
  job["sequences"] = {seq.string()};
  job["output"] = {{"directory", (a.work / name / "out").string()}, {"stem", "mesh"},
                   {"formats", {"ply"}}, {"tiles", json::object()}};
  const Run r = RunJob(name, job, a.work, a.imr);
  if (!r.ok) return false;
  std::printf("\nA drive of %d frames from images (imr-synth's street through the default job, "
              "engine.forget auto, tiles):\n", frames);
  json d = Tenths(r);
  d["frames"] = frames;
  (*out)["image"].push_back(d);
  return true;
}

// The image drives, shortest first, and their targets as the SLAM JSON drives'.
bool ImageDrives(const DriveArgs& a, DriveTargets* t, json* out) {
  std::vector<int> lengths = a.image_frames;
  std::sort(lengths.begin(), lengths.end());
  (*out)["image"] = json::array();
  for (int f : lengths)
    if (!ImageDrive(a, f, out)) return false;
  const json& first = (*out)["image"].front();
  const json& last = (*out)["image"].back();
  // What the process still holds at its end, the engine gone (report.json's final RSS: taking the
  // engine's last bytes off it, as this did before 2026-12-07, subtracted a figure measured
  // before they were freed, which swings with the forgetting's rebuild cycle).
  auto host = [](const json& d) { return d["final_rss_bytes"].get<double>(); };
  t->image_flat = last["peak_rss_bytes"].get<double>() <= 1.2 * first["peak_rss_bytes"].get<double>();
  t->image_peak_ok = last["peak_rss_bytes"].get<double>() <= 400e6;
  t->image_host_flat = host(last) <= 1.2 * host(first);
  DuringTheDrive(first, last, &t->image_drive_flat, &t->image_drive_ok, &t->image_tenths_flat,
                 &t->image_steady);
  return true;
}

void PrintDriveTargets(const DriveArgs& a, const DriveTargets& t, json* out) {
  auto line = [](bool met, const char* what) {
    std::printf("- %s: %s\n", met ? "met" : "NOT MET", what);
  };
  std::printf("\nTargets:\n");
  if (a.slam) {
    const std::string lengths = Format("%d frames beside %d", *std::max_element(a.slam_frames.begin(), a.slam_frames.end()),
                                       *std::min_element(a.slam_frames.begin(), a.slam_frames.end()));
    line(t.slam_flat, ("SLAM JSON: peak RSS <= 1.2 x the shortest drive's (" + lengths + ")").c_str());
    line(t.slam_peak_ok, "SLAM JSON: the longest drive's peak RSS <= 400 MB");
    line(t.slam_host_flat, ("SLAM JSON: RSS at the end, the engine gone, <= 1.2 x the "
                            "shortest drive's (" + lengths + ")").c_str());
    line(t.slam_drive_flat, ("SLAM JSON: during the drive, RSS <= 1.2 x the shortest drive's (" + lengths + ")").c_str());
    line(t.slam_drive_ok, "SLAM JSON: during the longest drive, RSS <= 400 MB");
    line(t.slam_tenths_flat, "SLAM JSON: the longest drive's RSS beyond the engine's bytes, last tenth <= 1.2 x first");
    line(t.slam_steady, "SLAM JSON: the longest drive's frames/s over the last tenth >= 0.9 x the first tenth");
  }
  if (a.image) {
    const std::string lengths = Format("%d frames beside %d", *std::max_element(a.image_frames.begin(), a.image_frames.end()),
                                       *std::min_element(a.image_frames.begin(), a.image_frames.end()));
    line(t.image_flat, ("images: peak RSS <= 1.2 x the shortest drive's (" + lengths + ")").c_str());
    line(t.image_peak_ok, "images: the longest drive's peak RSS <= 400 MB");
    line(t.image_host_flat, ("images: RSS at the end, the engine gone, <= 1.2 x the "
                             "shortest drive's (" + lengths + ")").c_str());
    line(t.image_drive_flat, ("images: during the drive, RSS <= 1.2 x the shortest drive's (" + lengths + ")").c_str());
    line(t.image_drive_ok, "images: during the longest drive, RSS <= 400 MB");
    line(t.image_tenths_flat, "images: the longest drive's RSS beyond the engine's bytes, last tenth <= 1.2 x first");
    line(t.image_steady, "images: the longest drive's frames/s over the last tenth >= 0.9 x the first tenth");
  }
  if (a.slam_only) {
    (*out)["targets"] = {{"slam_flat", t.slam_flat}, {"slam_peak", t.slam_peak_ok},
                         {"slam_host_flat", t.slam_host_flat}, {"image_flat", t.image_flat},
                         {"image_peak", t.image_peak_ok}, {"image_host_flat", t.image_host_flat},
                         {"slam_drive_flat", t.slam_drive_flat}, {"slam_drive", t.slam_drive_ok},
                         {"slam_tenths_flat", t.slam_tenths_flat}, {"image_drive_flat", t.image_drive_flat},
                         {"image_drive", t.image_drive_ok}, {"image_tenths_flat", t.image_tenths_flat},
                         {"slam_steady", t.slam_steady}, {"image_steady", t.image_steady}};
    return;
  }
  if (a.long_run) {
    line(t.flat, "RSS at the end <= 1.2 x RSS at the reference length");
    line(t.peak_ok, "peak RSS <= 400 MB (the whole process, the single mesh at the end included)");
    line(t.steady, "frames/s over the last tenth >= 0.9 x the first tenth");
  }
  line(t.no_slower, "the whole run's wall time per frame with forgetting no more than 2 % above "
                    "without");
  line(t.same_quality,
       "completeness and precision within 0.01 of the run without forgetting, a manifold");
  if (a.default_job) {
    line(t.default_same, "the default job: completeness and precision within 0.01 of the run "
                         "without forgetting, a manifold");
    std::printf("- %s: the default job's RSS at the end <= 1.2 x RSS at its middle (%d frames%s)\n",
                t.default_flat ? "met" : "NOT MET", a.synth_frames,
                a.synth_frames < 5000 ? "; the target is for 5,000" : "");
  }
  (*out)["targets"] = {{"flat", t.flat}, {"peak", t.peak_ok}, {"steady", t.steady},
                       {"no_slower", t.no_slower}, {"same_quality", t.same_quality},
                       {"default_same", t.default_same}, {"default_flat", t.default_flat},
                       {"slam_flat", t.slam_flat}, {"slam_peak", t.slam_peak_ok},
                       {"slam_host_flat", t.slam_host_flat}, {"image_flat", t.image_flat},
                       {"image_peak", t.image_peak_ok}, {"image_host_flat", t.image_host_flat}};
}

}  // namespace

int RunDriveBench(int argc, char** argv) {
  DriveArgs a;
  if (int status = 0; !ParseDriveArgs(argc, argv, &a, &status)) return status;
  std::printf("imr-bench drive: %s; %s, load %s; work %s\n", a.imr.c_str(), MachineLine().c_str(),
              LoadAverage().c_str(), a.work.c_str());
  json out = {{"bench", "drive"}, {"frames", a.frames}, {"reference_frames", a.reference},
              {"keyframe_every", a.keyframe_every}};
  DriveTargets t;
  if (!a.slam_only && !ReferenceStretch(a, &t, &out)) return 1;
  out["load"] = LoadAverage();  // after the reference stretch, as the figure always was
  if (a.long_run && !LongDrive(a, &t, &out)) return 1;
  if (a.street && !StreetStream(a, &out)) return 1;
  if (a.default_job && !DefaultJobs(a, &t, &out)) return 1;
  if (a.slam && !SlamDrives(a, &t, &out)) return 1;
  if (a.image && !ImageDrives(a, &t, &out)) return 1;
  PrintDriveTargets(a, t, &out);
  std::printf("%s\n", out.dump().c_str());
  return 0;
}

}  // namespace imr::bench
