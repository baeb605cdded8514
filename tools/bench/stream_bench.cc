// imr-bench stream: imr's synthetic observation stream alone (no engine), in its tracked model on
// the dense street of configs/dense-street.json, over a long drive: is the generator's time per
// frame and its memory flat in the drive's length, and what does it hand out (observations, new
// points and moves per frame, track lengths)? Also the scene: building the street's canyon
// (time, rects) and the cost of one Sees query at the start and at the end of the street. Prints
// a table per tenth of the run and ends with one JSON line.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/synthetic/stream.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/frame.h"

namespace imr::bench {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

// Resident set now (/proc/self/statm), bytes.
long RssBytes() {
  std::ifstream in("/proc/self/statm");
  long size = 0, resident = 0;
  in >> size >> resident;
  return resident * sysconf(_SC_PAGESIZE);
}

// Mean time of one Sees query for points on the surfaces around frame `frame` (what the stream
// asks: its live tracks' points from the frames near them), microseconds.
double SeesMicroseconds(const synthetic::SyntheticStream& s, int frame, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const synthetic::Vec3 c = s.CameraCenter(frame);
  std::vector<synthetic::Vec3> points;
  for (int i = 0; i < 4000; ++i) {
    // A direction in the field of view, to the first surface within max_range.
    const synthetic::Vec3 dir = synthetic::Normalized({u(rng), 1.0, 0.35 * u(rng)});
    double t = 0.0;
    if (s.scene().Intersect(c, dir, s.options().max_range, &t))
      points.push_back(synthetic::Add(c, synthetic::Scale(dir, t * (1.0 - 1e-9))));
  }
  int seen = 0;
  const int rounds = 25;
  const auto t0 = Clock::now();
  for (int r = 0; r < rounds; ++r)
    for (const auto& p : points) seen += s.Sees(frame + r % 5, p);
  const double us = 1e6 * Seconds(t0, Clock::now()) / (rounds * points.size());
  if (seen < 0) std::printf("%d", seen);  // keep the loop
  return us;
}

struct Args {
  int frames = 20000;
  int keyframe_every = 5;
  uint64_t seed = 1;
  bool keep_truth = false;
  int track_frames = 17;
  double track_density = 2.1;
  double max_range = 40.0;
};


bool ParseStreamArgs(int argc, char** argv, Args* a, synthetic::StreamOptions* o, int* status) {
  Options opts("imr-bench stream",
               "usage: imr-bench stream [--frames 20000] [--keyframe-every 5] [--seed 1]\n"
               "         [--keep-truth] [--track-frames 17] [--track-density 2.1]\n"
               "         [--max-range 40]\n");
  opts.Int("--frames", &a->frames).Int("--keyframe-every", &a->keyframe_every);
  opts.Uint64("--seed", &a->seed).Flag("--keep-truth", &a->keep_truth);
  opts.Int("--track-frames", &a->track_frames).Double("--track-density", &a->track_density);
  opts.Double("--max-range", &a->max_range);
  if (!opts.Parse(argc, argv, status)) return false;
  o->frames = a->frames;  // configs/dense-street.json's input options
  o->keyframe_every = a->keyframe_every;
  o->seed = a->seed;
  o->keep_truth = a->keep_truth;
  o->track_frames = a->track_frames;
  o->track_density = a->track_density;
  o->max_range = a->max_range;
  o->noise_at_10m = 0.2;
  if (const std::string problem = o->Check(); !problem.empty() || a->frames < 100) {
    std::fprintf(stderr, "imr-bench stream: %s\n",
                 problem.empty() ? "--frames: expected >= 100" : problem.c_str());
    *status = 2;
    return false;
  }
  return true;
}

// What the drive measured per tenth and over the whole.
struct Drive {
  nlohmann::json tenths = nlohmann::json::array();
  double ms_first = 0.0, ms_last = 0.0, wall = 0.0;
  long rss_peak = 0;
};

// The generator over the whole drive, a row per tenth of its frames.
Drive RunTenths(synthetic::SyntheticStream& stream, int frames_total) {
  Drive d;
  synthetic::StreamKeyframe kf;
  const synthetic::StreamStats& st = stream.stats();
  int tenth = 0;
  int64_t f0 = 0, obs0 = 0, new0 = 0, mov0 = 0;
  size_t live_max = 0;
  double sec0 = 0.0;
  const auto t0 = Clock::now();
  while (stream.Next(&kf)) {
    live_max = std::max(live_max, st.active_tracks);
    const bool last = st.keyframes == stream.keyframe_count();
    if (st.frames * 10 < static_cast<int64_t>(tenth + 1) * frames_total && !last) continue;
    const double frames = static_cast<double>(st.frames - f0);
    const double ms = 1e3 * (st.seconds - sec0) / frames;
    const long rss = RssBytes();
    d.rss_peak = std::max(d.rss_peak, rss);
    if (tenth == 0) d.ms_first = ms;
    d.ms_last = ms;
    std::printf("| %d | %lld-%lld | %.2f | %.0f | %.1f | %.0f | %zu | %zu | %.1f |\n", tenth + 1,
                static_cast<long long>(f0), static_cast<long long>(st.frames - 1), ms,
                (st.observations - obs0) / frames, (st.new_points - new0) / frames,
                (st.moved_points - mov0) / frames, live_max, st.kept_truths, rss / 1e6);
    d.tenths.push_back({{"frames", frames}, {"ms_per_frame", ms},
                        {"observations_per_frame", (st.observations - obs0) / frames},
                        {"live_tracks_max", live_max}, {"rss_bytes", rss}});
    f0 = st.frames, obs0 = st.observations, new0 = st.new_points, mov0 = st.moved_points;
    sec0 = st.seconds;
    live_max = 0;
    ++tenth;
  }
  d.wall = Seconds(t0, Clock::now());
  return d;
}

// Mean track length in observations: of every track that ended, and of those reported (>= 2).
void TrackLengths(const synthetic::StreamStats& st, double* mean, double* reported_mean) {
  int64_t ended = 0, sum = 0, reported = 0, reported_sum = 0;
  for (size_t n = 1; n < st.track_lengths.size(); ++n) {
    ended += st.track_lengths[n];
    sum += static_cast<int64_t>(n) * st.track_lengths[n];
    if (n >= 2) {
      reported += st.track_lengths[n];
      reported_sum += static_cast<int64_t>(n) * st.track_lengths[n];
    }
  }
  *mean = ended ? static_cast<double>(sum) / ended : 0.0;
  *reported_mean = reported ? static_cast<double>(reported_sum) / reported : 0.0;
}

void PrintTotals(const Args& a, const synthetic::StreamStats& st, const Drive& d) {
  double mean = 0.0, reported_mean = 0.0;
  TrackLengths(st, &mean, &reported_mean);
  const double frames = static_cast<double>(st.frames);
  std::printf("\ntotal: %.1f s (%.2f ms per frame, generator only); %.0f observations per frame "
              "(%.0f from the 2nd observation on, as a SLAM JSON view lists them), %.1f new points "
              "and %.0f moves per frame; tracks %lld started, %lld lost before %d observations, "
              "mean length %.2f observations (%.2f of those reported); live tracks at most %zu; "
              "peak RSS %.1f MB (VmHWM %.1f MB); ms per frame last tenth / first tenth %.2f\n",
              d.wall, 1e3 * d.wall / frames, st.observations / frames,
              (st.observations - st.new_points) / frames, st.new_points / frames,
              st.moved_points / frames, static_cast<long long>(st.tracks_started),
              static_cast<long long>(st.tracks_lost), a.track_frames, mean, reported_mean,
              st.max_active_tracks, d.rss_peak / 1e6, PeakRssKb() / 1e3, d.ms_last / d.ms_first);
  std::printf("track lengths (observations: tracks):");
  for (size_t n = 1; n < st.track_lengths.size(); ++n)
    std::printf(" %zu: %lld", n, static_cast<long long>(st.track_lengths[n]));
  std::printf("\n");
}

}  // namespace

int RunStreamBench(int argc, char** argv) {
  Args a;
  synthetic::StreamOptions o;
  if (int status = 0; !ParseStreamArgs(argc, argv, &a, &o, &status)) return status;
  const long rss_start = RssBytes();
  const auto t_build = Clock::now();
  synthetic::SyntheticStream stream(o);
  stream.Sees(0, stream.CameraCenter(0));  // builds the scene's index
  const double build_seconds = Seconds(t_build, Clock::now());
  const long scene_bytes = RssBytes() - rss_start;
  const double sees_start = SeesMicroseconds(stream, 10, a.seed);
  const double sees_end = SeesMicroseconds(stream, a.frames - 10, a.seed);

  std::printf("imr-bench stream: %d frames, a keyframe every %d, track_frames %d, "
              "track_density %.2f, max_range %.0f, keep_truth %s, seed %llu\n%s, load %s\n\n",
              a.frames, a.keyframe_every, a.track_frames, a.track_density, a.max_range,
              a.keep_truth ? "true" : "false", static_cast<unsigned long long>(a.seed),
              MachineLine().c_str(), LoadAverage().c_str());
  std::printf("scene: %zu rects, built and indexed in %.1f ms, +%.1f MB resident; one Sees query "
              "%.2f us at frame 10, %.2f us at frame %d\n\n",
              stream.scene().rects().size(), 1e3 * build_seconds, scene_bytes / 1e6, sees_start,
              sees_end, a.frames - 10);
  MarkdownHeader({"tenth", "frames", "ms per frame", "observations per frame", "new per frame",
                  "moves per frame", "live tracks (max)", "true points kept", "RSS MB"});
  const Drive d = RunTenths(stream, a.frames);
  const synthetic::StreamStats& st = stream.stats();
  double track_mean = 0.0, reported_mean = 0.0;
  TrackLengths(st, &track_mean, &reported_mean);
  PrintTotals(a, st, d);
  const double frames = static_cast<double>(st.frames);
  const nlohmann::json j = {
      {"bench", "stream"},
      {"frames", a.frames},
      {"keyframe_every", a.keyframe_every},
      {"keep_truth", a.keep_truth},
      {"scene_rects", stream.scene().rects().size()},
      {"scene_build_seconds", build_seconds},
      {"sees_us_start", sees_start},
      {"sees_us_end", sees_end},
      {"seconds", d.wall},
      {"ms_per_frame", 1e3 * d.wall / frames},
      {"ms_per_frame_last_over_first_tenth", d.ms_last / d.ms_first},
      {"observations_per_frame", st.observations / frames},
      {"new_points_per_frame", st.new_points / frames},
      {"moves_per_frame", st.moved_points / frames},
      {"track_mean_length", track_mean},
      {"live_tracks_max", st.max_active_tracks},
      {"peak_rss_bytes", PeakRssKb() * 1024},
      {"tenths", d.tenths}};
  std::printf("%s\n", j.dump().c_str());
  return 0;
}

}  // namespace imr::bench
