// Outputs appear whole or not at all: write under a temporary name in the same folder, flush to
// disk, then rename (atomic on POSIX). A killed run leaves only a dot-prefixed temporary behind,
// never a half file under the final name.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace imr {

// Writes `contents` to `path` atomically. Throws std::runtime_error naming the path on failure
// (folder missing or not writable, disk full); the final path is then untouched.
void WriteFileAtomically(const std::filesystem::path& path, std::string_view contents);

// Copies `from` to `to` atomically (a temporary beside `to`, renamed into place). Throws
// std::runtime_error naming the path and the system's reason ("No space left on device"); the
// temporary is removed and `to` untouched.
void CopyFileAtomically(const std::filesystem::path& from, const std::filesystem::path& to);

// A private folder beside the final outputs for writers that produce several files (glTF +
// .bin). Commit() moves every file into the destination folder (each by rename) and removes the
// staging folder; destruction without Commit() removes it and everything in it.
class StagingDirectory {
 public:
  // Creates `destination` if needed and a staging folder inside it. Throws on failure.
  explicit StagingDirectory(const std::filesystem::path& destination);
  ~StagingDirectory();
  StagingDirectory(const StagingDirectory&) = delete;
  StagingDirectory& operator=(const StagingDirectory&) = delete;

  const std::filesystem::path& path() const { return staging_; }
  // The staged files, in the order Commit moves them: by name, then the names in `last` in
  // their order.
  std::vector<std::filesystem::path> Staged(const std::vector<std::string>& last = {}) const;
  // Moves the staged files into the destination; the names in `last` (optional) are moved last,
  // in that order, so a reader that sees one can rely on those before it. Returns the final
  // paths.
  std::vector<std::filesystem::path> Commit(const std::vector<std::string>& last = {});
  std::vector<std::filesystem::path> Commit(const std::string& last) {
    return Commit(std::vector<std::string>{last});
  }

 private:
  std::filesystem::path destination_;
  std::filesystem::path staging_;
  bool committed_ = false;
};

// Throws std::runtime_error("<path>: <what>") when `dir` cannot be created or written.
void EnsureWritableDirectory(const std::filesystem::path& dir);

}  // namespace imr
