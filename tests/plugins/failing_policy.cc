// Test plugins that misbehave on purpose, to check the host's handling: a policy whose create
// fails on a param, one that returns an error from transfer, one that returns NaN weights.
#include <imr/sdk/plugin.hpp>

#include <limits>

namespace {

class FailingPolicy : public imr::sdk::WeightPolicy {
 public:
  static constexpr const char* kId = "org.imr.test.policy.failing";
  static constexpr const char* kVersion = "0.0.1";
  static constexpr const char* kDescription = "test: fails on request";
  static constexpr const char* kParamsSchema = R"({
    "fail_create": {"type": "boolean", "default": false},
    "fail_after": {"type": "integer", "default": -1, "description": "transfer calls before failing"},
    "nan": {"type": "boolean", "default": false}
  })";
  FailingPolicy(const imr::sdk::Params& p, const imr::sdk::Host&)
      : fail_after_(p.Get<int>("fail_after", -1)), nan_(p.Get<bool>("nan", false)) {
    if (p.Get<bool>("fail_create", false))
      throw imr::sdk::InvalidArgument("params.fail_create: asked to fail");
  }
  void Transfer(const imr::sdk::TransferRequest& r) override {
    if (fail_after_ >= 0 && calls_++ >= fail_after_)
      throw std::runtime_error("failing policy: transfer failed on purpose");
    for (auto& w : r.added_weights) w = nan_ ? std::numeric_limits<double>::quiet_NaN() : 1.0;
  }

 private:
  int fail_after_;
  bool nan_;
  int calls_ = 0;
};

}  // namespace

IMR_PLUGIN_EXPORT(FailingPolicy)
