// The engine's modes as the in-process benches name them (engine, paper, scaling):
// engine::testing::ConfigureMode's names.
#pragma once

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "host/engine/testing/run_stream.h"

namespace imr::bench {

// True when every mode is one ConfigureMode knows; else false, the first unknown one named
// ("imr-bench BENCH: unknown mode 'M'").
inline bool KnownModes(const std::vector<std::string>& modes, const char* bench) {
  for (const std::string& m : modes) {
    engine::EngineOptions eo;
    std::unique_ptr<engine::WeightTransferPolicy> p;
    if (!engine::testing::ConfigureMode(m, &eo, &p)) {
      std::fprintf(stderr, "imr-bench %s: unknown mode '%s'\n", bench, m.c_str());
      return false;
    }
  }
  return true;
}

}  // namespace imr::bench
