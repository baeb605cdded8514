#include "host/engine/retired_ids.h"

#include <algorithm>

namespace imr::engine::detail {

void RetiredIds::Add(uint64_t id) {
  Chunk& c = chunks_[id >> kChunkBits];
  const auto offset = static_cast<uint16_t>(id & (kChunkIds - 1));
  if (c.count == kChunkIds) return;  // full
  if (c.bits) {
    uint64_t& word = c.bits[offset / 64];
    const uint64_t bit = uint64_t{1} << (offset % 64);
    if (word & bit) return;
    word |= bit;
    ++size_;
    if (++c.count == kChunkIds) c.bits.reset();
    return;
  }
  auto at = std::lower_bound(c.listed.begin(), c.listed.end(), offset);
  if (at != c.listed.end() && *at == offset) return;
  c.listed.insert(at, offset);
  ++c.count;
  ++size_;
  if (c.count > kMaxListed) {  // the bitmap is smaller now
    c.bits = std::make_unique<uint64_t[]>(kWords);  // zeroed
    for (uint16_t o : c.listed) c.bits[o / 64] |= uint64_t{1} << (o % 64);
    std::vector<uint16_t>().swap(c.listed);
  }
}

bool RetiredIds::Contains(uint64_t id) const {
  auto it = chunks_.find(id >> kChunkBits);
  if (it == chunks_.end()) return false;
  const Chunk& c = it->second;
  const auto offset = static_cast<uint16_t>(id & (kChunkIds - 1));
  if (c.count == kChunkIds) return true;
  if (c.bits) return (c.bits[offset / 64] >> (offset % 64)) & 1;
  return std::binary_search(c.listed.begin(), c.listed.end(), offset);
}

int64_t RetiredIds::MemoryBytes() const {
  // An unordered_map node: the next pointer, the key, the chunk, the cached hash; a bucket each.
  int64_t bytes = static_cast<int64_t>(chunks_.bucket_count() * sizeof(void*) +
                                       chunks_.size() * (2 * sizeof(void*) + sizeof(uint64_t) +
                                                         sizeof(Chunk)));
  for (const auto& [key, c] : chunks_)
    bytes += c.bits ? kWords * sizeof(uint64_t)
                    : static_cast<int64_t>(c.listed.capacity() * sizeof(uint16_t));
  return bytes;
}

}  // namespace imr::engine::detail
