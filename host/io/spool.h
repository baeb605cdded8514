// Files that hold what a long run records, instead of memory (issue 46): an append-only file
// written through a fixed buffer, its sequential reader, and an external stable sort of
// fixed-size records (sorted runs of bounded size on disk, merged k ways). A writer of a
// whole-run file (--export-stream, --export-colmap: io/stream_recorder.h) then holds a bounded
// number of bytes however long the run.
#pragma once

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <queue>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace imr::io {

// Appends to a file (created or truncated) through a fixed buffer. Throws std::runtime_error
// naming the file and the system's reason when a write fails (e.g. the disk is full).
class SpoolWriter {
 public:
  static constexpr std::size_t kBufferBytes = 1 << 16;
  // sync: Close() also flushes the file to disk (an output about to be renamed into place).
  explicit SpoolWriter(std::filesystem::path path, bool sync = false);
  ~SpoolWriter();
  SpoolWriter(const SpoolWriter&) = delete;
  SpoolWriter& operator=(const SpoolWriter&) = delete;

  void Write(const void* data, std::size_t n);
  void Write(std::string_view s) { Write(s.data(), s.size()); }
  template <class T>
  void Put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    Write(&v, sizeof v);
  }
  // Writes the buffer out, so that a reader of the file sees everything written so far.
  void Flush();
  // Flushes and closes (once); throws when the last writes fail.
  void Close();
  uint64_t bytes() const { return bytes_; }
  const std::filesystem::path& path() const { return path_; }

 private:
  void WriteAll(const char* data, std::size_t n);
  std::filesystem::path path_;
  bool sync_;
  int fd_ = -1;
  std::string buffer_;
  uint64_t bytes_ = 0;
};

// Reads a file from its start through a fixed buffer.
class SpoolReader {
 public:
  explicit SpoolReader(std::filesystem::path path);
  ~SpoolReader();
  SpoolReader(const SpoolReader&) = delete;
  SpoolReader& operator=(const SpoolReader&) = delete;

  // Reads n bytes; false at the end of the file. Throws naming the file when it ends within
  // the n bytes (a damaged spool) or a read fails.
  bool Read(void* data, std::size_t n);
  template <class T>
  bool Get(T* v) {
    static_assert(std::is_trivially_copyable_v<T>);
    return Read(v, sizeof *v);
  }
  // Reads up to n bytes (a text spool's next chunk); 0 at the end of the file.
  std::size_t ReadUpTo(void* data, std::size_t n);

 private:
  bool Fill();
  std::filesystem::path path_;
  int fd_ = -1;
  std::vector<char> buffer_;
  std::size_t at_ = 0, end_ = 0;
};

// A stable external sort of fixed-size records: Add keeps up to run_records in memory; a full
// buffer is sorted and written as a run file in `folder`. Read() merges the runs k ways; equal
// records come in the order they were added. Read() may be called again (each merge reads the
// run files anew); records added after a Read() go into new runs.
template <class T, class Less>
class ExternalSort {
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  ExternalSort(std::filesystem::path folder, std::string name, std::size_t run_records,
               Less less = Less())
      : folder_(std::move(folder)), name_(std::move(name)),
        run_records_(std::max<std::size_t>(run_records, 1)), less_(less) {}
  ~ExternalSort() {
    std::error_code ec;
    for (const auto& r : runs_) std::filesystem::remove(r, ec);
  }
  ExternalSort(const ExternalSort&) = delete;
  ExternalSort& operator=(const ExternalSort&) = delete;

  void Add(const T& r) {
    if (buffer_.capacity() == 0) buffer_.reserve(run_records_);
    buffer_.push_back(r);
    ++size_;
    if (buffer_.size() >= run_records_) WriteRun();
  }
  uint64_t size() const { return size_; }
  std::size_t runs() const { return runs_.size(); }
  // The buffer's bytes (at most run_records records): what the sort holds between merges.
  std::size_t HeldBytes() const { return buffer_.capacity() * sizeof(T); }

  class Reader {
   public:
    // The next record in order; false after the last.
    bool Next(T* out) {
      if (heap_.empty()) return false;
      const std::size_t r = heap_.top();
      heap_.pop();
      *out = heads_[r];
      if (inputs_[r]->Get(&heads_[r])) heap_.push(r);
      return true;
    }

   private:
    friend class ExternalSort;
    // The heap's top is the run whose head comes first; ties go to the earlier run (stable).
    struct After {
      const Reader* reader;
      bool operator()(std::size_t a, std::size_t b) const {
        const T& x = reader->heads_[a];
        const T& y = reader->heads_[b];
        if (reader->less_(y, x)) return true;
        if (reader->less_(x, y)) return false;
        return a > b;
      }
    };
    Reader(const std::vector<std::filesystem::path>& runs, Less less)
        : less_(less), heads_(runs.size()), heap_(After{this}) {
      for (std::size_t r = 0; r < runs.size(); ++r) {
        inputs_.push_back(std::make_unique<SpoolReader>(runs[r]));
        if (inputs_[r]->Get(&heads_[r])) heap_.push(r);
      }
    }
    Less less_;
    std::vector<std::unique_ptr<SpoolReader>> inputs_;
    std::vector<T> heads_;
    std::priority_queue<std::size_t, std::vector<std::size_t>, After> heap_;
  };

  // The records added so far, in order (the buffer is written as a last run first). The reader
  // holds one buffer of SpoolReader per run.
  std::unique_ptr<Reader> Read() {
    if (!buffer_.empty()) WriteRun();
    Release();
    return std::unique_ptr<Reader>(new Reader(runs_, less_));
  }
  // Frees the buffer (a sort read at the end of a run needs it no more).
  void Release() { std::vector<T>().swap(buffer_); }

 private:
  void WriteRun() {
    std::stable_sort(buffer_.begin(), buffer_.end(), less_);
    runs_.push_back(folder_ / (name_ + "-" + std::to_string(runs_.size()) + ".run"));
    SpoolWriter w(runs_.back());
    w.Write(buffer_.data(), buffer_.size() * sizeof(T));
    w.Close();
    buffer_.clear();
  }
  std::filesystem::path folder_;
  std::string name_;
  std::size_t run_records_;
  Less less_;
  std::vector<T> buffer_;
  std::vector<std::filesystem::path> runs_;
  uint64_t size_ = 0;
};

}  // namespace imr::io
