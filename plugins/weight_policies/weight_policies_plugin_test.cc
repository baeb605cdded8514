// The policies through the real shared object and the C ABI, as the host sees them.
#include <imr/sdk/host.hpp>

#include <gtest/gtest.h>

#include <boost/dll/shared_library.hpp>
#include <map>
#include <string>
#include <vector>

namespace {

class PoliciesPlugin : public ::testing::Test {
 protected:
  void SetUp() override {
    lib_.load(IMR_POLICIES_SO, boost::dll::load_mode::rtld_now);
    auto entry = lib_.get<const imr_plugin_descriptor*(uint32_t)>("imr_plugin_entry");
    for (uint32_t i = 0; const imr_plugin_descriptor* d = entry(i); ++i) by_id_[d->id] = d;
  }
  boost::dll::shared_library lib_;
  std::map<std::string, const imr_plugin_descriptor*> by_id_;
};

TEST_F(PoliciesPlugin, ExportsTheThreePoliciesWithValidDescriptors) {
  ASSERT_EQ(by_id_.size(), 3u);
  for (const char* id :
       {"org.imr.policy.mean", "org.imr.policy.weighted_mean", "org.imr.policy.nearest"}) {
    ASSERT_TRUE(by_id_.count(id)) << id;
    const imr_plugin_descriptor* d = by_id_[id];
    EXPECT_EQ(imr::sdk::CheckDescriptor(d), "") << id;
    EXPECT_EQ(d->kind, IMR_KIND_WEIGHT_POLICY);
    EXPECT_EQ(d->abi_major, IMR_ABI_MAJOR);
  }
}

TEST_F(PoliciesPlugin, TransferThroughTheAbiMatchesHandComputedValues) {
  const std::vector<double> rc = {0, 0, 0, 4, 0, 0}, rw = {1.0, 3.0}, ac = {1, 0, 0};
  const std::map<std::string, double> expected = {{"org.imr.policy.mean", 2.0},
                                                  {"org.imr.policy.weighted_mean", 1.5},
                                                  {"org.imr.policy.nearest", 1.0}};
  for (const auto& [id, want] : expected) {
    imr::sdk::Instance inst(by_id_.at(id), "{}", nullptr);
    double out = -1.0;
    imr_transfer_request req{};
    req.removed_centroids = rc.data();
    req.removed_weights = rw.data();
    req.removed_count = 2;
    req.added_centroids = ac.data();
    req.added_count = 1;
    req.added_weights = &out;
    inst.Transfer(&req);
    EXPECT_DOUBLE_EQ(out, want) << id;
  }
}

TEST_F(PoliciesPlugin, MalformedParamsAreRefusedWithAMessage) {
  try {
    imr::sdk::Instance inst(by_id_.at("org.imr.policy.nearest"), "[1,2", nullptr);
    FAIL() << "expected an error";
  } catch (const imr::sdk::PluginCallError& e) {
    EXPECT_EQ(e.status(), IMR_INVALID_ARGUMENT);
    EXPECT_NE(std::string(e.what()).find("params"), std::string::npos) << e.what();
  }
}

}  // namespace
