#include "host/plugin/registry.h"

#include "host/plugin/elf_check.h"
#include "host/plugin/host_services.h"
#include "host/plugin/policy_adapter.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>

namespace imr::plugin {
namespace {

TEST(Registry, LoadsTheBuiltInPolicies) {
  PluginRegistry r;
  r.Scan({IMR_PLUGIN_BUILD_DIR});
  for (const char* id : {"org.imr.policy.mean", "org.imr.policy.weighted_mean",
                         "org.imr.policy.nearest"}) {
    const PluginInfo* p = r.Find(id);
    ASSERT_NE(p, nullptr) << id;
    EXPECT_EQ(p->kind(), "weight_policy");
    EXPECT_EQ(p->abi(), "1." + std::to_string(IMR_ABI_MINOR));
  }
  EXPECT_EQ(r.Ids("weight_policy").size(), 3u);
}

TEST(Registry, RefusesWithTheFileNamed) {
  PluginRegistry r;
  r.Scan({IMR_BAD_ABI_PLUGIN, IMR_NO_ENTRY_PLUGIN, "/no/such/folder"});
  ASSERT_EQ(r.refusals().size(), 3u);
  EXPECT_NE(r.refusals()[0].ToString().find("test_bad_abi_plugin.so: plugin #0 refused: built "
                                            "for plugin ABI 2.3, this host speaks ABI 1." +
                                            std::to_string(IMR_ABI_MINOR)),
            std::string::npos)
      << r.refusals()[0].ToString();
  EXPECT_NE(r.refusals()[1].ToString().find("no entry symbol"), std::string::npos);
  EXPECT_NE(r.refusals()[2].ToString().find("/no/such/folder: plugin path does not exist"),
            std::string::npos);
  EXPECT_TRUE(r.plugins().empty());
}

TEST(Registry, FilesAreJudgedByTheirElfHeadersBeforeLoading) {
  // Cut short: refused by size (dlopen would map past the end: SIGBUS).
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("imr-elf-test-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ifstream in(IMR_EXAMPLE_PLUGIN, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(dir / "half.so", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  std::ofstream(dir / "script.so") << "/* GNU ld script */\nGROUP ( libc.so.6 )\n";
  ElfCheck c = CheckElfFile(dir / "half.so", IMR_ENTRY_SYMBOL);
  EXPECT_EQ(c.problem.rfind("truncated: " + std::to_string(bytes.size() / 2) + " bytes", 0), 0u) << c.problem;
  c = CheckElfFile(dir / "script.so", IMR_ENTRY_SYMBOL);
  EXPECT_NE(c.problem.find("not an ELF shared library"), std::string::npos) << c.problem;
  c = CheckElfFile(IMR_EXAMPLE_PLUGIN, IMR_ENTRY_SYMBOL);
  EXPECT_EQ(c.problem, "");
  EXPECT_TRUE(c.symbols_known && c.has_entry);
  c = CheckElfFile(IMR_NO_ENTRY_PLUGIN, IMR_ENTRY_SYMBOL);
  EXPECT_EQ(c.problem, "");
  EXPECT_TRUE(c.symbols_known);
  EXPECT_FALSE(c.has_entry);
  std::filesystem::remove_all(dir);
}

TEST(Registry, FirstPathWinsForAnId) {
  PluginRegistry r;
  r.Scan({IMR_PLUGIN_BUILD_DIR, IMR_PLUGIN_BUILD_DIR});
  EXPECT_EQ(r.Ids("weight_policy").size(), 3u);
  ASSERT_FALSE(r.refusals().empty());
  EXPECT_NE(r.refusals()[0].reason.find("already provided by"), std::string::npos);
}

// plugin.h: a host accepts plugins of any minor and reads only the fields their struct_size
// covers. A C plugin whose descriptor is the ABI 1.0 prefix alone (96 bytes, smaller than this
// host's) loads, is created and does its work.
TEST(Registry, LoadsAPluginBuiltAgainstASmallerDescriptor) {
  PluginRegistry r;
  r.Scan({IMR_C_DESCRIPTOR_1_0_PLUGIN});
  ASSERT_TRUE(r.refusals().empty()) << r.refusals()[0].ToString();
  const PluginInfo* info = r.Find("org.imr.test.policy.c_descriptor_1_0");
  ASSERT_NE(info, nullptr);
  EXPECT_EQ(info->descriptor->struct_size, IMR_DESCRIPTOR_SIZE_1_0);
  EXPECT_LT(info->descriptor->struct_size, sizeof(imr_plugin_descriptor));
  EXPECT_EQ(info->abi(), "1.0");
  EXPECT_EQ(info->kind(), "weight_policy");
  PluginWeightPolicy policy(CreateInstance(*info, nlohmann::json::object()), info->id());
  const double rc[] = {0, 0, 0, 1, 0, 0}, rw[] = {2.0, 5.0}, nc[] = {0.5, 0, 0, 9, 9, 9};
  double out[2] = {-1, -1};
  policy.Transfer({rc, rw, 2, nc, 2}, out);
  EXPECT_FALSE(policy.failed()) << policy.error();
  EXPECT_EQ(out[0], 5.0);
  EXPECT_EQ(out[1], 5.0);
  // Its create refuses params it does not take, and a failed create leaves nothing to destroy.
  try {
    CreateInstance(*info, {{"radius", 1.0}});
    ADD_FAILURE() << "params accepted";
  } catch (const imr::sdk::PluginCallError& e) {
    EXPECT_EQ(e.status(), IMR_INVALID_ARGUMENT);
    EXPECT_NE(std::string(e.what()).find("params: none accepted"), std::string::npos) << e.what();
  }
}

// What the host refuses below the ABI 1.0 sizes, with the sizes named.
TEST(Registry, CheckDescriptorWantsTheAbi10Sizes) {
  static const imr_weight_policy_api api{sizeof(imr_weight_policy_api), 0,
                                         [](imr_instance*, const imr_transfer_request*,
                                            imr_error*) -> imr_status { return IMR_OK; }};
  imr_plugin_descriptor d{};
  d.struct_size = IMR_DESCRIPTOR_SIZE_1_0;
  d.abi_major = IMR_ABI_MAJOR;
  d.kind = IMR_KIND_WEIGHT_POLICY;
  d.id = "org.imr.test.sizes";
  d.version = "1";
  d.create = [](const char*, const imr_host_services*, imr_instance**, imr_error*) -> imr_status {
    return IMR_ERROR;
  };
  d.destroy = [](imr_instance*) {};
  d.weight_policy = &api;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d), "");
  d.struct_size = IMR_DESCRIPTOR_SIZE_1_0 - 8;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d), "descriptor is 88 bytes, expected at least 96 (its ABI 1.0 size)");
  d.struct_size = IMR_DESCRIPTOR_SIZE_1_0;
  imr_weight_policy_api small = api;
  small.struct_size = 8;
  d.weight_policy = &small;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d),
            "weight_policy table is 8 bytes, expected at least 16 (its ABI 1.0 size)");
  imr_weight_policy_api empty = api;
  empty.transfer = nullptr;
  d.weight_policy = &empty;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d), "weight_policy table lacks its function");
}

// A mesh refiner (a kind of ABI 1.4) needs the descriptor's 1.4 tail, where its table is.
TEST(Registry, CheckDescriptorWantsTheMeshRefinersTable) {
  static const imr_mesh_refiner_api api{
      sizeof(imr_mesh_refiner_api), 0,
      [](imr_instance*, const imr_refine_request*, imr_refine_result*, imr_error*) -> imr_status {
        return IMR_OK;
      }};
  imr_plugin_descriptor d{};
  d.struct_size = sizeof(imr_plugin_descriptor);
  d.abi_major = IMR_ABI_MAJOR;
  d.abi_minor = 4;
  d.kind = IMR_KIND_MESH_REFINER;
  d.id = "org.imr.test.refine";
  d.version = "1";
  d.create = [](const char*, const imr_host_services*, imr_instance**, imr_error*) -> imr_status {
    return IMR_ERROR;
  };
  d.destroy = [](imr_instance*) {};
  d.mesh_refiner = &api;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d), "");
  d.struct_size = IMR_DESCRIPTOR_SIZE_1_0;  // a 1.0-1.3 descriptor cannot carry the table
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d),
            "kind is mesh_refiner (ABI 1.4) but the descriptor is 96 bytes, expected at least 104");
  d.struct_size = sizeof(imr_plugin_descriptor);
  d.mesh_refiner = nullptr;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d), "kind is mesh_refiner but its function table is missing");
  imr_mesh_refiner_api small = api;
  small.struct_size = 8;
  d.mesh_refiner = &small;
  EXPECT_EQ(imr::sdk::CheckDescriptor(&d),
            "mesh_refiner table is 8 bytes, expected at least 16 (its ABI 1.4 size)");
}

TEST(PolicyAdapter, DrivesAPluginThroughTheEngineInterface) {
  PluginRegistry r;
  r.LoadFile(IMR_EXAMPLE_PLUGIN);
  const PluginInfo* info = r.Find("org.imr.example.policy.max");
  ASSERT_NE(info, nullptr);
  PluginWeightPolicy policy(CreateInstance(*info, {{"radius", 10.0}}), info->id());
  const double rc[] = {0, 0, 0, 1, 0, 0}, rw[] = {2.0, 5.0}, nc[] = {0.5, 0, 0};
  double out = -1;
  policy.Transfer({rc, rw, 2, nc, 1}, &out);
  EXPECT_FALSE(policy.failed()) << policy.error();
  EXPECT_EQ(out, 5.0);
}

}  // namespace
}  // namespace imr::plugin
