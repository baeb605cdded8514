#include "host/plugin/host_services.h"

#include "host/plugin/keyframe_images.h"
#include "host/util/log.h"

#include <atomic>
#include <csignal>
#include <cstdio>

namespace imr::plugin {
namespace {

std::atomic<bool> g_cancel{false};
std::atomic<int> g_cancel_signal{0};

void LogService(void*, int32_t level, const char* message) {
  if (message == nullptr) return;
  switch (level) {
    case IMR_LOG_DEBUG: LogDebug(message); break;
    case IMR_LOG_WARNING: LogWarning(message); break;
    case IMR_LOG_ERROR: LogError(message); break;
    default: LogInfo(message); break;
  }
}

void ProgressService(void*, double fraction, const char* message) {
  LogDebug("progress " + std::to_string(static_cast<int>(fraction * 100.0)) + "%" +
           (message ? std::string(" ") + message : std::string()));
}

int32_t CancelService(void*) { return g_cancel.load() ? 1 : 0; }

imr_status KeyframeImageService(void*, uint64_t index, imr_image_view* out, imr_error* error) {
  std::string message;
  imr_status status = IMR_INVALID_ARGUMENT;
  if (KeyframeImageStore* store = CurrentKeyframeImages(); store != nullptr)
    status = store->Acquire(index, out, &message);
  else
    message = "keyframe image " + std::to_string(index) +
              ": no keyframe images here (only during an export whose request has "
              "keyframe_images set; this input has no images)";
  if (status != IMR_OK && error != nullptr)
    std::snprintf(error->message, sizeof(error->message), "%s", message.c_str());
  return status;
}

void ReleaseKeyframeImageService(void*, uint64_t index) {
  if (KeyframeImageStore* store = CurrentKeyframeImages(); store != nullptr) store->Release(index);
}

}  // namespace

const imr_host_services* HostServices() {
  static const imr_host_services services{sizeof(imr_host_services), IMR_HOST_SERVICES_VERSION,
                                          nullptr,          &LogService,
                                          &ProgressService, &CancelService,
                                          &KeyframeImageService, &ReleaseKeyframeImageService};
  return &services;
}

void RequestCancel(int signal) {
  // The first signal names the cause, but a terminal's (SIGINT, SIGHUP) wins over an earlier
  // SIGTERM: a batch forwards SIGTERM to its sequences, so Ctrl-C to the whole process group can
  // reach a sequence just after its batch's SIGTERM (lock-free atomics: safe in a handler).
  int seen = g_cancel_signal.load();
  while (signal != 0 && (seen == 0 || (seen == SIGTERM && signal != SIGTERM)) &&
         !g_cancel_signal.compare_exchange_weak(seen, signal)) {
  }
  g_cancel = true;
}
bool CancelRequested() { return g_cancel.load(); }
int CancelSignal() { return g_cancel_signal.load(); }
void ClearCancel() {
  g_cancel = false;
  g_cancel_signal = 0;
}

LoadedInstance CreateInstance(const PluginInfo& info, const nlohmann::json& params) {
  return LoadedInstance{info.library,
                        imr::sdk::Instance(info.descriptor, params.dump(), HostServices())};
}

}  // namespace imr::plugin
