#include "host/util/write_rule.h"

#include "host/util/sha256.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

namespace imr {
namespace fs = std::filesystem;
namespace {

// One input of a live scope, resolved once: symlinks followed (a link to an input is the input),
// and its inode when it exists (a hard link to an input is the input too).
struct Input {
  uint64_t scope = 0;
  fs::path path;       // as given, for messages
  fs::path resolved;   // weakly canonical
  std::string what;
  bool folder = false;
  bool has_inode = false;
  dev_t dev = 0;
  ino_t ino = 0;
};

std::mutex& InputsMutex() {
  static std::mutex m;
  return m;
}
std::vector<Input>& Inputs() {
  static std::vector<Input> inputs;
  return inputs;
}
// Files live scopes claim (InputScope::Claim), resolved.
std::vector<std::pair<uint64_t, fs::path>>& Claims() {
  static std::vector<std::pair<uint64_t, fs::path>> claims;
  return claims;
}
std::vector<uint64_t>& LiveScopes() {
  static std::vector<uint64_t> scopes;
  return scopes;
}
std::atomic<uint64_t> next_scope{1};

fs::path Resolved(const fs::path& p) {
  std::error_code ec;
  fs::path abs = fs::absolute(p, ec);
  if (ec) abs = p;
  fs::path r = fs::weakly_canonical(abs, ec);
  return ec ? abs.lexically_normal() : r;
}

// Whether `inner` is `outer` or lies below it (both resolved).
bool Within(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

// Private folders of live scopes (InputScope::Private), resolved.
std::vector<std::pair<uint64_t, fs::path>>& PrivateFolders() {
  static std::vector<std::pair<uint64_t, fs::path>> folders;
  return folders;
}

// A folder of imr's own staging (StagingDirectory) or a private one: everything in it is imr's.
bool InStaging(const fs::path& target) {
  const fs::path parent = target.parent_path();
  for (const auto& part : parent)
    if (part.string().rfind(".imr-staging-", 0) == 0) return true;
  std::lock_guard<std::mutex> lock(InputsMutex());
  if (PrivateFolders().empty()) return false;
  const fs::path resolved = Resolved(parent);
  for (const auto& f : PrivateFolders())
    if (Within(resolved, f.second)) return true;
  return false;
}

std::string Kind(const struct stat& st) {
  if (S_ISREG(st.st_mode)) return "a file";
  if (S_ISDIR(st.st_mode)) return "a folder";
  if (S_ISFIFO(st.st_mode)) return "a FIFO";
  if (S_ISCHR(st.st_mode)) return "a character device";
  if (S_ISBLK(st.st_mode)) return "a block device";
  if (S_ISSOCK(st.st_mode)) return "a socket";
  if (S_ISLNK(st.st_mode)) return "a symbolic link";
  return "not a regular file";
}

// Rule 1: an input of a live scope, or inside a folder one reads from. "" when none.
std::string InputConflict(const fs::path& target) {
  const fs::path resolved = Resolved(target);
  struct stat st {};
  const bool exists = ::stat(target.c_str(), &st) == 0;
  std::lock_guard<std::mutex> lock(InputsMutex());
  for (const Input& in : Inputs()) {
    const bool same_file =
        resolved == in.resolved ||
        (exists && in.has_inode && st.st_dev == in.dev && st.st_ino == in.ino);
    if (same_file)
      return "it is " + in.what + ", an input of this run (imr never writes over what it reads)";
    if (in.folder && Within(resolved, in.resolved))
      return "it lies inside " + in.path.string() + " (" + in.what +
             "), a folder this run reads from (imr never writes into its inputs)";
  }
  return {};
}

// The ledger: one line per file imr wrote in a folder, "<sha256> <bytes> <name as JSON>".
struct Claim {
  std::string sha256;
  uint64_t bytes = 0;
};

fs::path LedgerOf(const fs::path& file) {
  const fs::path dir = file.has_parent_path() ? file.parent_path() : fs::path(".");
  return dir / kWriteLedgerName;
}

// Reads `size` bytes from the start of `fd` (pread: the position of an O_APPEND descriptor
// does not matter); fewer when the file is shorter.
std::string ReadFrom(int fd, std::size_t size) {
  std::string text(size, '\0');
  std::size_t got = 0;
  while (got < text.size()) {
    const ssize_t n = ::pread(fd, text.data() + got, text.size() - got, static_cast<off_t>(got));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
  }
  text.resize(got);
  return text;
}

// The ledger's text, "" when there is none (or it is not a regular file, or absurdly large).
std::string LedgerText(const fs::path& ledger) {
  std::string text;
  const int fd = ::open(ledger.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return text;
  struct stat st {};
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size < (64 << 20)) {
    // Shared with other readers, never with a compaction in progress (it rewrites in place).
    while (::flock(fd, LOCK_SH) != 0 && errno == EINTR) {
    }
    ::fstat(fd, &st);
    text = ReadFrom(fd, static_cast<std::size_t>(st.st_size));
  }
  ::close(fd);
  return text;
}

// Parses one whole line ("<sha256> <bytes> <name as JSON>"); false for a malformed one.
bool ParseClaim(const std::string& line, std::string* name, Claim* c) {
  const std::size_t s1 = line.find(' ');
  const std::size_t s2 = s1 == std::string::npos ? s1 : line.find(' ', s1 + 1);
  if (s2 == std::string::npos || s1 != 64) return false;
  c->sha256 = line.substr(0, s1);
  try {
    c->bytes = std::stoull(line.substr(s1 + 1, s2 - s1 - 1));
    const nlohmann::json n = nlohmann::json::parse(line.substr(s2 + 1));
    if (!n.is_string()) return false;
    *name = n.get<std::string>();
  } catch (const std::exception&) {
    return false;
  }
  return true;
}

// Every whole line of a ledger's text, by name.
std::multimap<std::string, Claim> ParseLedger(const std::string& text) {
  std::multimap<std::string, Claim> claims;
  std::size_t b = 0;
  while (b < text.size()) {
    const std::size_t e = text.find('\n', b);
    if (e == std::string::npos) break;  // a line cut by a kill: not a claim
    std::string name;
    Claim c;
    if (ParseClaim(text.substr(b, e - b), &name, &c)) claims.emplace(std::move(name), c);
    b = e + 1;
  }
  return claims;
}

// The claims of one name, found by its JSON spelling at the ends of lines: a scan of the text,
// not a parse of every line (a folder of thousands of tiles rewrites its tileset often).
std::vector<Claim> ClaimsOf(const fs::path& file) {
  std::vector<Claim> claims;
  const std::string text = LedgerText(LedgerOf(file));
  const std::string needle = " " + nlohmann::json(file.filename().string()).dump() + "\n";
  for (std::size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) {
    const std::size_t begin = text.rfind('\n', at);
    const std::size_t b = begin == std::string::npos ? 0 : begin + 1;
    std::string name;
    Claim c;
    if (ParseClaim(text.substr(b, at + needle.size() - 1 - b), &name, &c)) claims.push_back(c);
  }
  return claims;
}

// Whether the regular file `file` (of `size` bytes) holds what the ledger says imr wrote.
bool Claimed(const fs::path& file, uint64_t size) {
  std::optional<std::string> hash;
  for (const Claim& c : ClaimsOf(file)) {
    if (c.bytes != size) continue;
    if (!hash) {
      try {
        hash = Sha256File(file);
      } catch (const std::exception&) {
        return false;
      }
    }
    if (*hash == c.sha256) return true;
  }
  return false;
}

// Rule 2 and 3 for an existing target. "" when imr may replace it.
std::string OwnershipConflict(const fs::path& target) {
  struct stat st {};
  if (::lstat(target.c_str(), &st) != 0) return {};  // nothing there: nothing to lose
  if (!S_ISREG(st.st_mode))
    return Kind(st) + ", not a file imr wrote (imr writes only regular files and never replaces "
                      "anything else)";
  {
    const fs::path resolved = Resolved(target);
    std::lock_guard<std::mutex> lock(InputsMutex());
    for (const auto& c : Claims())
      if (c.second == resolved) return {};
  }
  if (Claimed(target, static_cast<uint64_t>(st.st_size))) return {};
  if (!ClaimsOf(target).empty())
    return "changed since imr wrote it (its bytes are not those imr's ledger " +
           LedgerOf(target).string() + " records), so it is yours now; imr never writes over it";
  return "a file imr did not write (no record of it in imr's ledger " + LedgerOf(target).string() +
         "); imr never writes over a file it did not write";
}

// Appends lines to `ledger` under an exclusive lock; a ledger grown past kCompactBytes is first
// rewritten with the last two claims of each name that still exists (the newest may be a claim
// whose rename a kill prevented, so the one before it is kept too).
constexpr off_t kCompactBytes = 1 << 20;

void Compact(int fd, const fs::path& ledger) {
  // Read through the locked descriptor: another open of the file would wait for our own lock.
  struct stat st {};
  if (::fstat(fd, &st) != 0) return;
  const std::string text = ReadFrom(fd, static_cast<std::size_t>(st.st_size));
  if (text.size() != static_cast<std::size_t>(st.st_size)) return;  // not read whole: left as is
  const auto claims = ParseLedger(text);
  std::map<std::string, std::vector<Claim>> last;
  for (const auto& [name, c] : claims) {
    auto& v = last[name];
    v.push_back(c);
    if (v.size() > 2) v.erase(v.begin());
  }
  std::string kept;
  for (const auto& [name, v] : last) {
    std::error_code ec;
    if (!fs::exists(ledger.parent_path() / name, ec)) continue;
    for (const Claim& c : v)
      kept += c.sha256 + " " + std::to_string(c.bytes) + " " + nlohmann::json(name).dump() + "\n";
  }
  if (::ftruncate(fd, 0) != 0) return;
  ::lseek(fd, 0, SEEK_SET);
  std::size_t done = 0;
  while (done < kept.size()) {
    const ssize_t n = ::write(fd, kept.data() + done, kept.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;
    done += static_cast<std::size_t>(n);
  }
}

void AppendToLedger(const fs::path& ledger, const std::string& line) {
  struct stat lst {};
  if (::lstat(ledger.c_str(), &lst) == 0 && !S_ISREG(lst.st_mode))
    throw WriteRefused(ledger.string() + ": imr's ledger is " + Kind(lst) +
                       "; nothing was written");
  const int fd =
      ::open(ledger.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (fd < 0)
    throw std::runtime_error(ledger.string() + ": cannot record what imr writes: " +
                             std::strerror(errno));
  while (::flock(fd, LOCK_EX) != 0 && errno == EINTR) {
  }
  struct stat st {};
  if (::fstat(fd, &st) == 0 && st.st_size > kCompactBytes) Compact(fd, ledger);
  std::size_t done = 0;
  int err = 0;
  while (done < line.size()) {
    const ssize_t n = ::write(fd, line.data() + done, line.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      err = n < 0 ? errno : ENOSPC;
      break;
    }
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);  // releases the lock
  if (err != 0)
    throw std::runtime_error(ledger.string() + ": cannot record what imr writes: " +
                             std::strerror(err));
}

}  // namespace

InputScope::InputScope() : id_(next_scope++) {
  std::lock_guard<std::mutex> lock(InputsMutex());
  LiveScopes().push_back(id_);
}

InputScope::~InputScope() {
  std::lock_guard<std::mutex> lock(InputsMutex());
  auto& inputs = Inputs();
  inputs.erase(std::remove_if(inputs.begin(), inputs.end(),
                              [&](const Input& in) { return in.scope == id_; }),
               inputs.end());
  auto& folders = PrivateFolders();
  folders.erase(std::remove_if(folders.begin(), folders.end(),
                               [&](const auto& f) { return f.first == id_; }),
                folders.end());
  auto& claims = Claims();
  claims.erase(std::remove_if(claims.begin(), claims.end(),
                              [&](const auto& c) { return c.first == id_; }),
               claims.end());
  auto& live = LiveScopes();
  live.erase(std::remove(live.begin(), live.end(), id_), live.end());
}

namespace {

void AddInputTo(uint64_t scope, const fs::path& path, std::string_view what) {
  if (path.empty()) return;
  Input in;
  in.scope = scope;
  in.path = path;
  in.resolved = Resolved(path);
  in.what = std::string(what);
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    in.folder = S_ISDIR(st.st_mode);
    in.has_inode = true;
    in.dev = st.st_dev;
    in.ino = st.st_ino;
  }
  std::lock_guard<std::mutex> lock(InputsMutex());
  for (const Input& e : Inputs()) {
    if (e.scope == scope && e.resolved == in.resolved) return;
    // A file inside a folder input is covered by it: a sequence's images are not kept one by
    // one (a drive reads tens of thousands, and every write is checked against the list).
    if (e.folder && !in.folder && Within(in.resolved, e.resolved)) return;
  }
  Inputs().push_back(std::move(in));
}

}  // namespace

void InputScope::Add(const fs::path& path, std::string_view what) { AddInputTo(id_, path, what); }

void InputScope::Private(const fs::path& folder) {
  if (folder.empty()) return;
  const fs::path resolved = Resolved(folder);
  std::lock_guard<std::mutex> lock(InputsMutex());
  PrivateFolders().emplace_back(id_, resolved);
}

void InputScope::Claim(const fs::path& path) {
  if (path.empty()) return;
  const fs::path resolved = Resolved(path);
  std::lock_guard<std::mutex> lock(InputsMutex());
  Claims().emplace_back(id_, resolved);
}

void NoteInput(const fs::path& path, std::string_view what) {
  uint64_t scope = 0;
  {
    std::lock_guard<std::mutex> lock(InputsMutex());
    if (LiveScopes().empty()) return;
    scope = LiveScopes().back();
  }
  AddInputTo(scope, path, what);
}

std::string WhyNotWritable(const fs::path& target) {
  if (InStaging(target)) return {};
  if (std::string why = InputConflict(target); !why.empty()) return why;
  return OwnershipConflict(target);
}

void CheckWriteTarget(const fs::path& target) {
  if (const std::string why = WhyNotWritable(target); !why.empty())
    throw WriteRefused(target.string() + ": " + why + "; nothing was written");
}

void CheckWriteFolder(const fs::path& dir) {
  if (dir.empty() || InStaging(dir / "x")) return;
  // A file inside `dir` conflicts with a folder input exactly when `dir` does.
  std::string why = InputConflict(dir);
  if (why.empty()) {
    struct stat st {};
    if (::stat(dir.c_str(), &st) == 0 && !S_ISDIR(st.st_mode))
      why = Kind(st) + ", not a folder imr can write into";
  }
  if (!why.empty()) throw WriteRefused(dir.string() + ": " + why + "; nothing was written");
}

void RecordWritten(const fs::path& target, std::string_view sha256_hex, uint64_t bytes) {
  if (InStaging(target)) return;
  AppendToLedger(LedgerOf(target), std::string(sha256_hex) + " " + std::to_string(bytes) + " " +
                                       nlohmann::json(target.filename().string()).dump() + "\n");
}

void RecordWrittenFile(const fs::path& staged, const fs::path& target) {
  if (InStaging(target)) return;
  std::error_code ec;
  const uint64_t bytes = fs::file_size(staged, ec);
  if (ec) throw std::runtime_error(staged.string() + ": cannot read what imr wrote: " + ec.message());
  RecordWritten(target, Sha256File(staged), bytes);
}

bool WrittenByImr(const fs::path& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  return Claimed(path, static_cast<uint64_t>(st.st_size));
}

bool RemoveWrittenFile(const fs::path& path, std::string* why) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) return true;
  std::string reason = InStaging(path) ? std::string() : InputConflict(path);
  if (reason.empty() && !InStaging(path)) reason = OwnershipConflict(path);
  if (!reason.empty()) {
    if (why != nullptr) *why = path.string() + ": " + reason + "; it was left in place";
    return false;
  }
  std::error_code ec;
  fs::remove(path, ec);
  if (ec) {
    if (why != nullptr) *why = path.string() + ": cannot remove: " + ec.message();
    return false;
  }
  return true;
}

}  // namespace imr
