// The frame every imr-bench subcommand runs in, so that a bench is its inputs and its rows: its
// options declared once (Options), its work folder (WorkFolder), the team's data folder
// (SharedDir), imr run on a job with its wall time, peak RSS and report (RunImrJob), Markdown
// tables (MarkdownHeader, MarkdownRow) and the figures' formatting (Format).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace imr::bench {

// A bench's command line: each option declared with where its value goes. Parse refuses an
// unknown option, a missing value and a value that is not of its kind, naming the option and
// what was expected, with the bench's usage and its exit status (2 unless told).
class Options {
 public:
  Options(std::string prefix, std::string usage, int error_status = 2);

  Options& Flag(const std::string& name, bool* to, bool value = true);
  Options& Int(const std::string& name, int* to);
  Options& Uint64(const std::string& name, uint64_t* to);
  Options& Double(const std::string& name, double* to);
  Options& String(const std::string& name, std::string* to);
  Options& Path(const std::string& name, std::filesystem::path* to);
  // "a,b,c" (or words apart with `separator` ' ') into `to`, replacing what was there.
  Options& List(const std::string& name, std::vector<std::string>* to, char separator = ',');
  // "1,2,4" into `to`, replacing what was there; each number at least `min`.
  Options& IntList(const std::string& name, std::vector<int>* to, int min);
  // A flag that does more than set one bool.
  Options& Action(const std::string& name, std::function<void()> act);
  // A value checked by `take`: it returns "" when it took the value, else what was expected.
  Options& Custom(const std::string& name, std::function<std::string(const std::string&)> take);

  // Reads argv (without the subcommand). False when the bench is to stop: *status is then 0 for
  // --help (the usage printed to stdout) or the error status (the problem printed to stderr).
  bool Parse(int argc, char** argv, int* status) const;

 private:
  struct Option {
    std::string name;
    bool takes_value = false;
    std::function<std::string(const std::string&)> take;  // "" or what was expected
  };
  Options& Add(const std::string& name, bool takes_value,
               std::function<std::string(const std::string&)> take);

  std::string prefix_, usage_;
  int error_status_;
  std::vector<Option> options_;
};

// The folder a bench's runs write to: `given` (kept), or a new one under the temp folder named
// "imr-bench-NAME-PID" (removed by Finish unless `keep`).
class WorkFolder {
 public:
  WorkFolder(const std::string& given, const std::string& bench);
  const std::filesystem::path& path() const { return path_; }
  bool given() const { return given_; }
  // Removes a folder made here when `remove` holds (a bench keeps it after a failure).
  void Finish(bool remove = true) const;

 private:
  std::filesystem::path path_;
  bool given_;
};

// The team's shared folder (data/, paper/): `given`, else $IMR_SHARED_DIR, else the one beside
// this source tree.
std::filesystem::path SharedDir(const std::string& given = "");

// The KITTI raw sample of the shared folder (data/kitti-raw-2011_09_26-traffic), unless `given`.
std::string KittiRawSample(const std::string& given = "");

// A file's bytes ("" when it cannot be read).
std::string ReadFileBytes(const std::filesystem::path& p);
// Writes `j` (indented by 2) to `p`, the way every bench writes its job files.
void WriteJson(const std::filesystem::path& p, const nlohmann::json& j);

// A python3 that imports matplotlib (for the benches' plots), or "".
std::string FindPython();

// printf into a string.
std::string Format(const char* format, ...) __attribute__((format(printf, 1, 2)));

// "| a | b |\n|---|---|\n".
void MarkdownHeader(const std::vector<std::string>& columns);
// "| a | b |\n".
void MarkdownRow(const std::vector<std::string>& cells);

// imr run on one job: where the job goes, what else is on the command line.
struct ImrJob {
  std::filesystem::path job_file;        // written here; the log beside it (.log) unless `log`
  std::filesystem::path log;
  std::string imr;                       // default: the imr beside imr-bench
  std::string before;                    // words before imr (e.g. "taskset -c 0 ")
  std::string args = "-q";               // after `run`, before the job file
  std::string extra;                     // after the job file
};
// What it gave: the exit status (0 ok), wall time and peak RSS of the imr process, and the
// report.json of the job's output folder (null when missing).
struct ImrJobResult {
  int status = -1;
  double seconds = 0.0;
  double peak_rss_mb = 0.0;
  nlohmann::json report;
  std::filesystem::path log;
  bool ok() const { return status == 0 && report.is_object(); }
};
ImrJobResult RunImrJob(const nlohmann::json& job, const ImrJob& how);

}  // namespace imr::bench
