#include "host/batch/batch.h"

#include "host/batch/child.h"
#include "host/batch/manifest.h"
#include "host/batch/run_flags.h"
#include "host/batch/summary.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/host_services.h"
#include "host/util/clock.h"
#include "host/util/atomic_file.h"
#include "host/util/write_rule.h"
#include "host/util/file_lock.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"
#include "host/util/log.h"
#include "host/util/sha256.h"
#include "host/util/thread_pool.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>

namespace imr::batch {
namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {


// Seconds a running sequence has, after the batch's SIGTERM, to stop before it is killed.
constexpr int kCancelGraceSeconds = 10;

std::string Hostname() {
  char buf[256] = {};
  return ::gethostname(buf, sizeof(buf) - 1) == 0 ? std::string(buf) : std::string("?");
}

// A quoted line of a sequence list ("..." with C escapes) -> the name; false when malformed.
bool Unquote(const std::string& line, std::string* name) {
  name->clear();
  if (line.size() < 2 || line.front() != '"' || line.back() != '"') return false;
  for (std::size_t i = 1; i + 1 < line.size(); ++i) {
    const char c = line[i];
    if (c == '"') return false;
    if (c != '\\') {
      *name += c;
      continue;
    }
    if (++i + 1 >= line.size()) return false;
    switch (line[i]) {
      case '"': *name += '"'; break;
      case '\\': *name += '\\'; break;
      case 'n': *name += '\n'; break;
      case 'r': *name += '\r'; break;
      case 't': *name += '\t'; break;
      case 'x': {
        if (i + 3 >= line.size()) return false;
        const std::string hex = line.substr(i + 1, 2);
        if (hex.find_first_not_of("0123456789abcdefABCDEF") != std::string::npos) return false;
        *name += static_cast<char>(std::stoi(hex, nullptr, 16));
        i += 2;
        break;
      }
      default: return false;
    }
  }
  return true;
}

// Why a sequence whose manifest matches must still be redone because its input changed: the
// files of its source as report.json hashed them (input.checksums.files: the source file, or
// the files directly in its folder) are hashed again. Empty when they match, or when the report
// names none. Files in the source's subfolders (an image sequence's images) are not re-read.
std::string InputChanged(const fs::path& output, const std::string& source) {
  json files;
  try {
    InputStream in(output / "report.json", "the report of the last run", InputRole::kOwnOutput);
    const json report = json::parse(in);
    files = report.at("input").at("checksums").at("files");
  } catch (const std::exception&) {
    return {};
  }
  if (!files.is_object()) return {};
  std::error_code ec;
  const fs::path src(source);
  const bool one_file = fs::is_regular_file(src, ec);
  for (const auto& [name, sha] : files.items()) {
    if (!sha.is_string() || name.find("\\x") != std::string::npos) continue;  // a name kept as text
    const fs::path p = one_file ? src.parent_path() / name : src / name;
    if (!fs::is_regular_file(p, ec))
      return "its input " + p.string() + " is gone since the last run";
    if (Sha256File(p) != sha.get<std::string>())
      return "its input " + p.string() + " changed since the last run (SHA-256)";
  }
  return {};
}

std::string HolderOf(const fs::path& lock_file) {
  std::string who;
  const std::vector<pid_t> holders = LockHolders(lock_file);
  for (pid_t pid : holders) who += (who.empty() ? "pid " : ", pid ") + std::to_string(pid);
  std::string described;
  try {
    InputStream in(lock_file, "the batch's lock file", InputRole::kOwnOutput);
    std::getline(in, described);
  } catch (const std::runtime_error&) {
    // Unreadable (gone, or not a file): the holders' ids say it.
  }
  // "pid 4242 on host h, imr run since ...": the holder's own words, unless the holders seen
  // here are others (shards hold the lock shared and leave an earlier run's words in place).
  bool current = holders.empty();
  for (pid_t pid : holders) current = current || described.rfind("pid " + std::to_string(pid) + " ", 0) == 0;
  if (!described.empty() && current) return described;
  return who.empty() ? std::string("a process on another machine, or one that just ended")
                     : who + " on " + Hostname();
}

// One child running one sequence.
struct Running {
  std::size_t index = 0;  // into the job's sequences
  ChildProcess proc;
  LineBuffer out, msg;
  bool out_open = true, msg_open = true;
  LogTail tail{20};
  json result;
  RunningSequence shown;
  bool killed_for_memory = false;
  bool killed_after_cancel = false;
  uint64_t peak_rss = 0;
  bool exited = false;
  int wait_status = 0;
};

// Writes JSON lines to the parent, if there is one listening on fd 3.
class MessageChannel {
 public:
  MessageChannel() : ok_(::fcntl(kChildMessageFd, F_GETFD) != -1) {}
  void Send(const json& j) {
    // A stage timeout sends its result from the watchdog thread.
    std::lock_guard<std::mutex> lock(mutex_);
    if (!ok_) return;
    const std::string line = DumpJson(j) + "\n";
    for (std::size_t done = 0; done < line.size();) {
      const ssize_t n = ::write(kChildMessageFd, line.data() + done, line.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        ok_ = false;  // the parent is gone; the run goes on, its files say how it ended
        return;
      }
      done += static_cast<std::size_t>(n);
    }
  }

 private:
  std::mutex mutex_;
  bool ok_;
};

}  // namespace

const char* ToString(SequenceStatus s) {
  switch (s) {
    case SequenceStatus::kOk: return "ok";
    case SequenceStatus::kSkipped: return "skipped";
    case SequenceStatus::kFailed: return "failed";
    case SequenceStatus::kInterrupted: return "interrupted";
    case SequenceStatus::kNotRun: return "not run";
  }
  return "?";
}

std::string SequenceListLine(const std::string& name) {
  const bool plain = !name.empty() && name.front() != ' ' && name.front() != '\t' &&
                     name.front() != '#' && name.front() != '"' && name.back() != ' ' &&
                     name.back() != '\t' && IsUtf8(name) &&
                     std::none_of(name.begin(), name.end(),
                                  [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; });
  if (plain) return name;
  std::string q = "\"";
  for (const char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"') q += "\\\"";
    else if (c == '\\') q += "\\\\";
    else if (c == '\n') q += "\\n";
    else if (c == '\r') q += "\\r";
    else if (c == '\t') q += "\\t";
    else if (u < 0x20 || u == 0x7f || u >= 0x80) {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02x", u);
      q += hex;
    } else {
      q += c;
    }
  }
  return q + "\"";
}

std::vector<std::string> ReadSequenceList(const fs::path& file) {
  // The open rule: a FIFO or a device is refused by name; at most one byte past the bound is
  // read (a 2 GB file is not a list of names).
  std::string text = InputFile::Open(file, "a list of sequence names, one a line")
                         .ReadUpTo(kMaxSequenceListBytes + 1);
  if (text.size() > kMaxSequenceListBytes)
    throw std::runtime_error(file.string() + ": more than " +
                             std::to_string(kMaxSequenceListBytes >> 20) +
                             " MiB: not a sequence list (one name a line)");
  std::vector<std::string> names;
  int number = 0;
  for (std::size_t pos = 0; pos < text.size();) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    ++number;
    const std::string where = file.string() + ":" + std::to_string(number) + ": ";
    if (line.size() > kMaxSequenceListLine)
      throw std::runtime_error(where + std::to_string(line.size()) + " bytes, more than a name (" +
                               std::to_string(kMaxSequenceListLine) + " at most): " +
                               OneLine(line, 80));
    if (line.find('\0') != std::string::npos)
      throw std::runtime_error(where + "a NUL byte (not a text file?): " + OneLine(line, 80));
    const auto b = line.find_first_not_of(" \t\r");
    const auto e = line.find_last_not_of(" \t\r");
    if (b == std::string::npos || line[b] == '#') continue;
    line = line.substr(b, e - b + 1);
    if (line[0] != '"') {
      names.push_back(line);
      continue;
    }
    std::string name;
    if (!Unquote(line, &name))
      throw std::runtime_error(where + "a quoted name must be one \"...\" with the escapes \\\", "
                               "\\\\, \\n, \\r, \\t, \\xNN, got " + OneLine(line, 200));
    names.push_back(std::move(name));
  }
  return names;
}

class BatchLock {
 public:
  std::vector<FileLock> locks;
};

std::shared_ptr<BatchLock> LockBatchFolder(const fs::path& batch_dir, const Shard& shard) {
  const fs::path dir = batch_dir / kBatchSubdir;
  EnsureWritableDirectory(dir);
  auto lock = std::make_shared<BatchLock>();
  // A shard shares the folder with the other shards of its array, not with a whole run; two
  // runs of one shard exclude each other.
  std::vector<std::pair<fs::path, bool>> wanted = {{dir / "lock", !shard.active()}};
  if (shard.active())
    wanted.push_back({dir / ("lock-shard-" + std::to_string(shard.index) + "-of-" +
                             std::to_string(shard.count)), true});
  for (const auto& [file, exclusive] : wanted) {
    FileLock l = FileLock::TryLock(file, exclusive);
    if (l.busy())
      throw BatchFolderBusy(file.string() + ": another imr run (" + HolderOf(file) +
                            ") is using this batch folder " + batch_dir.string() +
                            "; wait for it to end, or stop it");
    if (!l.held()) {
      LogDebug(l.error() + " (running without the lock)");  // e.g. a file system without flock
      continue;
    }
    if (exclusive)
      l.Describe("pid " + std::to_string(::getpid()) + " on " + Hostname() + ", imr run since " +
                 UtcNow() + "\n");
    lock->locks.push_back(std::move(l));
  }
  return lock;
}

std::shared_ptr<BatchLock> HoldBatchFolderForReport(const fs::path& batch_dir) {
  const fs::path file = batch_dir / kBatchSubdir / "lock";
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return nullptr;  // never run (or not a batch folder)
  FileLock l = FileLock::TryLock(file, /*exclusive=*/true);
  if (l.busy())
    throw BatchFolderBusy(file.string() + ": an imr run (" + HolderOf(file) +
                          ") is using this batch folder " + batch_dir.string() +
                          "; nothing was written: run imr report when it has ended");
  if (!l.held()) {
    LogDebug(l.error() + " (reporting without the lock)");
    return nullptr;
  }
  auto lock = std::make_shared<BatchLock>();
  lock->locks.push_back(std::move(l));
  return lock;
}

int BatchRunResult::Count(SequenceStatus s) const {
  return static_cast<int>(std::count_if(outcomes.begin(), outcomes.end(),
                                        [s](const SequenceOutcome& o) { return o.status == s; }));
}

std::string BatchOptions::Check() const {
  if (jobs < 1 || jobs > 1024) return "--jobs must be in 1..1024, got " + std::to_string(jobs);
  if (std::string e = shard.Check(); !e.empty()) return "--shard: " + e;
  if (!(progress_interval > 0)) return "progress interval must be positive";
  if (executable.empty()) return "no imr executable for the child processes";
  return {};
}

std::vector<std::string> CheckBatch(const pipeline::ValidatedJob& v, const BatchOptions& o) {
  std::vector<std::string> problems;
  if (std::string e = o.Check(); !e.empty()) problems.push_back(e);
  if (!o.sequences_from.empty()) {
    try {
      std::set<std::string> known;
      for (const auto& s : v.sequences) known.insert(s.name);
      for (const auto& n : ReadSequenceList(o.sequences_from))
        if (!known.count(n))
          problems.push_back("--sequences-from " + o.sequences_from.string() + ": '" +
                             OneLine(n, 200) + "' is not a sequence of the job");
    } catch (const std::exception& e) {
      problems.push_back(std::string("--sequences-from: ") + e.what());
    }
  }
  const fs::path reserved = BatchDirectory(v.job) / kBatchSubdir;
  for (const auto& s : v.sequences) {
    const fs::path out = fs::absolute(v.job.OutputDirectory(s.name)).lexically_normal();
    const fs::path rel = out.lexically_relative(reserved);
    if (!rel.empty() && *rel.begin() != "..")
      problems.push_back("sequence '" + s.name + "': its output folder " + out.string() +
                         " is inside the batch folder's own " + reserved.string());
  }
  return problems;
}

void RecordBatch(const pipeline::ValidatedJob& v, const plugin::PluginRegistry& registry,
                 const pipeline::RunOptions& run_options) {
  BatchInfo info;
  info.job_file = fs::absolute(v.job.file).lexically_normal();
  info.job_name = v.job.Name();
  info.output_stem = v.job.output.stem;
  for (const auto& s : v.sequences)
    info.sequences.push_back(
        {s.name, s.source, fs::absolute(v.job.OutputDirectory(s.name)).lexically_normal(),
         HashIdentity(JobIdentity(v, registry, run_options, s))});
  WriteBatchInfo(BatchDirectory(v.job), info);
}

namespace {

// Which sequences this process runs, as indices into the job's: the frozen list
// (--sequences-from), then this process's shard of it.
std::vector<std::size_t> SelectSequences(const pipeline::ValidatedJob& v,
                                         const BatchOptions& options) {
  std::vector<std::size_t> candidates;
  if (options.sequences_from.empty()) {
    for (std::size_t i = 0; i < v.sequences.size(); ++i) candidates.push_back(i);
  } else {
    std::set<std::string> listed;
    for (const auto& n : ReadSequenceList(options.sequences_from)) listed.insert(n);
    for (std::size_t i = 0; i < v.sequences.size(); ++i)
      if (listed.count(v.sequences[i].name)) candidates.push_back(i);
  }
  std::vector<std::string> names;
  for (std::size_t i : candidates) names.push_back(v.sequences[i].name);
  std::vector<std::size_t> selected;
  for (std::size_t k : SelectShard(names, options.shard)) selected.push_back(candidates[k]);
  if (options.shard.active())
    LogInfo("shard " + options.shard.ToString() +
            (options.shard_origin.empty() ? "" : " (" + options.shard_origin + ")") + ": " +
            std::to_string(selected.size()) + " of " + std::to_string(candidates.size()) +
            " sequences");
  return selected;
}

// The selected sequences run J at a time, each in a child process: started in order (or skipped
// when finished), watched (output, messages, memory, a cancel), and each outcome recorded in the
// batch folder as it ends.
class SequenceRunner {
 public:
  SequenceRunner(const pipeline::ValidatedJob& v, const plugin::PluginRegistry& registry,
                 const pipeline::RunOptions& run_options, const BatchOptions& options,
                 const fs::path& batch_dir, std::vector<std::size_t> selected)
      : v_(v), registry_(registry), run_options_(run_options), options_(options),
        batch_dir_(batch_dir), selected_(std::move(selected)),
        display_(options.progress, options.progress_interval), host_(Hostname()) {
    shown_.total = static_cast<int>(selected_.size());
  }

  // Until every selected sequence has ended, or a cancel has stopped the running ones.
  void RunAll();
  // The outcomes in the order of the selection; a sequence a cancel kept from starting is
  // "not run".
  std::vector<SequenceOutcome> Outcomes() const;

 private:
  void Say(LogLevel level, const std::string& m);
  void Record(const SequenceOutcome& o);
  void Write(const StatusRecord& r, const char* what);
  bool SkipIfFinished(std::size_t index, const std::string& position, SequenceOutcome* o);
  void StartNext();
  void HandleOutput(Running& r, const std::string& line);
  void HandleMessage(Running& r, const std::string& line);
  void Drain(Running& r, bool to_end);
  void Finish(Running& r);
  void DescribeFailure(const Running& r, SequenceOutcome* o) const;
  void CancelIfAsked();
  void ReapAndWatchMemory();

  const pipeline::ValidatedJob& v_;
  const plugin::PluginRegistry& registry_;
  const pipeline::RunOptions& run_options_;
  const BatchOptions& options_;
  const fs::path batch_dir_;
  const std::vector<std::size_t> selected_;
  ProgressDisplay display_;
  const std::string host_;
  BatchProgress shown_;
  std::map<std::size_t, SequenceOutcome> outcomes_;
  std::vector<std::unique_ptr<Running>> running_;
  std::size_t next_ = 0;
  bool cancelled_ = false;
  Clock::time_point cancelled_at_;
};

void SequenceRunner::Say(LogLevel level, const std::string& m) {
  if (level != LogLevel::kError && static_cast<int>(level) < static_cast<int>(GetLogLevel())) return;
  display_.Clear();
  Log(level, m);
}

void SequenceRunner::Record(const SequenceOutcome& o) {
  StatusRecord r;
  r.sequence = o.name;
  r.status = ToString(o.status);
  r.seconds = o.seconds;
  r.error = o.detail;
  r.exit_code = o.exit_code;
  r.signal = o.signal != 0 ? SignalName(o.signal) : "";
  r.log_tail = o.log_tail;
  r.warnings = o.warnings;
  r.host = host_;
  r.finished_at = UtcNow();
  Write(r, "outcome");
}

// A record the batch cannot write is said, and the batch goes on.
void SequenceRunner::Write(const StatusRecord& r, const char* what) {
  try {
    WriteStatusRecord(batch_dir_, r);
  } catch (const std::exception& e) {
    Say(LogLevel::kError,
        std::string("cannot record the ") + what + " of " + r.sequence + ": " + e.what());
  }
}

// A sequence whose manifest matches (and whose input did not change) is skipped and recorded so;
// otherwise *o says why it runs.
bool SequenceRunner::SkipIfFinished(std::size_t index, const std::string& position,
                                    SequenceOutcome* o) {
  const pipeline::SequenceRef& seq = v_.sequences[index];
  if (options_.force) {
    o->detail = "--force";
    return false;
  }
  const json identity = JobIdentity(v_, registry_, run_options_, seq);
  const ManifestCheck check = CheckManifest(o->output_directory, HashIdentity(identity), identity);
  const std::string changed =
      check.up_to_date ? InputChanged(o->output_directory, seq.source) : std::string();
  if (check.up_to_date && changed.empty()) {
    o->status = SequenceStatus::kSkipped;
    o->detail = "up to date (" + check.reason + ")";
    Say(LogLevel::kInfo, position + seq.name + ": skipped, " + o->detail);
    Record(*o);
    ++shown_.done;
    ++shown_.skipped;
    outcomes_[index] = *o;
    return true;
  }
  o->detail = changed.empty() ? check.reason : changed;
  return false;
}

void SequenceRunner::StartNext() {
  const std::size_t index = selected_[next_++];
  const pipeline::SequenceRef& seq = v_.sequences[index];
  SequenceOutcome o;
  o.name = seq.name;
  o.output_directory = v_.job.OutputDirectory(seq.name);
  const std::string position =
      "[" + std::to_string(next_) + "/" + std::to_string(selected_.size()) + "] ";
  if (SkipIfFinished(index, position, &o)) return;
  Say(LogLevel::kInfo, position + seq.name + ": running (" + o.detail + ")");
  // Until it ends, the record says where and when it started: a run killed with it (a time
  // limit, SIGKILL) then shows as interrupted, not as its previous outcome.
  StatusRecord started;
  started.sequence = seq.name;
  started.status = "running";
  started.host = host_;
  started.started_at = UtcNow();
  Write(started, "start");
  std::vector<std::string> argv = {options_.executable, kChildCommand,
                                   "--job", fs::absolute(v_.job.file).string(),
                                   "--sequence", seq.name,
                                   "--parent-pid", std::to_string(::getpid())};
  for (std::string& a : JobOverrideArgs(v_.job.overrides)) argv.push_back(std::move(a));
  // J sequences at once share the cores: each engine gets cores / J threads (not J x cores).
  pipeline::RunOptions child_options = run_options_;
  if (child_options.threads <= 0 && options_.jobs > 1)
    child_options.threads = std::max(1, util::AvailableCores() / options_.jobs);
  for (std::string& a : RunOptionsToArgs(child_options)) argv.push_back(std::move(a));
  if (options_.verbose) argv.push_back("-v");
  auto r = std::make_unique<Running>();
  r->index = index;
  r->shown = {seq.name, {}, Clock::now()};
  try {
    r->proc = SpawnChild(argv);
  } catch (const std::exception& e) {
    o.status = SequenceStatus::kFailed;
    o.detail = e.what();
    Record(o);
    ++shown_.done;
    ++shown_.failed;
    outcomes_[index] = o;
    return;
  }
  outcomes_[index] = o;
  running_.push_back(std::move(r));
}

void SequenceRunner::HandleOutput(Running& r, const std::string& line) {
  r.tail.Add(line);
  const std::string& name = v_.sequences[r.index].name;
  const std::string shown_line =
      line.find("[" + name + "]") != std::string::npos ? line : "[" + name + "] " + line;
  if (options_.verbose)
    Say(LogLevel::kInfo, shown_line);
  else if (line.rfind("warning: ", 0) == 0) {
    const std::string text = line.substr(9);
    Say(LogLevel::kWarning,
        text.find("[" + name + "]") != std::string::npos ? text : "[" + name + "] " + text);
  }
}

void SequenceRunner::HandleMessage(Running& r, const std::string& line) {
  try {
    const json m = json::parse(line);
    if (m.contains("progress")) {
      const json& p = m["progress"];
      r.shown.progress = {p.at(0).get<int>(), p.at(1).get<int>(), p.at(2).get<int>()};
    } else if (m.contains("result")) {
      r.result = m["result"];
    } else if (m.contains("note")) {
      Say(LogLevel::kInfo, m["note"].get<std::string>());  // RunOptions::note, already "[name] ..."
    }
  } catch (const std::exception&) {
    r.tail.Add("(unreadable message from the child: " + line + ")");
  }
}

void SequenceRunner::Drain(Running& r, bool to_end) {
  std::string line;
  if (r.out_open) {
    r.out_open = ReadAvailable(r.proc.output_fd, &r.out);
    while (r.out.Next(&line, to_end || !r.out_open)) HandleOutput(r, line);
  }
  if (r.msg_open) {
    r.msg_open = ReadAvailable(r.proc.message_fd, &r.msg);
    while (r.msg.Next(&line, to_end || !r.msg_open)) HandleMessage(r, line);
  }
}

// A failure's cause: the child's own error, or how its process ended.
void SequenceRunner::DescribeFailure(const Running& r, SequenceOutcome* o) const {
  const int st = r.wait_status;
  o->log_tail = r.tail.Lines();
  if (r.result.is_object() && r.result.contains("warnings") && r.result["warnings"].is_array())
    for (const json& w : r.result["warnings"])
      if (w.is_string()) o->warnings.push_back(w.get<std::string>());
  if (WIFEXITED(st)) {
    o->exit_code = WEXITSTATUS(st);
    o->detail = r.result.is_object() && r.result.contains("error")
                    ? r.result["error"].get<std::string>()
                    : "the sequence's process exited with status " + std::to_string(o->exit_code) +
                          " without a result";
  } else if (WIFSIGNALED(st)) {
    o->signal = WTERMSIG(st);
    if (r.killed_for_memory)
      o->detail = "killed: resident memory reached " + FormatBytes(r.peak_rss) +
                  ", over --max-rss " + FormatBytes(options_.max_rss);
    else if (cancelled_)
      o->detail = "cancelled (" + DescribeSignal(o->signal) + ")";
    else
      o->detail = "crashed: " + DescribeSignal(o->signal);
    if (!o->log_tail.empty() && !r.killed_for_memory)
      o->detail += "; last log line: " + o->log_tail.back();
  }
}

// A child has ended: its outcome (ok, interrupted by the batch's cancel, or failed), recorded.
void SequenceRunner::Finish(Running& r) {
  Drain(r, true);
  ::close(r.proc.output_fd);
  ::close(r.proc.message_fd);
  SequenceOutcome& o = outcomes_[r.index];
  o.seconds = SecondsSince(r.shown.started);
  o.peak_rss = r.peak_rss;
  const int st = r.wait_status;
  const bool result_ok = r.result.is_object() && r.result.value("ok", false);
  // Stopped by the batch's cancel (the child ended on the signal, or reports it stopped for
  // it): interrupted, not failed. A failure of its own, reported as such, stays a failure.
  const bool stopped = cancelled_ && !result_ok &&
                       (WIFSIGNALED(st) || !r.result.is_object() || r.result.value("cancelled", false));
  if (WIFEXITED(st) && WEXITSTATUS(st) == 0 && result_ok) {
    o.status = SequenceStatus::kOk;
    o.detail.clear();
  } else if (stopped) {
    o.status = SequenceStatus::kInterrupted;
    const int sig = plugin::CancelSignal();
    o.detail = std::string("interrupted: imr run was stopped") +
               (sig != 0 ? " by " + SignalName(sig) : std::string()) + " while the sequence ran" +
               (r.killed_after_cancel ? " (it did not stop within " +
                                            std::to_string(kCancelGraceSeconds) +
                                            " s of SIGTERM and was killed)"
                                      : "");
    if (WIFSIGNALED(st)) o.signal = WTERMSIG(st);
    if (WIFEXITED(st)) o.exit_code = WEXITSTATUS(st);
  } else {
    o.status = SequenceStatus::kFailed;
    DescribeFailure(r, &o);
  }
  Record(o);
  ++shown_.done;
  if (o.status == SequenceStatus::kFailed) {
    ++shown_.failed;
    Say(LogLevel::kError, o.name + " failed: " + o.detail);
  } else if (o.status == SequenceStatus::kInterrupted) {
    Say(LogLevel::kWarning, o.name + ": " + o.detail);
  } else {
    char took[32];
    std::snprintf(took, sizeof(took), "%.2f s", o.seconds);
    Say(LogLevel::kInfo, o.name + ": done in " + took);
  }
}

// Ctrl-C, SIGTERM or SIGHUP: no more sequences start and the running ones get SIGTERM; a
// sequence stuck in a plugin call cannot act on it, so it is killed after the grace period.
void SequenceRunner::CancelIfAsked() {
  if (!cancelled_ && plugin::CancelRequested()) {
    cancelled_ = true;
    cancelled_at_ = Clock::now();
    const int sig = plugin::CancelSignal();
    Say(LogLevel::kWarning, std::string("cancelled") + (sig != 0 ? " (" + SignalName(sig) + ")" : "") +
                                ": no more sequences start; stopping the running ones");
    for (auto& r : running_) ::kill(r->proc.pid, SIGTERM);
  }
  if (cancelled_ && SecondsSince(cancelled_at_) > kCancelGraceSeconds)
    for (auto& r : running_)
      if (!r->killed_after_cancel) {
        r->killed_after_cancel = true;
        ::kill(r->proc.pid, SIGKILL);
      }
}

// Finishes the children that have ended; kills one over --max-rss.
void SequenceRunner::ReapAndWatchMemory() {
  for (auto it = running_.begin(); it != running_.end();) {
    Running& r = **it;
    const pid_t w = ::waitpid(r.proc.pid, &r.wait_status, WNOHANG);
    if (w == r.proc.pid) {
      Finish(r);
      it = running_.erase(it);
      continue;
    }
    if (options_.max_rss > 0) {
      if (auto rss = ResidentBytes(r.proc.pid)) {
        r.peak_rss = std::max(r.peak_rss, *rss);
        if (*rss > options_.max_rss && !r.killed_for_memory) {
          r.killed_for_memory = true;
          ::kill(r.proc.pid, SIGKILL);
        }
      }
    }
    ++it;
  }
}

void SequenceRunner::RunAll() {
  if (display_.mode() == ProgressMode::kBar) display_.Update(shown_, true);
  for (;;) {
    CancelIfAsked();
    while (!cancelled_ && running_.size() < static_cast<std::size_t>(options_.jobs) &&
           next_ < selected_.size())
      StartNext();
    if (running_.empty() && (cancelled_ || next_ >= selected_.size())) break;

    std::vector<pollfd> fds;
    for (auto& r : running_) {
      if (r->out_open) fds.push_back({r->proc.output_fd, POLLIN, 0});
      if (r->msg_open) fds.push_back({r->proc.message_fd, POLLIN, 0});
    }
    ::poll(fds.data(), fds.size(), 100);
    for (auto& r : running_) Drain(*r, false);
    ReapAndWatchMemory();
    shown_.running.clear();
    for (auto& r : running_) shown_.running.push_back(r->shown);
    display_.Update(shown_);
  }
  shown_.running.clear();
  display_.Update(shown_, true);
  display_.Clear();
}

std::vector<SequenceOutcome> SequenceRunner::Outcomes() const {
  std::vector<SequenceOutcome> out;
  for (std::size_t i : selected_) {
    auto it = outcomes_.find(i);
    if (it != outcomes_.end()) {
      out.push_back(it->second);
    } else {
      SequenceOutcome o;
      o.name = v_.sequences[i].name;
      o.output_directory = v_.job.OutputDirectory(o.name);
      o.detail = "not started (cancelled)";
      out.push_back(o);
    }
  }
  return out;
}

// The batch summary and the viewer page, for a whole run (a shard's are `imr report`'s).
void Summarise(const BatchOptions& options, BatchRunResult* result) {
  try {
    const nlohmann::json summary = WriteSummary(result->batch_directory, "imr run");
    result->summary_written = true;
    if (options.viewer_page)
      result->viewer_page = WriteViewerPage(result->batch_directory, summary);
  } catch (const std::exception& e) {
    LogError(std::string("cannot write the batch summary: ") + e.what());
  }
}

}  // namespace

// The steps of a batch: record it, select this process's sequences, run them (skipping the
// finished ones, recording each outcome), summarise.
BatchRunResult RunBatch(const pipeline::ValidatedJob& v, const plugin::PluginRegistry& registry,
                        const pipeline::RunOptions& run_options, const BatchOptions& options) {
  BatchRunResult result;
  result.batch_directory = BatchDirectory(v.job);
  RecordBatch(v, registry, run_options);
  SequenceRunner runner(v, registry, run_options, options, result.batch_directory,
                        SelectSequences(v, options));
  runner.RunAll();
  result.outcomes = runner.Outcomes();
  if (!options.shard.active()) Summarise(options, &result);
  return result;
}

namespace {

// The body of RunSequenceChild: `fail` reports a failure (and returns the exit status).
int RunOneChild(const ChildArguments& args, MessageChannel& channel,
                const std::function<int(const std::string&)>& fail) {
  // The batch already logged the plugin scan's warnings; once is enough.
  SetLogLevel(LogLevel::kError);
  plugin::PluginRegistry registry;
  const pipeline::ValidatedJob v = pipeline::LoadAndValidateJob(args.job, &registry, args.overrides);
  SetLogLevel(args.verbose ? LogLevel::kDebug : LogLevel::kInfo);
  if (!v.ok()) return fail(args.job.string() + " is no longer valid: " + v.problems[0].ToString());
  const auto seq = std::find_if(v.sequences.begin(), v.sequences.end(),
                                [&](const pipeline::SequenceRef& s) { return s.name == args.sequence; });
  if (seq == v.sequences.end()) return fail("the job has no sequence '" + args.sequence + "' any more");

  const fs::path output = v.job.OutputDirectory(seq->name);
  // Files another job or tool wrote are never replaced or deleted.
  if (const std::string foreign = ForeignOutputs(output, v.job.file, seq->name); !foreign.empty())
    return fail(foreign);
  // One process writes an output folder at a time (two jobs, or two runs, sharing it).
  EnsureWritableDirectory(output);
  const FileLock lock = FileLock::TryLock(output, true);
  if (lock.busy()) {
    std::string who;
    for (pid_t pid : LockHolders(output)) who += (who.empty() ? " (pid " : ", pid ") + std::to_string(pid);
    return fail(output.string() + ": another imr process" + (who.empty() ? "" : who + ")") +
                " is writing into this output folder; wait for it to end");
  }
  const json identity = JobIdentity(v, registry, args.run_options, *seq);
  // Redoing: the old manifest goes first (its files are being replaced), with what a killed run
  // left behind. Its file list is kept to remove files this run no longer writes, if this job
  // wrote it (an older imr's manifest names no job: its files are left alone). What it names
  // this run may replace, whatever their bytes now are (a damaged output is redone).
  std::string error;
  const std::optional<Manifest> old = ReadManifest(output, &error);
  const std::string this_job = ManifestJob(v.job.file, output);
  InputScope claims;
  if (old && old->job == this_job)
    for (const auto& e : old->files) claims.Claim(EntryPath(e, output));
  // Nothing is removed for a run that may not write its outputs (the write rule: an input of the
  // run, a user's file where a mesh would go).
  {
    InputScope inputs;
    pipeline::NoteJobInputs(v, *seq, &inputs);
    if (const std::string why = pipeline::WhyNotWritableOutputs(v, args.run_options, *seq);
        !why.empty())
      return fail(why + "; nothing ran");
  }
  std::error_code ec;
  claims.Claim(output / kManifestFile);
  if (std::string why; !RemoveWrittenFile(output / kManifestFile, &why))
    return fail(why + "; nothing ran");
  if (const int n = RemoveLeftovers(output); n > 0)
    LogInfo("[" + seq->name + "] removed " + std::to_string(n) + " leftover(s) of an interrupted run");

  pipeline::RunOptions run_options = args.run_options;
  auto last = Clock::now() - std::chrono::seconds(1);
  run_options.progress = [&](const pipeline::SequenceProgress& p) {
    // At most 10 messages a second, and always the last keyframe.
    if (p.keyframes != p.total_keyframes && SecondsSince(last) < 0.1) return;
    last = Clock::now();
    channel.Send({{"progress", {p.keyframes, p.total_keyframes, p.frame}}});
  };
  run_options.note = [&](const std::string& line) { channel.Send({{"note", line}}); };
  // A hung plugin cannot be unwound: report like any failure, clear what the stalled write
  // leaves (staging folders, temporaries) and end the process.
  run_options.on_stage_timeout = [&](const std::string& message) {
    LogError("sequence " + seq->name + " failed: " + message);
    channel.Send({{"result", {{"ok", false}, {"error", message}}}});
    RemoveLeftovers(output);
    std::_Exit(pipeline::kStageTimeoutExitCode);
  };
  const pipeline::SequenceResult r = pipeline::RunOneSequence(v, registry, run_options, *seq);
  if (!r.ok) {
    // The outputs of this job's earlier run were being replaced: without a manifest they would
    // look whole, so they go too (only the files imr wrote, RemoveWrittenFile).
    if (old && old->job == this_job)
      for (const auto& e : old->files)
        if (!fs::path(e.path).is_absolute()) RemoveWrittenFile(output / e.path);
    channel.Send({{"result",
                   {{"ok", false},
                    {"error", r.error},
                    {"warnings", r.warnings},
                    {"cancelled", plugin::CancelRequested()}}}});
    return 1;
  }
  try {
    std::vector<fs::path> files = r.extra_files;
    files.insert(files.end(), r.files.begin(), r.files.end());
    Manifest m = MakeManifest(seq->name, identity, files, output, BatchDirectory(v.job));
    m.job = this_job;
    WriteManifest(m, output);
    if (old && old->job == this_job) {
      std::set<std::string> kept;
      for (const auto& e : m.files) kept.insert(e.path);
      for (const auto& e : old->files)
        if (!kept.count(e.path) && !fs::path(e.path).is_absolute()) RemoveWrittenFile(output / e.path);
    }
  } catch (const std::exception& e) {
    return fail(std::string("cannot write the manifest: ") + e.what());
  }
  channel.Send({{"result", {{"ok", true}, {"seconds", r.seconds}}}});
  return 0;
}

}  // namespace

int RunSequenceChild(const ChildArguments& args) {
  if (args.parent_pid > 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != args.parent_pid) return 1;  // the batch died before prctl
  }
  SetLogLevel(args.verbose ? LogLevel::kDebug : LogLevel::kInfo);
  MessageChannel channel;
  auto fail = [&](const std::string& error) {
    LogError("sequence " + JsonText(args.sequence) + " failed: " + JsonText(error));
    channel.Send({{"result", {{"ok", false}, {"error", error}, {"cancelled", plugin::CancelRequested()}}}});
    return 1;
  };
  // Whatever goes wrong reaches the batch with its message (it used to be lost: "exited with
  // status 1 without a result").
  try {
    return RunOneChild(args, channel, fail);
  } catch (const std::exception& e) {
    return fail(e.what());
  }
}

}  // namespace imr::batch
