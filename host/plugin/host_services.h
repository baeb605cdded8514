// The services the host hands to every plugin instance (SDK imr_host_services): log lines go to
// imr's log, progress to debug lines, cancellation follows SIGINT/SIGTERM/SIGHUP, keyframe images
// come from the store a ScopedKeyframeImages installed (keyframe_images.h).
#pragma once

#include <imr/sdk/plugin.h>

#include <memory>
#include <string>

#include "host/plugin/registry.h"

#include <imr/sdk/host.hpp>

namespace imr::plugin {

// Services shared by all instances of this process.
const imr_host_services* HostServices();

// Cancellation: set by the signal handlers the CLI installs (async-signal-safe); plugins poll
// it. CancelSignal: the first signal that asked (0: none, or asked without a signal), or a
// SIGINT / SIGHUP that came after a SIGTERM (the batch's forward of a Ctrl-C the group got too).
void RequestCancel(int signal = 0);
bool CancelRequested();
int CancelSignal();
// Clears a cancel request: for hosts that run many calls in one process (the Python module: a
// Ctrl-C stops one call, the next one starts afresh). The CLI never clears it.
void ClearCancel();

// An instance of a loaded plugin that also keeps its library loaded.
struct LoadedInstance {
  std::shared_ptr<boost::dll::shared_library> library;  // declared first: destroyed last
  imr::sdk::Instance instance;
};

// Creates an instance from a registry entry with `params` (defaults already filled in).
// Throws imr::sdk::PluginCallError naming the plugin and its message on failure.
LoadedInstance CreateInstance(const PluginInfo& info, const nlohmann::json& params);

}  // namespace imr::plugin
