#include "host/batch/manifest.h"

#include "host/util/sha256.h"
#include "host/io/engine_options.h"
#include "host/util/atomic_file.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"

#include <algorithm>
#include <fstream>
#include <sstream>

namespace imr::batch {
namespace fs = std::filesystem;
using nlohmann::json;

json JobIdentity(const pipeline::ValidatedJob& v, const plugin::PluginRegistry& registry,
                 const pipeline::RunOptions& options, const pipeline::SequenceRef& seq) {
  const io::JobSpec& job = v.job;
  json stages = json::array();
  for (std::size_t i = 0; i < job.pipeline.size(); ++i) {
    const io::StageSpec& s = job.pipeline[i];
    const plugin::PluginInfo* info = registry.Find(s.plugin);
    stages.push_back({{"kind", s.kind},
                      {"plugin", s.plugin},
                      {"version", info != nullptr ? info->version() : std::string("?")},
                      {"params", i < v.stage_params.size() ? v.stage_params[i] : s.params}});
  }
  json exports = json::object();
  if (!options.export_stream.empty())
    exports["stream"] = fs::absolute(pipeline::ExpandExportPath(options.export_stream, v, seq.name)).string();
  if (!options.export_colmap.empty())
    exports["colmap"] = fs::absolute(pipeline::ExpandExportPath(options.export_colmap, v, seq.name)).string();
  // A trace is an output too: asking for one redoes a sequence that was run without it.
  if (!options.trace.empty())
    exports["trace"] = fs::absolute(pipeline::ExpandExportPath(options.trace, v, seq.name)).string();
  // nlohmann's objects keep keys sorted, so dump() is canonical.
  json identity = {{"imr", pipeline::Version()},
          {"sequence", {{"name", seq.name}, {"source", seq.source}}},
          {"input", {{"format", job.input.format}, {"options", v.input_options}}},
          {"engine", io::EngineOptionsToJson(v.engine_options)},
          {"pipeline", stages},
          {"output", {{"stem", job.output.stem},
                      {"formats", job.output.formats},
                      {"snapshot_every", job.output.snapshot_every}}},
          {"evaluation", v.evaluation},
          {"exports", exports}};
  // --set overrides change the fields above already; naming them also makes a changed --set
  // (even one that restates the job's value) redo the sequence. Absent without overrides, so
  // runs without --set keep their hashes.
  if (!job.overrides.empty()) identity["overrides"] = job.overrides;
  // Likewise tiles: absent when the job asks for none.
  if (!v.tiles.is_null()) identity["output"]["tiles"] = v.tiles;
  return identity;
}

std::string HashIdentity(const json& identity) { return Sha256Hex(DumpJson(identity)); }

fs::path EntryPath(const ManifestEntry& e, const fs::path& output_directory) {
  const fs::path p(e.path);
  return p.is_absolute() ? p : output_directory / p;
}

namespace {

// Whether `path` (absolute, normal) is `dir` or inside it.
bool Inside(const fs::path& path, const fs::path& dir) {
  const fs::path rel = path.lexically_relative(dir);
  return !rel.empty() && *rel.begin() != "..";
}

json ReadJsonFile(const fs::path& p) {
  // The open rule: a FIFO or a device in imr's place is refused by name, never waited on.
  return json::parse(ReadInputFile(p, "a manifest imr wrote", kDefaultMaxInputBytes,
                                   InputRole::kOwnOutput));
}

}  // namespace

std::string ManifestJob(const fs::path& job_file, const fs::path& output_directory) {
  return fs::absolute(job_file)
      .lexically_normal()
      .lexically_relative(fs::absolute(output_directory).lexically_normal())
      .string();
}

Manifest MakeManifest(const std::string& sequence, const json& identity,
                      const std::vector<fs::path>& files, const fs::path& output_directory,
                      const fs::path& relative_within) {
  Manifest m;
  m.sequence = sequence;
  m.job_identity = identity;
  m.job_hash = HashIdentity(identity);
  const fs::path base = fs::absolute(output_directory).lexically_normal();
  const fs::path within =
      relative_within.empty() ? base : fs::absolute(relative_within).lexically_normal();
  for (const fs::path& f : files) {
    const fs::path abs = fs::absolute(f).lexically_normal();
    ManifestEntry e;
    e.path = Inside(abs, within) ? abs.lexically_relative(base).string() : abs.string();
    std::error_code ec;
    e.bytes = fs::file_size(abs, ec);
    if (ec) throw std::runtime_error(abs.string() + ": " + ec.message());
    e.sha256 = Sha256File(abs);
    m.files.push_back(std::move(e));
  }
  return m;
}

void WriteManifest(const Manifest& m, const fs::path& output_directory) {
  json files = json::array();
  for (const auto& e : m.files) {
    json f = {{"bytes", e.bytes}, {"sha256", e.sha256}};
    PutBytes(f, "path", e.path);
    files.push_back(std::move(f));
  }
  json j = {{"imr_manifest", 1},
            {"job_hash", m.job_hash},
            {"job_identity", m.job_identity},
            {"files", files}};
  PutBytes(j, "sequence", m.sequence);
  if (!m.job.empty()) PutBytes(j, "job", m.job);
  WriteFileAtomically(output_directory / kManifestFile, DumpJson(j, 2) + "\n");
}

std::optional<Manifest> ReadManifest(const fs::path& output_directory, std::string* error) {
  const fs::path p = output_directory / kManifestFile;
  std::error_code ec;
  if (!fs::exists(p, ec)) return std::nullopt;
  try {
    const json j = ReadJsonFile(p);
    Manifest m;
    m.sequence = GetBytes(j, "sequence");
    if (j.contains("job")) m.job = GetBytes(j, "job");
    m.job_hash = j.at("job_hash").get<std::string>();
    m.job_identity = j.value("job_identity", json());
    for (const json& f : j.at("files"))
      m.files.push_back({GetBytes(f, "path"), f.at("bytes").get<uint64_t>(),
                         f.at("sha256").get<std::string>()});
    return m;
  } catch (const std::exception& e) {
    *error = p.string() + ": unreadable manifest: " + e.what();
    return std::nullopt;
  }
}

ManifestCheck CheckManifest(const fs::path& output_directory, const std::string& job_hash,
                            const json& identity) {
  std::string error;
  const std::optional<Manifest> m = ReadManifest(output_directory, &error);
  if (!m) return {false, error.empty() ? "no manifest: not finished by an earlier run" : error};
  if (m->job_hash != job_hash) {
    // Name the parts of the job that changed, when both identities are known.
    std::string what;
    if (identity.is_object() && m->job_identity.is_object())
      for (const auto& [key, value] : identity.items())
        if (!m->job_identity.contains(key) || m->job_identity[key] != value)
          what += (what.empty() ? "" : ", ") + key;
    return {false, "the job changed since the last run" + (what.empty() ? "" : " (" + what + ")")};
  }
  for (const ManifestEntry& e : m->files) {
    const fs::path p = EntryPath(e, output_directory);
    std::error_code ec;
    const uint64_t size = fs::file_size(p, ec);
    if (ec) return {false, e.path + " is missing"};
    if (size != e.bytes || Sha256File(p) != e.sha256)
      return {false, e.path + " changed since it was written (checksum)"};
  }
  return {true, "manifest matches"};
}

std::string ForeignOutputs(const fs::path& output_directory, const fs::path& job_file,
                           const std::string& sequence) {
  const fs::path job = fs::absolute(job_file).lexically_normal();
  const std::string advice = "; give each job its own output folder (e.g. {job} in "
                             "output.directory), or remove the file if it is not needed";
  std::error_code ec;
  const fs::path manifest = output_directory / kManifestFile;
  if (fs::exists(manifest, ec)) {
    json j;
    try {
      j = ReadJsonFile(manifest);
    } catch (const std::exception&) {
    }
    if (!j.is_object() || !j.contains("imr_manifest"))
      return manifest.string() + ": not a manifest of imr (no \"imr_manifest\" key): imr would "
             "overwrite it" + advice;
    std::string recorded;
    try {
      if (j.contains("job")) recorded = GetBytes(j, "job");
    } catch (const std::exception&) {
    }
    if (!recorded.empty() && recorded != ManifestJob(job, output_directory)) {
      const fs::path other = (fs::absolute(output_directory) / recorded).lexically_normal();
      return manifest.string() + ": written by another job (" + other.string() + "), not by " +
             job.string() + ": two jobs share this output folder, and each would delete or "
             "overwrite the other's files" + advice;
    }
    return {};  // this job's (or an imr manifest that names no job: an older imr's)
  }
  const fs::path report = output_directory / "report.json";
  if (fs::exists(report, ec)) {
    json j;
    try {
      j = ReadJsonFile(report);
    } catch (const std::exception&) {
    }
    const bool ours = j.is_object() && j.contains("imr_version") && j.contains("sequence") &&
                      j["sequence"].is_object() && j["sequence"].value("name", "") == JsonText(sequence) &&
                      j.value("job", "") == JsonText(job.string());
    if (!ours)
      return report.string() + ": not a report of this job's sequence '" + sequence + "' (" +
             job.string() + "): imr would overwrite it" + advice;
  }
  return {};
}

int RemoveLeftovers(const fs::path& output_directory) {
  int removed = 0;
  for (const fs::path& dir : {output_directory, output_directory / "snapshots", output_directory / "tiles"}) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    std::vector<fs::path> doomed;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const std::string name = e.path().filename().string();
      if (name.rfind(".imr-staging-", 0) == 0 ||
          (name.size() > 1 && name[0] == '.' && name.find(".tmp-") != std::string::npos))
        doomed.push_back(e.path());
    }
    for (const auto& p : doomed) {
      fs::remove_all(p, ec);
      if (!ec) ++removed;
    }
  }
  return removed;
}

std::vector<std::string> WrittenFilesForLog(const Manifest& m) {
  // Folder (as written: "" for the output folder's own files) -> its files, in first-seen order.
  std::vector<std::pair<std::string, std::vector<std::string>>> folders;
  for (const ManifestEntry& e : m.files) {
    const fs::path p(e.path);
    const std::string folder = p.has_parent_path() ? p.parent_path().string() : "";
    auto it = std::find_if(folders.begin(), folders.end(),
                           [&](const auto& f) { return f.first == folder; });
    if (it == folders.end()) it = folders.insert(folders.end(), {folder, {}});
    it->second.push_back(e.path);
  }
  std::vector<std::string> out;
  for (const auto& [folder, files] : folders) {
    if (folder.empty() || files.size() <= 3) {
      out.insert(out.end(), files.begin(), files.end());
    } else {
      out.push_back(folder + "/ (" + std::to_string(files.size()) + " files)");
    }
  }
  // The output folder's own files first (the mesh, report.json), then sub-folders and exports.
  std::stable_partition(out.begin(), out.end(), [](const std::string& f) {
    return f.find('/') == std::string::npos;
  });
  out.push_back(kManifestFile);
  return out;
}

}  // namespace imr::batch
