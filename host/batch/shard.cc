#include "host/batch/shard.h"

#include <algorithm>
#include <charconv>
#include <numeric>

namespace imr::batch {
namespace {

bool ParseInt(std::string_view s, long long* out) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && !s.empty();
}

}  // namespace

std::string Shard::Check() const {
  if (count < 1) return "shard count must be at least 1, got " + std::to_string(count);
  if (index < 1 || index > count)
    return "shard index must be in 1.." + std::to_string(count) + ", got " + std::to_string(index);
  return {};
}

std::optional<Shard> ParseShard(const std::string& text, std::string* error) {
  const auto slash = text.find('/');
  long long i = 0, n = 0;
  if (slash == std::string::npos || !ParseInt(std::string_view(text).substr(0, slash), &i) ||
      !ParseInt(std::string_view(text).substr(slash + 1), &n) || n > 1000000 || i > n || i < 0) {
    *error = "expected I/N with 1 <= I <= N (e.g. 1/4), got '" + text + "'";
    return std::nullopt;
  }
  Shard s{static_cast<int>(i), static_cast<int>(n)};
  if (std::string e = s.Check(); !e.empty()) {
    *error = e + " in '" + text + "' (shards are numbered from 1)";
    return std::nullopt;
  }
  return s;
}

std::optional<Shard> ShardFromSlurm(const std::function<const char*(const char*)>& getenv,
                                    std::string* error) {
  const char* id = getenv("SLURM_ARRAY_TASK_ID");
  if (id == nullptr || *id == '\0') return std::nullopt;
  auto number = [&](const char* name, long long fallback, long long* out) {
    const char* v = getenv(name);
    if (v == nullptr || *v == '\0') {
      if (fallback < 0) {
        *error = std::string(name) + " is not set (SLURM_ARRAY_TASK_ID is " + id + ")";
        return false;
      }
      *out = fallback;
      return true;
    }
    if (!ParseInt(v, out)) {
      *error = std::string(name) + ": expected an integer, got '" + v + "'";
      return false;
    }
    return true;
  };
  long long task = 0, min = 0, count = 0, step = 1;
  if (!number("SLURM_ARRAY_TASK_ID", -1, &task) || !number("SLURM_ARRAY_TASK_MIN", 0, &min) ||
      !number("SLURM_ARRAY_TASK_COUNT", -1, &count) || !number("SLURM_ARRAY_TASK_STEP", 1, &step))
    return std::nullopt;
  if (step < 1) step = 1;
  const long long index = (task - min) / step + 1;
  Shard s{static_cast<int>(index), static_cast<int>(count)};
  if (std::string e = s.Check(); !e.empty()) {
    *error = "Slurm array task " + std::to_string(task) + " (min " + std::to_string(min) +
             ", count " + std::to_string(count) + "): " + e;
    return std::nullopt;
  }
  return s;
}

uint64_t StableHash(std::string_view s) {
  uint64_t h = 14695981039346656037ull;  // FNV offset basis
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::vector<std::size_t> SelectShard(const std::vector<std::string>& names, const Shard& shard) {
  std::vector<std::size_t> order(names.size());
  std::iota(order.begin(), order.end(), 0);
  if (!shard.active()) return order;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const uint64_t ha = StableHash(names[a]), hb = StableHash(names[b]);
    return ha != hb ? ha < hb : names[a] < names[b];
  });
  std::vector<std::size_t> mine;
  for (std::size_t rank = 0; rank < order.size(); ++rank)
    if (static_cast<int>(rank % static_cast<std::size_t>(shard.count)) == shard.index - 1)
      mine.push_back(order[rank]);
  std::sort(mine.begin(), mine.end());
  return mine;
}

}  // namespace imr::batch
