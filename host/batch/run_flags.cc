#include "host/batch/run_flags.h"

#include "host/pipeline/stage_watch.h"
#include "host/util/strict_number.h"

#include <cstdio>

namespace imr::batch {
namespace {

using pipeline::RunOptions;

// A path template flag (--export-stream and the like): any text but the empty one.
RunFlag PathFlag(const char* name, const char* value_name, const char* help,
                 std::string RunOptions::*member) {
  return {name, value_name, help,
          [member](const std::string& text, RunOptions* o) -> std::string {
            if (text.empty()) return "the path must not be empty";
            o->*member = text;
            return "";
          },
          [member](const RunOptions& o) -> std::optional<std::string> {
            if ((o.*member).empty()) return std::nullopt;
            return o.*member;
          }};
}

std::vector<RunFlag> MakeFlags() {
  return {
      PathFlag("export-stream", "FILE",
               "also write the engine's input stream as SLAM JSON 0.3 (replayable)",
               &RunOptions::export_stream),
      PathFlag("export-colmap", "DIR",
               "also write the final points and their cameras as a COLMAP text model",
               &RunOptions::export_colmap),
      PathFlag("trace", "FILE", "per keyframe, one JSON line: points, cells, resident memory, times",
               &RunOptions::trace),
      {"check-invariants", "",
       "after every keyframe, check that the surface is a 2-manifold and the weights are "
       "consistent; stop the sequence naming the keyframe and the cell if not (slow)",
       [](const std::string&, RunOptions* o) -> std::string {
         o->check_invariants_every = 1;
         return "";
       },
       [](const RunOptions&) -> std::optional<std::string> { return std::nullopt; }},
      {"check-invariants-every", "N", "the same check after every N-th keyframe",
       [](const std::string& text, RunOptions* o) -> std::string {
         int n = 0;
         if (!ParseWholeInteger(text, &n) || n < 1)
           return "expected a number of keyframes >= 1, got '" + text + "'";
         o->check_invariants_every = n;
         return "";
       },
       [](const RunOptions& o) -> std::optional<std::string> {
         if (o.check_invariants_every <= 0) return std::nullopt;
         return std::to_string(o.check_invariants_every);
       }},
      {"threads", "N",
       "threads casting rays and planning moves in the engine (default: the job's "
       "engine.threads, else every core the process may run on; with --jobs J, the cores / J); "
       "the mesh is the same for any N",
       [](const std::string& text, RunOptions* o) -> std::string {
         int n = 0;
         if (!ParseWholeInteger(text, &n) || n < 1 || n > 1024)
           return "expected a number of threads in 1..1024, got '" + text + "'";
         o->threads = n;
         return "";
       },
       [](const RunOptions& o) -> std::optional<std::string> {
         if (o.threads <= 0) return std::nullopt;
         return std::to_string(o.threads);
       }},
      {"no-overlap", "",
       "make each keyframe of the image front end only when the engine asks for it (default, "
       "on 2 or more cores: the next keyframes are made while the engine applies this one)",
       [](const std::string&, RunOptions* o) -> std::string {
         o->overlap = false;
         return "";
       },
       [](const RunOptions& o) -> std::optional<std::string> {
         if (o.overlap) return std::nullopt;
         return std::string();
       }},
      {"stage-timeout", "SECONDS",
       "fail a sequence when a call into a plugin, or the engine's work on one keyframe, takes "
       "longer (a stage's timeout_seconds wins for its plugin; 0: no limit, the default)",
       [](const std::string& text, RunOptions* o) -> std::string {
         double seconds = 0.0;
         if (!ParseWholeDouble(text, &seconds))
           return pipeline::CheckStageTimeout(-1.0) + ", got '" + text + "'";
         if (std::string e = pipeline::CheckStageTimeout(seconds); !e.empty())
           return e + ", got " + text;
         o->stage_timeout = seconds;
         return "";
       },
       [](const RunOptions& o) -> std::optional<std::string> {
         if (!(o.stage_timeout > 0.0)) return std::nullopt;
         char seconds[32];
         std::snprintf(seconds, sizeof(seconds), "%.17g", o.stage_timeout);
         return std::string(seconds);
       }},
  };
}

}  // namespace

const std::vector<RunFlag>& RunFlags() {
  static const std::vector<RunFlag> flags = MakeFlags();
  return flags;
}

const RunFlag* FindRunFlag(const std::string& name) {
  for (const RunFlag& f : RunFlags())
    if (f.name == name) return &f;
  return nullptr;
}

std::vector<std::string> RunOptionsToArgs(const RunOptions& options) {
  std::vector<std::string> args;
  for (const RunFlag& f : RunFlags()) {
    const std::optional<std::string> v = f.value(options);
    if (!v) continue;
    args.push_back("--" + f.name);
    if (!f.value_name.empty()) args.push_back(*v);
  }
  return args;
}

std::vector<std::string> JobOverrideArgs(const std::vector<std::string>& overrides) {
  std::vector<std::string> args;
  for (const std::string& o : overrides) args.insert(args.end(), {"--set", o});
  return args;
}

}  // namespace imr::batch
