// The one rule for every file imr writes or removes (docs/reliability.md, "Writing"), and the
// inputs it protects. A command (or one call of the Python module) opens an InputScope and names
// its inputs in it: the job file, each sequence's files and folders, the models, images and
// meshes it reads, the run folder a merge reads from. Readers that open a file through the open
// rule (host/util/input_file.h) add it too. Every write asks the rule first — WriteFileAtomically,
// CopyFileAtomically and StagingDirectory::Commit do, so no writer decides on its own — and is
// refused, with WriteRefused naming the path and the reason (exit 73, EX_CANTCREAT), when the
// target
//   1. is an input of the same run, or lies inside a folder the run reads from;
//   2. exists and imr did not write it: no line of imr's ledger in its folder (".imr-written")
//      records its size and SHA-256, so it is a user's file, or one a user changed since (unless
//      a live scope claims it: the manifest of the same job and sequence names it);
//   3. exists and is not a regular file (a folder, a symlink, a FIFO, a device, a socket).
// What imr writes is recorded in its folder's ledger before it is renamed into place, so a
// re-run (and `--force`) may replace exactly what imr wrote, and nothing else. Removals go
// through RemoveWrittenFile under the same rule.
#pragma once

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>

namespace imr {

// A write the rule refused; what() is "<path>: <reason>". Commands exit 73 on it.
class WriteRefused : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The ledger's file name in each folder imr writes into.
inline constexpr const char* kWriteLedgerName = ".imr-written";

// The inputs of one command or module call, for as long as the scope lives. Scopes nest (the
// module may run inside a test that holds one); the rule checks the inputs of every live scope.
// Thread-safe.
class InputScope {
 public:
  InputScope();
  ~InputScope();
  InputScope(const InputScope&) = delete;
  InputScope& operator=(const InputScope&) = delete;

  // A file or folder this command reads. `what` names it in refusals ("the job file",
  // "sequence 'seq' (its input folder)"). A path that does not exist is still remembered (a
  // file the run creates later is no input). Empty paths are ignored.
  void Add(const std::filesystem::path& path, std::string_view what);
  // A file a record of imr names as this run's own output (the manifest of the same job and
  // sequence): replaceable whatever its bytes now are (a damaged output is redone).
  void Claim(const std::filesystem::path& path);
  // A folder the command builds privately and puts in place whole by one rename (imr-synth's
  // DIR.partial-<pid>), as a staging folder: what is written inside needs no check or record.
  void Private(const std::filesystem::path& folder);

 private:
  uint64_t id_;
};

// Adds `path` to the innermost live InputScope (none: ignored). The open rule calls it for
// every file a reader opens, so what a run read is never what it writes.
void NoteInput(const std::filesystem::path& path, std::string_view what);

// Why imr may not write `target` (rule 1-3 above), or "" when it may. `target`'s folder need not
// exist. A target inside one of imr's own staging folders (".imr-staging-*") is always writable.
std::string WhyNotWritable(const std::filesystem::path& target);
// Throws WriteRefused("<target>: <reason>; nothing was written") when WhyNotWritable says why.
void CheckWriteTarget(const std::filesystem::path& target);

// Throws WriteRefused when imr may not create or write into the folder `dir`: it is an input
// file, or a folder the run reads from or lies inside one, or something other than a folder.
void CheckWriteFolder(const std::filesystem::path& dir);

// Records in `target`'s folder's ledger that imr writes `bytes` bytes with SHA-256 `sha256_hex`
// under that name. Called before the rename that puts the file in place (a run killed between
// the two leaves a claim no file matches, which is harmless). Throws naming the ledger when it
// cannot be written.
void RecordWritten(const std::filesystem::path& target, std::string_view sha256_hex,
                   uint64_t bytes);
// Hashes the file at `staged` and records it under `target`'s name (see RecordWritten).
void RecordWrittenFile(const std::filesystem::path& staged, const std::filesystem::path& target);

// Whether the regular file `path` holds bytes imr wrote under its name (its ledger says so).
bool WrittenByImr(const std::filesystem::path& path);

// Removes `path` when imr wrote it (WrittenByImr) or it is already gone; else leaves it,
// returns false and says why in `why`. Inputs are never removed.
bool RemoveWrittenFile(const std::filesystem::path& path, std::string* why = nullptr);

}  // namespace imr
