#include "host/util/exit_status.h"

#include <gtest/gtest.h>

namespace imr {
namespace {

TEST(ExitStatus, CountsFailuresBelowTheUsageCode) {
  EXPECT_EQ(ExitStatusForFailures(0), kExitOk);
  EXPECT_EQ(ExitStatusForFailures(1), 1);
  EXPECT_EQ(ExitStatusForFailures(17), 17);
  EXPECT_EQ(ExitStatusForFailures(63), 63);
  EXPECT_EQ(ExitStatusForFailures(5000), kExitMaxFailures);  // never 64 (usage) or wrapped
  EXPECT_LT(ExitStatusForFailures(1 << 20), kExitUsage);
  EXPECT_EQ(ExitStatusForFailures(256) % 256, kExitMaxFailures);  // 256 would read as 0
}

TEST(ExitStatus, EnvironmentErrorsAreNeitherFailureCountsNorUsage) {
  for (int code : {kExitCantCreate, kExitTempFail}) {
    EXPECT_GT(code, kExitUsage);
    EXPECT_LT(code, 126);  // 126 and up: the shell's (not executable, not found, signals)
  }
  EXPECT_NE(kExitCantCreate, kExitTempFail);
}

}  // namespace
}  // namespace imr
