// Sharding: which sequences of a job one process (one Slurm array task) runs. A sequence's shard
// depends on its name only through a stable hash: sequences are ordered by FNV-1a 64 of their
// names (ties by name) and dealt round-robin, so the shards are balanced (sizes differ by at most
// one), the same on every machine and every re-run, and independent of the order the job lists
// or a folder listing returns them in. The assignment does depend on the set of sequences, which
// is why `imr submit` freezes the list for its array tasks.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace imr::batch {

struct Shard {
  int index = 1;  // 1-based: shard `index` of `count`
  int count = 1;  // 1: no sharding
  bool active() const { return count > 1; }
  std::string ToString() const { return std::to_string(index) + "/" + std::to_string(count); }
  // Empty when usable, otherwise what is wrong.
  std::string Check() const;
};

// "I/N" (1 <= I <= N); nullopt with `error` set otherwise.
std::optional<Shard> ParseShard(const std::string& text, std::string* error);

// The shard of a Slurm array task: index from SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN (divided
// by SLURM_ARRAY_TASK_STEP when set), count from SLURM_ARRAY_TASK_COUNT. nullopt when not in an
// array task (no SLURM_ARRAY_TASK_ID); `error` is set when the variables are inconsistent.
// `getenv` is injectable for tests.
std::optional<Shard> ShardFromSlurm(const std::function<const char*(const char*)>& getenv,
                                    std::string* error);

uint64_t StableHash(std::string_view s);  // FNV-1a 64

// Indices (into `names`, ascending) of the sequences that belong to `shard`.
std::vector<std::size_t> SelectShard(const std::vector<std::string>& names, const Shard& shard);

}  // namespace imr::batch
