#include "host/io/batch_folder.h"

#include "host/util/write_rule.h"

namespace imr::io {
namespace fs = std::filesystem;

namespace {

bool HoldsAny(const fs::path& dir, std::initializer_list<const char*> names) {
  std::error_code ec;
  if (fs::is_empty(dir, ec) && !ec) return true;
  for (const char* n : names)
    if (fs::exists(dir / n, ec)) return true;
  return false;
}

}  // namespace

std::string ForeignBatchEntry(const fs::path& batch_dir, const std::string& entry) {
  const fs::path p = batch_dir / entry;
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(p, ec);
  if (ec || !fs::exists(st)) return {};
  const bool folder = entry == kBatchSubdir || entry == "assets";
  const bool is_dir = fs::is_directory(st);
  if (folder != is_dir)
    return p.string() + ": a " + (is_dir ? "folder" : fs::is_regular_file(st) ? "file" : "special file") +
           ", not what imr writes there (its " + (folder ? "folder" : "file") + " " + entry + ")";
  if (entry == kBatchSubdir) {
    // Its records are imr's by name (locks, status records, Slurm's task logs are not written
    // through the rule); a folder without any of them is someone else's.
    const bool ours = HoldsAny(p, {"batch.json", "lock", "status", "slurm", "sequences.txt"});
    return ours ? std::string()
                : p.string() + ": a folder without imr's batch.json, lock or status records";
  }
  if (entry == "assets") {
    // Every file in it is one the page replaces: each must be one imr wrote (the write rule).
    for (auto it = fs::recursive_directory_iterator(p, ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
      if (it->path().filename() == kWriteLedgerName) continue;
      if (it->is_directory(ec)) continue;
      if (const std::string why = WhyNotWritable(it->path()); !why.empty())
        return it->path().string() + ": " + why;
    }
    return {};
  }
  if (const std::string why = WhyNotWritable(p); !why.empty()) return p.string() + ": " + why;
  return {};
}

std::string ForeignBatchFiles(const fs::path& batch_dir, bool viewer) {
  for (const char* entry : kBatchFolderEntries) {
    const std::string e = entry;
    if (!viewer && (e == "index.html" || e == "assets")) continue;
    if (std::string foreign = ForeignBatchEntry(batch_dir, e); !foreign.empty())
      return foreign + ": imr would overwrite it with " +
             (e == kBatchSubdir ? std::string("its batch records")
              : e == "index.html" || e == "assets" ? std::string("the viewer page")
                                                   : std::string("the batch summary")) +
             "; move it away, or give output.directory a folder of its own (e.g. "
             "\"runs/{sequence}\")" +
             (e == "index.html" || e == "assets" ? ", or give imr run --no-viewer" : "");
  }
  return {};
}

}  // namespace imr::io
