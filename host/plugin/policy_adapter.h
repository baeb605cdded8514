// Binds a loaded weight-policy plugin to the engine's WeightTransferPolicy interface.
#pragma once

#include "host/engine/weight_transfer_policy.h"
#include "host/plugin/host_services.h"

#include <string>

namespace imr::plugin {

class PluginWeightPolicy : public engine::WeightTransferPolicy {
 public:
  PluginWeightPolicy(LoadedInstance instance, std::string name)
      : instance_(std::move(instance)), name_(std::move(name)) {}

  // The engine's interface must not throw: a plugin failure is kept (first one wins), the
  // weights are set to 0, and the pipeline stops the sequence after the update with the message.
  void Transfer(const engine::TransferInput& in, double* out) override;
  std::string Name() const override { return name_; }

  bool failed() const { return !error_.empty(); }
  const std::string& error() const { return error_; }

 private:
  LoadedInstance instance_;
  std::string name_;
  std::string error_;
};

}  // namespace imr::plugin
