#include "host/io/batch_folder.h"

#include "host/util/input_file.h"

#include <fstream>

namespace imr::io {
namespace fs = std::filesystem;

namespace {

// The first `limit` bytes of a file ("" when unreadable).
// Through the open rule (host/util/input_file.h): a FIFO in imr's place is unreadable, so
// foreign, and never waited on.
std::string Head(const fs::path& p, std::size_t limit) {
  try {
    return InputFile::Open(p, "a file imr wrote", InputRole::kOwnOutput).ReadUpTo(limit);
  } catch (const std::runtime_error&) {
    return {};
  }
}

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
  const bool is_dir = fs::is_directory(p, ec);
  if (folder != is_dir)
    return p.string() + ": a " + (is_dir ? "folder" : "file") + ", not what imr writes there (its " +
           (folder ? "folder" : "file") + " " + entry + ")";
  bool ours = false;
  std::string what;
  if (entry == "summary.json") {
    ours = Head(p, 64 << 10).find("\"imr_summary\"") != std::string::npos;
    what = "not a batch summary of imr (no \"imr_summary\" key)";
  } else if (entry == "summary.md") {
    ours = Head(p, 64).rfind("# imr batch summary", 0) == 0;
    what = "not a batch summary of imr (it does not start with \"# imr batch summary\")";
  } else if (entry == "index.html") {
    // imr's pages name their generator in the head; older ones hold its mesh table.
    const std::string page = Head(p, 32 << 20);
    ours = page.find("<meta name=\"generator\" content=\"imr") != std::string::npos ||
           page.find("<script type=\"application/json\" id=\"imr-meshes\">") != std::string::npos;
    what = "not a viewer page of imr";
  } else if (entry == "assets") {
    ours = HoldsAny(p, {kViewerScriptName, "meshes"});
    what = std::string("a folder without imr's ") + kViewerScriptName + " or meshes/";
  } else if (entry == kBatchSubdir) {
    ours = HoldsAny(p, {"batch.json", "lock", "status", "slurm", "sequences.txt"});
    what = "a folder without imr's batch.json, lock or status records";
  } else {
    return {};
  }
  return ours ? std::string() : p.string() + ": " + what;
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
