// What a batch folder (a job's RUN_DIR, JobSpec::BatchDirectory) holds besides the sequences'
// folders, and how to tell imr's own entries from a user's files of the same name: imr writes
// them into a folder that may already hold other things (output.directory "{sequence}" makes the
// job's own folder the batch folder), and never overwrites a file it did not write.
#pragma once

#include <array>
#include <filesystem>
#include <string>

namespace imr::io {

// The batch folder's own subfolder: batch.json, status records, locks, the Slurm scripts.
inline constexpr const char* kBatchSubdir = "imr-batch";
// <model-viewer>'s script, which the viewer page (host/report) copies into assets/.
inline constexpr const char* kViewerScriptName = "model-viewer-umd.min.js";

// The entries imr writes in a batch folder: no sequence may be named so (its output folder
// would be one of them), and a glob does not take imr's own for sequences.
inline constexpr std::array<const char*, 5> kBatchFolderEntries = {
    kBatchSubdir, "summary.json", "summary.md", "index.html", "assets"};
inline bool IsBatchFolderEntry(const std::string& name) {
  for (const char* e : kBatchFolderEntries)
    if (name == e) return true;
  return false;
}

// Empty when batch_dir / entry (one of kBatchFolderEntries) is absent or imr may replace it;
// else why not, naming the path. Files (summary.json, summary.md, index.html) and every file
// under assets/ follow the write rule (host/util/write_rule.h: imr's ledger records their
// bytes); imr-batch/ is imr's when empty or holding batch.json, a lock or status records.
std::string ForeignBatchEntry(const std::filesystem::path& batch_dir, const std::string& entry);

// The first foreign entry of the batch folder (index.html and assets/ only when `viewer`), as
// ForeignBatchEntry says it, with what to do; empty when imr may write them all.
std::string ForeignBatchFiles(const std::filesystem::path& batch_dir, bool viewer);

}  // namespace imr::io
