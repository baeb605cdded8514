#include "host/batch/slurm.h"

#include "host/batch/batch.h"
#include "host/batch/child.h"
#include "host/batch/run_flags.h"
#include "host/batch/summary.h"
#include "host/util/atomic_file.h"
#include "host/util/json_text.h"

#include <strings.h>
#include <sys/stat.h>

#include <algorithm>
#include <sstream>

namespace imr::batch {
namespace fs = std::filesystem;

namespace {

std::string Join(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& w : words) s += (s.empty() ? "" : " ") + ShellQuote(w);
  return s;
}

// "Submitted batch job 123" with --parsable is "123" or "123;cluster".
std::string ParseJobId(const std::string& out) {
  std::string id = out.substr(0, out.find_first_of(";\n"));
  if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos)
    throw std::runtime_error("sbatch printed no job id: '" + out + "'");
  return id;
}

// An #SBATCH option's value as sbatch reads it. When it holds a blank, a quote, '\' or '#' (a
// comment, even inside quotes in older Slurm): in double quotes (a backslash cannot escape a
// blank), with '"', '\' and '#' escaped by a backslash, which sbatch drops; otherwise as it is.
// `pattern`: a file name in which Slurm expands %-patterns (%A, %a, %j): a literal '%' is "%%".
std::string SbatchValue(const std::string& value, bool pattern = false) {
  const bool quote = value.find_first_of(" \t\"'\\#") != std::string::npos;
  std::string out = quote ? "\"" : "";
  for (const char c : value) {
    if (c == '"' || c == '\\' || c == '#') out += '\\';
    out += c;
    if (pattern && c == '%') out += '%';
  }
  return quote ? out + "\"" : out;
}

bool IsControl(char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }
bool HasControl(const std::string& s) { return std::any_of(s.begin(), s.end(), IsControl); }

// A word of a script's command line, for bash: ShellQuote's, or, when it holds a control
// character (a newline would end the line and start a command of its own), ANSI-C quoted
// ($'...' with \xNN): every command of the script stays on its own line.
std::string ScriptWord(const std::string& word) {
  if (!HasControl(word)) return ShellQuote(word);
  std::string q = "$'";
  for (const char c : word) {
    if (c == '\'' || c == '\\') {
      q += '\\';
      q += c;
    } else if (IsControl(c)) {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02x", static_cast<unsigned>(static_cast<unsigned char>(c)));
      q += hex;
    } else {
      q += c;
    }
  }
  return q + "'";
}

std::string ScriptLine(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& w : words) s += (s.empty() ? "" : " ") + ScriptWord(w);
  return s;
}

bool Digits(const std::string& s, std::size_t max_digits = 9) {
  return !s.empty() && s.size() <= max_digits &&
         s.find_first_not_of("0123456789") == std::string::npos;
}

// A time limit as sbatch --time reads it: minutes, minutes:seconds, hours:minutes:seconds,
// days-hours, days-hours:minutes, days-hours:minutes:seconds, or UNLIMITED / INFINITE.
bool IsSlurmTime(const std::string& t) {
  if (::strcasecmp(t.c_str(), "UNLIMITED") == 0 || ::strcasecmp(t.c_str(), "INFINITE") == 0)
    return true;
  std::string rest = t;
  if (const std::size_t dash = t.find('-'); dash != std::string::npos) {
    if (!Digits(t.substr(0, dash))) return false;
    rest = t.substr(dash + 1);
  }
  int parts = 0;
  for (std::size_t pos = 0;; ++parts) {
    const std::size_t colon = std::min(rest.find(':', pos), rest.size());
    if (!Digits(rest.substr(pos, colon - pos))) return false;
    if (colon == rest.size()) break;
    pos = colon + 1;
  }
  return parts <= 2;
}

// A memory size as sbatch --mem reads it: a whole number of megabytes, or with a unit K, M, G
// or T.
bool IsSlurmMemory(const std::string& m) {
  if (m.empty()) return false;
  const bool unit = std::string("KMGTkmgt").find(m.back()) != std::string::npos;
  return Digits(unit ? m.substr(0, m.size() - 1) : m, 15);
}

// A value that reaches a script: none of its characters may end the line.
std::string CheckScriptValue(const char* option, const std::string& value) {
  if (value.empty()) return std::string(option) + ": expected a value, got ''";
  if (HasControl(value))
    return std::string(option) + ": '" + OneLine(value, 200) +
           "' holds a control character (a newline would end the #SBATCH line): not a Slurm value";
  return {};
}

std::string SubmitScript(const std::vector<std::string>& command) {
  std::string out, err;
  const int status = RunAndCapture(command, &out, &err);
  if (status != 0)
    throw std::runtime_error(Join(command) + " failed (status " + std::to_string(status) + "): " +
                             (err.empty() ? out : err));
  return ParseJobId(out);
}

}  // namespace

std::string SubmitOptions::Check() const {
  if (tasks < 1) return "--tasks must be at least 1, got " + std::to_string(tasks);
  if (cpus_per_task < 1) return "--cpus-per-task must be at least 1";
  if (jobs < 0) return "--jobs must be at least 1";
  if (executable.empty()) return "no imr executable for the tasks";
  for (const auto& [option, value] : {std::pair{"--partition", &partition},
                                      std::pair{"--account", &account}, std::pair{"--qos", &qos}})
    if (!value->empty())
      if (std::string e = CheckScriptValue(option, *value); !e.empty()) return e;
  if (!time.empty() && !IsSlurmTime(time))
    return "--time: expected a Slurm time limit (minutes, M:S, H:M:S, D-H, D-H:M or D-H:M:S, or "
           "UNLIMITED), got '" + OneLine(time, 200) + "'";
  if (!mem.empty() && !IsSlurmMemory(mem))
    return "--mem: expected a memory size in megabytes, or with a unit K, M, G or T (e.g. 8G), "
           "got '" + OneLine(mem, 200) + "'";
  for (const std::string& a : sbatch_args) {
    if (std::string e = CheckScriptValue("--sbatch-arg", a); !e.empty()) return e;
    if (a[0] != '-')
      return "--sbatch-arg: expected an sbatch option (e.g. --constraint=avx2), got '" +
             OneLine(a, 200) + "'";
  }
  return {};
}

std::string CheckScriptPaths(const std::filesystem::path& batch_directory) {
  if (HasControl(batch_directory.string()))
    return "the batch folder " + OneLine(batch_directory.string(), 400) +
           " holds a control character in its name: Slurm cannot write the tasks' logs there "
           "(#SBATCH --output); choose another output.directory";
  return {};
}

SubmitResult Submit(const pipeline::ValidatedJob& v, const plugin::PluginRegistry& registry,
                    const pipeline::RunOptions& run_options, const SubmitOptions& o) {
  SubmitResult r;
  r.batch_directory = BatchDirectory(v.job);
  const fs::path batch = r.batch_directory / kBatchSubdir;
  const fs::path slurm = batch / "slurm";
  r.log_directory = slurm / "logs";
  EnsureWritableDirectory(r.log_directory);
  RecordBatch(v, registry, run_options);

  // The frozen list: tasks that start hours apart shard the same set.
  if (std::string e = CheckScriptPaths(r.batch_directory); !e.empty()) throw std::invalid_argument(e);
  std::string list = "# the sequences of " + OneLine(fs::absolute(v.job.file).string()) +
                     " when `imr submit` ran; the array tasks shard this list (names that need it\n"
                     "# are in double quotes, with C escapes)\n";
  for (const auto& s : v.sequences) list += SequenceListLine(s.name) + "\n";
  const fs::path list_file = batch / "sequences.txt";
  WriteFileAtomically(list_file, list);

  r.tasks = std::min<int>(o.tasks, static_cast<int>(v.sequences.size()));
  const std::string job_file = fs::absolute(v.job.file).lexically_normal().string();
  // The job's name, a label: a control character in the job file's name becomes '?'.
  std::string name = "imr-" + v.job.Name();
  std::replace_if(name.begin(), name.end(), IsControl, '?');
  const int jobs = o.jobs > 0 ? o.jobs : o.cpus_per_task;

  std::vector<std::string> run = {o.executable, "run", job_file, "--sequences-from",
                                  list_file.string(), "--jobs", std::to_string(jobs)};
  if (o.max_rss > 0) {
    run.push_back("--max-rss");
    run.push_back(std::to_string(o.max_rss));
  }
  if (o.force) run.push_back("--force");
  for (std::string& a : JobOverrideArgs(v.job.overrides)) run.push_back(std::move(a));
  for (std::string& a : RunOptionsToArgs(run_options)) run.push_back(std::move(a));

  auto common = [&](std::ostringstream& s) {
    if (!o.partition.empty()) s << "#SBATCH --partition=" << SbatchValue(o.partition) << "\n";
    if (!o.account.empty()) s << "#SBATCH --account=" << SbatchValue(o.account) << "\n";
    if (!o.qos.empty()) s << "#SBATCH --qos=" << SbatchValue(o.qos) << "\n";
  };
  const std::string cwd = fs::current_path().string();
  std::ostringstream a;
  a << "#!/bin/bash\n"
    << "# imr array job, written by `imr submit` (imr " << pipeline::Version() << ") at "
    << UtcNow() << ".\n"
    << "# Job " << OneLine(job_file) << ": " << v.sequences.size() << " sequences in " << r.tasks
    << " tasks. Each task runs `imr run` on its\n"
    << "# share of " << OneLine(list_file.string()) << " (its shard comes from SLURM_ARRAY_TASK_ID,\n"
    << "# SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_MIN); each sequence runs in a child process.\n"
    << "# Submitting this script again redoes only what is not finished: sequences whose\n"
    << "# manifest matches are skipped. Then run `imr report " << OneLine(r.batch_directory.string())
    << "`.\n"
    << "#SBATCH --job-name=" << SbatchValue(name) << "\n"
    << "#SBATCH --array=0-" << (r.tasks - 1) << "\n"
    << "#SBATCH --output=" << SbatchValue(r.log_directory.string(), true) << "/array-%A_%a.out\n"
    << "#SBATCH --cpus-per-task=" << o.cpus_per_task << "\n";
  common(a);
  if (!o.time.empty()) a << "#SBATCH --time=" << o.time << "\n";
  if (!o.mem.empty()) a << "#SBATCH --mem=" << o.mem << "\n";
  for (const auto& extra : o.sbatch_args) a << "#SBATCH " << extra << "\n";
  a << "set -eu\n"
    << "cd " << ScriptWord(cwd) << "  # where imr submit ran: relative export paths resolve here\n"
    << "exec " << ScriptLine(run) << "\n";
  r.array_script = slurm / "array.sbatch";
  WriteFileAtomically(r.array_script, a.str());
  ::chmod(r.array_script.c_str(), 0755);

  std::ostringstream b;
  b << "#!/bin/bash\n"
    << "# imr reduce job, written by `imr submit`: after every task of the array has ended (however\n"
    << "# it ended), merge the sequences' reports into " << (r.batch_directory / "summary.md").string()
    << "\n# and summary.json. It exits with 1 when a sequence failed or did not run.\n"
    << "#SBATCH --job-name=" << SbatchValue(name) << "-report\n"
    << "#SBATCH --output=" << SbatchValue(r.log_directory.string(), true) << "/report-%j.out\n"
    << "#SBATCH --cpus-per-task=1\n";
  common(b);
  if (!o.time.empty()) b << "#SBATCH --time=" << o.time << "\n";
  b << "set -eu\n"
    << "exec " << ScriptLine({o.executable, "report", r.batch_directory.string()}) << "\n";
  r.reduce_script = slurm / "report.sbatch";
  WriteFileAtomically(r.reduce_script, b.str());
  ::chmod(r.reduce_script.c_str(), 0755);

  r.array_command = {o.sbatch, "--parsable", r.array_script.string()};
  r.reduce_command = {o.sbatch, "--parsable", "--dependency=afterany:<array job id>",
                      r.reduce_script.string()};
  if (o.dry_run) return r;
  r.array_job_id = SubmitScript(r.array_command);
  r.reduce_command[2] = "--dependency=afterany:" + r.array_job_id;
  r.reduce_job_id = SubmitScript(r.reduce_command);
  return r;
}

}  // namespace imr::batch
