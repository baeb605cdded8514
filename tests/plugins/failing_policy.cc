// Test plugins that misbehave on purpose, to check the host's handling: a policy whose create
// fails on a param, one that returns an error from transfer, one that returns NaN weights, one
// that returns negative weights (finite, so only `imr run --check-invariants` catches them), one
// that hangs in transfer (for the stage timeout), one that is slow (a run to signal midway). With
// "only_in", it misbehaves only in the process of the sequence of that name, so one job can hold
// a bad and a good sequence.
#include <imr/sdk/plugin.hpp>

#include <chrono>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <thread>

namespace {

// The sequence this process runs: the argument after "--sequence" in imr run's per-sequence
// command line ("" elsewhere).
std::string SequenceOfThisProcess() {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string flag = std::string("--sequence") + '\0';
  const auto at = all.find(flag);
  if (at == std::string::npos) return {};
  const auto begin = at + flag.size();
  return all.substr(begin, all.find('\0', begin) - begin);
}

class FailingPolicy : public imr::sdk::WeightPolicy {
 public:
  static constexpr const char* kId = "org.imr.test.policy.failing";
  static constexpr const char* kVersion = "0.0.1";
  static constexpr const char* kDescription = "test: fails on request";
  static constexpr const char* kParamsSchema = R"({
    "fail_create": {"type": "boolean", "default": false},
    "fail_after": {"type": "integer", "default": -1, "description": "transfer calls before failing"},
    "nan": {"type": "boolean", "default": false},
    "negative": {"type": "boolean", "default": false},
    "hang": {"type": "boolean", "default": false, "description": "transfer never returns"},
    "sleep_ms": {"type": "integer", "default": 0, "description": "each transfer sleeps this long"},
    "only_in": {"type": "string", "default": "", "description": "misbehave only in this sequence's process"}
  })";
  FailingPolicy(const imr::sdk::Params& p, const imr::sdk::Host&)
      : active_(p.Get<std::string>("only_in", "").empty() ||
                p.Get<std::string>("only_in", "") == SequenceOfThisProcess()),
        fail_after_(active_ ? p.Get<int>("fail_after", -1) : -1),
        nan_(active_ && p.Get<bool>("nan", false)),
        negative_(active_ && p.Get<bool>("negative", false)),
        hang_(active_ && p.Get<bool>("hang", false)),
        sleep_ms_(active_ ? p.Get<int>("sleep_ms", 0) : 0) {
    if (active_ && p.Get<bool>("fail_create", false))
      throw imr::sdk::InvalidArgument("params.fail_create: asked to fail");
  }
  void Transfer(const imr::sdk::TransferRequest& r) override {
    while (hang_) std::this_thread::sleep_for(std::chrono::seconds(1));
    if (sleep_ms_ > 0) std::this_thread::sleep_for(std::chrono::milliseconds(sleep_ms_));
    if (fail_after_ >= 0 && calls_++ >= fail_after_)
      throw std::runtime_error("failing policy: transfer failed on purpose");
    for (auto& w : r.added_weights)
      w = nan_ ? std::numeric_limits<double>::quiet_NaN() : negative_ ? -3.0 : 1.0;
  }

 private:
  bool active_;
  int fail_after_;
  bool nan_;
  bool negative_;
  bool hang_;
  int sleep_ms_;
  int calls_ = 0;
};

}  // namespace

IMR_PLUGIN_EXPORT(FailingPolicy)
