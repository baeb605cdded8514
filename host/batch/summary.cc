#include "host/batch/summary.h"

#include "host/batch/manifest.h"
#include "host/report/viewer_page.h"
#include "host/util/atomic_file.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"
#include "host/util/log.h"
#include "host/util/sha256.h"

#include <unistd.h>

#include <cctype>
#include <cmath>
#include <ctime>
#include <fstream>
#include <sstream>

namespace imr::batch {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json ReadJson(const fs::path& p) {
  // The open rule: a FIFO or a device in imr's place is refused by name, never waited on.
  const std::string text = ReadInputFile(p, "a JSON file imr wrote", kDefaultMaxInputBytes,
                                         InputRole::kOwnOutput);
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    throw std::runtime_error(p.string() + ": malformed JSON: " + e.what());
  }
}

fs::path StatusPath(const fs::path& batch_dir, const std::string& sequence) {
  return batch_dir / kBatchSubdir / "status" / StatusFileName(sequence);
}

// A path stored relative to the batch folder when it is inside it (the folder may be moved).
std::string RelativeToBatch(const fs::path& path, const fs::path& batch_dir) {
  const fs::path abs = fs::absolute(path).lexically_normal();
  const fs::path rel = abs.lexically_relative(fs::absolute(batch_dir).lexically_normal());
  const bool inside = !rel.empty() && *rel.begin() != "..";
  return inside ? rel.string() : abs.string();
}

json OrNull(const json& j, const json::json_pointer& p) {
  return j.contains(p) ? j.at(p) : json();
}

// Markdown table cells: no pipes or line breaks.
std::string Cell(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  std::string out;
  for (char c : s) out += c == '|' ? std::string("\\|") : std::string(1, c);
  return out;
}

std::string Number(const json& v, const char* format) {
  if (!v.is_number()) return "";
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v.get<double>());
  return buf;
}

std::string Bytes(uint64_t b) {
  char buf[32];
  if (b >= (1u << 20))
    std::snprintf(buf, sizeof(buf), "%.1f MiB", static_cast<double>(b) / (1 << 20));
  else
    std::snprintf(buf, sizeof(buf), "%.0f KiB", static_cast<double>(b) / 1024);
  return buf;
}

}  // namespace

std::string StatusFileName(const std::string& sequence) {
  // Names of letters, digits, '.', '_', '-' and ' ' (not starting with '.') are kept; others
  // (a '/', a newline, bytes that are not UTF-8, 200 characters) become a readable prefix and a
  // hash of the name, which always fits in NAME_MAX with the temporaries of atomic writes.
  const bool plain = !sequence.empty() && sequence[0] != '.' && sequence.size() <= 100 &&
                     sequence.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                                "0123456789._- ") == std::string::npos;
  if (plain) return sequence + ".json";
  std::string prefix;
  for (char c : sequence.substr(0, 48)) prefix += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return prefix + "-" + Sha256Hex(sequence).substr(0, 16) + ".json";
}

std::string CountsSentence(const json& c) {
  const int n = c.at("sequences").get<int>();
  std::string s = std::to_string(n) + (n == 1 ? " sequence: " : " sequences: ") +
                  std::to_string(c.at("ok").get<int>()) + " ok";
  if (const int r = c.value("reused", 0); r > 0)
    s += " (" + std::to_string(r) + " from an earlier run)";
  s += ", " + std::to_string(c.at("failed").get<int>()) + " failed";
  if (const int i = c.value("interrupted", 0); i > 0) s += ", " + std::to_string(i) + " interrupted";
  if (const int r = c.value("not_run", 0); r > 0) s += ", " + std::to_string(r) + " not run";
  return s;
}

std::filesystem::path WriteViewerPage(const std::filesystem::path& batch_dir, const json& summary) {
  for (const char* entry : {"index.html", "assets"})
    if (const std::string foreign = io::ForeignBatchEntry(batch_dir, entry); !foreign.empty()) {
      LogWarning("viewer page not written: " + foreign + ": imr does not overwrite a file it did "
                 "not write");
      return {};
    }
  try {
    const report::ViewerPageResult page = report::WriteBatchPage(batch_dir, summary);
    for (const std::string& note : page.notes) LogWarning("viewer page: " + note);
    for (const std::string& line : page.info) LogInfo("viewer page: " + line);
    return page.page;
  } catch (const std::exception& e) {
    LogWarning(std::string("viewer page not written: ") + e.what());
    return {};
  }
}

std::string UtcNow() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

fs::path BatchDirectory(const io::JobSpec& job) { return job.BatchDirectory(); }

void WriteBatchInfo(const fs::path& batch_dir, const BatchInfo& info) {
  // Names and paths are bytes (PutBytes); outputs inside the batch folder are stored relative to
  // it, so that a batch folder moved elsewhere still finds them.
  json seqs = json::array();
  for (const auto& s : info.sequences) {
    json e = json::object();
    PutBytes(e, "name", s.name);
    PutBytes(e, "source", s.source);
    PutBytes(e, "output", RelativeToBatch(s.output, batch_dir));
    e["job_hash"] = s.job_hash;
    seqs.push_back(std::move(e));
  }
  json j = {{"imr_batch", 1}, {"output_stem", info.output_stem}, {"sequences", seqs}};
  PutBytes(j, "job", info.job_file.string());
  PutBytes(j, "job_name", info.job_name);
  EnsureWritableDirectory(batch_dir / kBatchSubdir);
  // No timestamps: concurrent array tasks write the same bytes.
  WriteFileAtomically(batch_dir / kBatchSubdir / "batch.json", DumpJson(j, 2) + "\n");
}

BatchInfo ReadBatchInfo(const fs::path& batch_dir) {
  const fs::path p = batch_dir / kBatchSubdir / "batch.json";
  std::error_code ec;
  if (!fs::exists(p, ec))
    throw std::runtime_error(p.string() + ": not found: " + batch_dir.string() +
                             " is not a batch folder of imr run or imr submit");
  const json j = ReadJson(p);
  BatchInfo info;
  try {
    info.job_file = GetBytes(j, "job");
    info.job_name = GetBytes(j, "job_name");
    info.output_stem = j.value("output_stem", "mesh");
    for (const json& s : j.at("sequences")) {
      const fs::path output = GetBytes(s, "output");
      info.sequences.push_back({GetBytes(s, "name"), GetBytes(s, "source"),
                                output.is_absolute() ? output : (batch_dir / output).lexically_normal(),
                                s.at("job_hash").get<std::string>()});
    }
  } catch (const json::exception& e) {
    throw std::runtime_error(p.string() + ": " + e.what());
  }
  return info;
}

void WriteStatusRecord(const fs::path& batch_dir, const StatusRecord& r) {
  json j = {{"status", r.status}, {"host", r.host}};
  PutBytes(j, "sequence", r.sequence);
  if (r.status == "running") {
    j["started_at"] = r.started_at;
  } else {
    j["seconds"] = r.seconds;
    j["finished_at"] = r.finished_at;
  }
  if (r.status == "failed" || r.status == "interrupted") {
    j["error"] = r.error;
    j["exit_code"] = r.exit_code >= 0 ? json(r.exit_code) : json();
    j["signal"] = r.signal.empty() ? json() : json(r.signal);
    j["log_tail"] = r.log_tail;
    if (!r.warnings.empty()) j["warnings"] = r.warnings;
  }
  EnsureWritableDirectory(StatusPath(batch_dir, r.sequence).parent_path());
  WriteFileAtomically(StatusPath(batch_dir, r.sequence), DumpJson(j, 2) + "\n");
}

json BuildSummary(const fs::path& batch_dir) {
  const BatchInfo info = ReadBatchInfo(batch_dir);
  json rows = json::array();
  int ok = 0, reused = 0, failed = 0, interrupted = 0, not_run = 0;
  for (const BatchSequence& s : info.sequences) {
    json row = {{"reused", false},     {"seconds", nullptr}, {"frames", nullptr},
                {"keyframes", nullptr}, {"mesh", nullptr},    {"accuracy", nullptr},
                {"error", nullptr}};
    PutBytes(row, "name", s.name);
    PutBytes(row, "source", s.source);
    PutBytes(row, "output", RelativeToBatch(s.output, batch_dir));
    json record = json::object();
    const fs::path record_path = StatusPath(batch_dir, s.name);
    std::error_code ec;
    if (fs::exists(record_path, ec)) {
      try {
        record = ReadJson(record_path);
      } catch (const std::exception& e) {
        record = {{"status", "failed"}, {"error", e.what()}};
      }
    }
    const std::string recorded = record.value("status", "");
    const ManifestCheck check = CheckManifest(s.output, s.job_hash);
    if (check.up_to_date) {
      row["status"] = "ok";
      row["reused"] = recorded == "skipped";
      ++ok;
      reused += recorded == "skipped" ? 1 : 0;
      const fs::path report_path = s.output / "report.json";
      try {
        const json report = ReadJson(report_path);
        row["seconds"] = OrNull(report, "/seconds"_json_pointer);
        json frames = OrNull(report, "/input/summary/frames_processed"_json_pointer);
        if (frames.is_null()) frames = OrNull(report, "/input/options/frames"_json_pointer);
        row["frames"] = frames;
        row["keyframes"] = OrNull(report, "/engine/keyframes"_json_pointer);
        std::string error;
        uint64_t bytes = 0;
        if (auto m = ReadManifest(s.output, &error))
          for (const ManifestEntry& e : m->files)
            if (fs::path(e.path).stem() == info.output_stem && !fs::path(e.path).has_parent_path())
              bytes += e.bytes;
        row["mesh"] = {{"vertices", OrNull(report, "/mesh/vertices"_json_pointer)},
                       {"faces", OrNull(report, "/mesh/faces"_json_pointer)},
                       {"bytes", bytes}};
        row["accuracy"] = OrNull(report, "/accuracy"_json_pointer);
        if (const json w = OrNull(report, "/warnings"_json_pointer); w.is_array() && !w.empty())
          row["warnings"] = w;
      } catch (const std::exception& e) {
        row["error"] = e.what();
      }
    } else if (recorded == "failed") {
      row["status"] = "failed";
      ++failed;
      row["seconds"] = record.value("seconds", json());
      row["error"] = record.value("error", "failed");
      for (const char* k : {"exit_code", "signal", "log_tail", "host", "finished_at", "warnings"})
        if (record.contains(k)) row[k] = record[k];
    } else if (recorded == "interrupted") {
      // Stopped by a signal to the batch (Ctrl-C, SIGTERM, SIGHUP): not a failure of its own.
      row["status"] = "interrupted";
      ++interrupted;
      row["seconds"] = record.value("seconds", json());
      row["error"] = record.value("error", "interrupted");
      row["host"] = record.value("host", json());
    } else if (recorded == "running") {
      row["status"] = "interrupted";
      ++interrupted;
      row["error"] = "started on " + record.value("host", std::string("?")) + " at " +
                     record.value("started_at", std::string("?")) +
                     " and never ended: its process was killed (SIGKILL, a time limit, a lost "
                     "node), or it is still running";
      row["host"] = record.value("host", json());
    } else if (recorded == "ok" || recorded == "skipped") {
      // It finished, but its outputs no longer match its manifest.
      row["status"] = "failed";
      ++failed;
      row["error"] = "outputs changed after the run: " + check.reason;
    } else {
      row["status"] = "not run";
      ++not_run;
    }
    rows.push_back(std::move(row));
  }
  json summary = {{"imr_summary", 1},
                  {"counts", {{"sequences", info.sequences.size()}, {"ok", ok}, {"reused", reused},
                              {"failed", failed}, {"interrupted", interrupted}, {"not_run", not_run}}},
                  {"sequences", rows}};
  PutBytes(summary, "job", info.job_file.string());
  PutBytes(summary, "job_name", info.job_name);
  PutBytes(summary, "batch_directory", fs::absolute(batch_dir).lexically_normal().string());
  return summary;
}

std::string SummaryMarkdown(const json& s) {
  std::ostringstream md;
  const json& c = s.at("counts");
  md << "# imr batch summary: " << s.value("job_name", "") << "\n\n";
  md << "Job `" << s.value("job", "") << "`, batch folder `" << s.value("batch_directory", "")
     << "`";
  if (s.contains("written_by"))
    md << ", written by `" << s["written_by"].get<std::string>() << "` at "
       << s.value("written_at", "");
  md << ".\n\n";
  md << CountsSentence(c) << ".\n\n";
  md << "Accuracy: the mean distance truth → mesh (from each ground-truth point to the nearest "
        "triangle; scene units) and the completeness at τ (share of the ground truth within τ "
        "of the mesh), the ground truth cropped to what the cameras saw; each report.json's "
        "`accuracy` gives τ and the crop.\n\n";
  md << "| sequence | status | frames | keyframes | time (s) | triangles | mesh files | "
        "mean distance truth → mesh | completeness at τ | error |\n";
  md << "|---|---|---:|---:|---:|---:|---:|---:|---:|---|\n";
  for (const json& r : s.at("sequences")) {
    std::string status = r.value("status", "");
    if (r.value("reused", false)) status += " (earlier run)";
    std::string faces, bytes;
    if (r["mesh"].is_object()) {
      faces = r["mesh"]["faces"].is_number() ? std::to_string(r["mesh"]["faces"].get<long long>()) : "";
      bytes = Bytes(r["mesh"].value("bytes", uint64_t{0}));
    }
    std::string mean, completeness;
    if (r["accuracy"].is_object()) {
      const json& a = r["accuracy"];
      mean = Number(a.contains("mean_truth_to_mesh") ? a["mean_truth_to_mesh"] : a.value("mean", json()), "%.4f");
      completeness = Number(a.value("completeness", json()), "%.3f");
    }
    std::string error = r["error"].is_string() ? r["error"].get<std::string>() : "";
    if (error.size() > 160) error = error.substr(0, 157) + "...";
    md << "| " << Cell(r.value("name", "")) << " | " << status << " | "
       << (r["frames"].is_number() ? std::to_string(r["frames"].get<long long>()) : "") << " | "
       << (r["keyframes"].is_number() ? std::to_string(r["keyframes"].get<long long>()) : "")
       << " | " << Number(r["seconds"], "%.2f") << " | " << faces << " | " << bytes << " | "
       << mean << " | " << completeness << " | " << Cell(error) << " |\n";
  }
  bool heading = false;
  for (const json& r : s.at("sequences")) {
    if (r.value("status", "") != "failed") continue;
    if (!heading) md << "\n## Failures\n";
    heading = true;
    md << "\n### " << Cell(r.value("name", "")) << "\n\n" << r.value("error", "") << "\n";
    if (r.contains("signal") && r["signal"].is_string())
      md << "\nEnded by " << r["signal"].get<std::string>() << ".\n";
    else if (r.contains("exit_code") && r["exit_code"].is_number())
      md << "\nExit status " << r["exit_code"].get<int>() << ".\n";
    if (r.contains("log_tail") && !r["log_tail"].empty()) {
      md << "\nLast log lines:\n\n```\n";
      for (const json& l : r["log_tail"]) md << l.get<std::string>() << "\n";
      md << "```\n";
    }
  }
  heading = false;
  for (const json& r : s.at("sequences")) {
    if (!r.contains("warnings") || !r["warnings"].is_array()) continue;
    if (!heading) md << "\n## Warnings\n";
    heading = true;
    md << "\n### " << Cell(r.value("name", "")) << "\n\n";
    for (const json& w : r["warnings"])
      if (w.is_string()) md << "- " << w.get<std::string>() << "\n";
  }
  // A cut error message may end inside a UTF-8 sequence: the page stays valid text.
  return JsonText(md.str());
}

json WriteSummary(const fs::path& batch_dir, const std::string& written_by) {
  if (const std::string foreign = io::ForeignBatchFiles(batch_dir, false); !foreign.empty())
    throw std::runtime_error(foreign);
  json s = BuildSummary(batch_dir);
  s["written_by"] = written_by;
  s["written_at"] = UtcNow();
  WriteFileAtomically(batch_dir / "summary.json", DumpJson(s, 2) + "\n");
  WriteFileAtomically(batch_dir / "summary.md", SummaryMarkdown(s));
  return s;
}

}  // namespace imr::batch
