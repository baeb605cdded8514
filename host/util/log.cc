#include "host/util/log.h"

#include <atomic>
#include <cstdio>
#include <mutex>

namespace imr {
namespace {
std::atomic<int> g_level{static_cast<int>(LogLevel::kInfo)};
std::mutex g_mutex;
const char* Prefix(LogLevel l) {
  switch (l) {
    case LogLevel::kDebug: return "debug: ";
    case LogLevel::kWarning: return "warning: ";
    case LogLevel::kError: return "error: ";
    default: return "";
  }
}
}  // namespace

void SetLogLevel(LogLevel level) { g_level = static_cast<int>(level); }
LogLevel GetLogLevel() { return static_cast<LogLevel>(g_level.load()); }

void Log(LogLevel level, const std::string& message) {
  // Errors are always shown: a quiet run still says why it failed.
  if (level != LogLevel::kError && static_cast<int>(level) < g_level.load()) return;
  std::lock_guard<std::mutex> lock(g_mutex);
  std::fprintf(stderr, "%s%s\n", Prefix(level), message.c_str());
  std::fflush(stderr);
}

}  // namespace imr
