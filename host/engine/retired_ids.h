// The external ids of points forgotten (Forgetting, engine_parts.h): an update may still name
// them (a late move of a point far behind), which is then ignored, not an error.
#pragma once

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

namespace imr::engine::detail {

// A set of 64-bit ids in chunks of 4,096 consecutive ids, each held as the fewest bytes its ids
// allow: a sorted list of 16-bit offsets while it has few, then a bitmap (512 bytes), then
// nothing once every id of the chunk is in. A stream whose ids come in order with gaps (the image
// pipeline's tracks: most never become points, and points leave in an order of their own) costs
// at most a bit per id it named, where runs of consecutive ids cost 48 bytes a gap (2 kB a frame
// on a 5,000-frame image drive); ids scattered over the whole range cost about a chunk each.
class RetiredIds {
 public:
  void Add(uint64_t id);
  bool Contains(uint64_t id) const;
  bool empty() const { return chunks_.empty(); }
  int64_t size() const { return size_; }
  // Heap bytes held (EngineMemory::points counts them).
  int64_t MemoryBytes() const;

 private:
  static constexpr int kChunkBits = 12;
  static constexpr uint32_t kChunkIds = 1u << kChunkBits;
  static constexpr uint32_t kWords = kChunkIds / 64;
  // A list of more offsets than this takes more bytes than the bitmap.
  static constexpr uint32_t kMaxListed = kWords * 4;
  struct Chunk {
    uint32_t count = 0;                // ids held
    std::vector<uint16_t> listed;      // sorted offsets while count <= kMaxListed
    std::unique_ptr<uint64_t[]> bits;  // kWords words beyond that, until the chunk is full
  };
  std::unordered_map<uint64_t, Chunk> chunks_;  // id >> kChunkBits -> its chunk
  int64_t size_ = 0;
};

}  // namespace imr::engine::detail
