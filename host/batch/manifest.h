// Per-sequence manifests: what makes a finished sequence "finished". After a sequence's outputs
// and report.json are in place, manifest.json is written last (atomically) with every file the
// run wrote, its size and SHA-256, and the job identity it was made from: imr's version, the
// input format and options, the sequence's source, engine options, every stage's plugin id,
// version and params (defaults filled in), the output stem/formats and export paths. A re-run
// skips a sequence only when the identity's hash matches and every file still matches.
#pragma once

#include "host/pipeline/run.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace imr::batch {

inline constexpr const char* kManifestFile = "manifest.json";

struct ManifestEntry {
  std::string path;    // relative to the sequence's output folder, or absolute when outside it
  uint64_t bytes = 0;
  std::string sha256;  // hex
};

struct Manifest {
  std::string sequence;
  // The job file that wrote it, relative to the output folder (a folder moved with its job
  // keeps it); empty in manifests of imr before 0.x that did not record it.
  std::string job;
  std::string job_hash;      // SHA-256 of job_identity.dump()
  nlohmann::json job_identity;  // what the hash covers, kept to say what changed
  std::vector<ManifestEntry> files;
};

// The identity of one sequence's run (see the file comment) and its hash.
nlohmann::json JobIdentity(const pipeline::ValidatedJob& job, const plugin::PluginRegistry& registry,
                           const pipeline::RunOptions& options, const pipeline::SequenceRef& seq);
std::string HashIdentity(const nlohmann::json& identity);

// Hashes `files` (absolute paths) into a manifest for `output_directory`. Files inside
// `relative_within` (the batch folder; default: the output folder) are listed relative to the
// output folder, others by absolute path. Throws naming a file that cannot be read.
Manifest MakeManifest(const std::string& sequence, const nlohmann::json& identity,
                      const std::vector<std::filesystem::path>& files,
                      const std::filesystem::path& output_directory,
                      const std::filesystem::path& relative_within = {});
// The job file as a manifest in `output_directory` records it.
std::string ManifestJob(const std::filesystem::path& job_file,
                        const std::filesystem::path& output_directory);
void WriteManifest(const Manifest& m, const std::filesystem::path& output_directory);
// nullopt when there is none; `error` set when it exists but cannot be read or parsed.
std::optional<Manifest> ReadManifest(const std::filesystem::path& output_directory,
                                     std::string* error);

// What a finished run wrote, as its last log lines name it (issue 47): the output folder's own
// files by name, a sub-folder of more than three files as one entry ("tiles/ (120 files)"),
// files outside the folder (exports) by absolute path, those of a folder of more than three as
// one entry; manifest.json itself last. In the manifest's order otherwise.
std::vector<std::string> WrittenFilesForLog(const Manifest& m);

struct ManifestCheck {
  bool up_to_date = false;
  std::string reason;  // why not (or "manifest matches"), for logs and the summary
};

// Whether the outputs in `output_directory` are those of a finished run with `job_hash`: the
// manifest exists and parses, its hash matches, and every file it lists exists with the same
// size and SHA-256. `identity`, when given, lets the reason name what changed in the job.
ManifestCheck CheckManifest(const std::filesystem::path& output_directory,
                            const std::string& job_hash,
                            const nlohmann::json& identity = nullptr);

// Why this job must not write `sequence` into `output_directory`, or "" when it may: a
// manifest.json that is no imr manifest, or one another job wrote (its clean-up would delete
// that job's files), or a report.json that is not a report of this sequence of this job (imr
// would overwrite another tool's file, e.g. with the output folder = the input folder).
std::string ForeignOutputs(const std::filesystem::path& output_directory,
                           const std::filesystem::path& job_file, const std::string& sequence);

// The absolute path of a manifest entry.
std::filesystem::path EntryPath(const ManifestEntry& e, const std::filesystem::path& output_directory);

// Removes what a killed run may leave in an output folder (and its snapshots/ and tiles/): staging folders
// (.imr-staging-*) and temporaries of atomic writes (.<name>.tmp-*). Never a file under a final
// name. Returns the number of entries removed.
int RemoveLeftovers(const std::filesystem::path& output_directory);

}  // namespace imr::batch
