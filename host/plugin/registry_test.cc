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
    EXPECT_EQ(p->abi(), "1.1");
  }
  EXPECT_EQ(r.Ids("weight_policy").size(), 3u);
}

TEST(Registry, RefusesWithTheFileNamed) {
  PluginRegistry r;
  r.Scan({IMR_BAD_ABI_PLUGIN, IMR_NO_ENTRY_PLUGIN, "/no/such/folder"});
  ASSERT_EQ(r.refusals().size(), 3u);
  EXPECT_NE(r.refusals()[0].ToString().find("test_bad_abi_plugin.so: plugin #0 refused: built "
                                            "for plugin ABI 2.3, this host speaks ABI 1.1"),
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
