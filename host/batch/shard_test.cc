#include "host/batch/shard.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

namespace imr::batch {
namespace {

TEST(Shard, ParsesIOverN) {
  std::string error;
  auto s = ParseShard("2/5", &error);
  ASSERT_TRUE(s) << error;
  EXPECT_EQ(s->index, 2);
  EXPECT_EQ(s->count, 5);
  EXPECT_TRUE(s->active());
  EXPECT_FALSE(ParseShard("1/1", &error)->active());
  for (const char* bad : {"0/2", "3/2", "2", "a/b", "1/0", "-1/2", "1/2/3", "", "/2", "1/"}) {
    error.clear();
    EXPECT_FALSE(ParseShard(bad, &error)) << bad;
    EXPECT_NE(error.find(bad), std::string::npos) << bad << ": " << error;
  }
}

TEST(Shard, ComesFromSlurmArrayVariables) {
  std::map<std::string, std::string> env;
  auto getenv = [&](const char* k) -> const char* {
    auto it = env.find(k);
    return it == env.end() ? nullptr : it->second.c_str();
  };
  std::string error;
  EXPECT_FALSE(ShardFromSlurm(getenv, &error));  // not in an array task
  EXPECT_TRUE(error.empty());
  env = {{"SLURM_ARRAY_TASK_ID", "5"}, {"SLURM_ARRAY_TASK_MIN", "4"}, {"SLURM_ARRAY_TASK_COUNT", "3"}};
  auto s = ShardFromSlurm(getenv, &error);
  ASSERT_TRUE(s) << error;
  EXPECT_EQ(s->ToString(), "2/3");
  // --array=0-10:5 -> ids 0, 5, 10: the third task is shard 3/3.
  env = {{"SLURM_ARRAY_TASK_ID", "10"}, {"SLURM_ARRAY_TASK_MIN", "0"},
         {"SLURM_ARRAY_TASK_COUNT", "3"}, {"SLURM_ARRAY_TASK_STEP", "5"}};
  ASSERT_TRUE(s = ShardFromSlurm(getenv, &error)) << error;
  EXPECT_EQ(s->ToString(), "3/3");
  env = {{"SLURM_ARRAY_TASK_ID", "1"}};
  EXPECT_FALSE(ShardFromSlurm(getenv, &error));
  EXPECT_NE(error.find("SLURM_ARRAY_TASK_COUNT is not set"), std::string::npos) << error;
  env = {{"SLURM_ARRAY_TASK_ID", "7"}, {"SLURM_ARRAY_TASK_COUNT", "2"}};
  error.clear();
  EXPECT_FALSE(ShardFromSlurm(getenv, &error));
  EXPECT_NE(error.find("shard index must be in 1..2"), std::string::npos) << error;
}

TEST(Shard, HashIsFnv1a) {
  // Published FNV-1a 64 values: the assignment must never change between imr versions.
  EXPECT_EQ(StableHash(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(StableHash("a"), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(StableHash("foobar"), 0x85944171f73967e8ull);
}

std::vector<std::string> Names(int n) {
  std::vector<std::string> names;
  for (int i = 0; i < n; ++i) names.push_back("seq" + std::to_string(i * 7 % 101));
  return names;
}

TEST(Shard, ShardsCoverEverySequenceOnceAndAreBalanced) {
  for (int n : {0, 1, 2, 3, 4, 5, 17, 64}) {
    for (int count : {1, 2, 3, 4, 7}) {
      const auto names = Names(n);
      std::multiset<std::string> seen;
      std::size_t smallest = names.size(), largest = 0;
      for (int i = 1; i <= count; ++i) {
        const auto mine = SelectShard(names, {i, count});
        EXPECT_TRUE(std::is_sorted(mine.begin(), mine.end()));
        for (std::size_t k : mine) seen.insert(names[k]);
        smallest = std::min(smallest, mine.size());
        largest = std::max(largest, mine.size());
      }
      EXPECT_EQ(seen, std::multiset<std::string>(names.begin(), names.end())) << n << " in " << count;
      EXPECT_LE(largest - std::min(smallest, largest), 1u) << n << " in " << count;
    }
  }
}

TEST(Shard, AssignmentDoesNotDependOnListingOrder) {
  auto names = Names(23);
  std::map<std::string, int> first;
  for (int i = 1; i <= 4; ++i)
    for (std::size_t k : SelectShard(names, {i, 4})) first[names[k]] = i;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 5; ++trial) {
    std::shuffle(names.begin(), names.end(), rng);
    for (int i = 1; i <= 4; ++i)
      for (std::size_t k : SelectShard(names, {i, 4})) EXPECT_EQ(first[names[k]], i) << names[k];
  }
}

}  // namespace
}  // namespace imr::batch
