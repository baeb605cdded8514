// The plugin author's path, for real: install the SDK into a temporary prefix, build a plugin
// from a folder outside the source tree against it alone (find_package(imr_sdk)), and show the
// already-built imr loading it and running a job with it. Then a plugin built against an SDK of
// another ABI major is refused with both versions named.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "test_util.h"

#include <imr/sdk/plugin.h>

namespace imr::testing {
namespace {
namespace fs = std::filesystem;

const std::string kCmake = IMR_CMAKE_COMMAND;

class OutOfTree : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new ScratchDir("oot");
    prefix_ = scratch_->path() / "prefix";
    auto r = RunShell(kCmake + " --install " + Quote(IMR_BINARY_DIR) + " --prefix " + Quote(prefix_.string()));
    install_ok_ = r.status == 0;
    install_log_ = r.out + r.err;
  }
  static void TearDownTestSuite() { delete scratch_; }

  // Copies the example plugin's folder, as installed with the SDK, and builds it against `prefix`.
  static CommandResult BuildExample(const fs::path& prefix, const fs::path& where) {
    fs::create_directories(where);
    fs::copy(prefix / "share" / "doc" / "imr_sdk" / "examples" / "max_policy", where / "src",
             fs::copy_options::recursive);
    // Only the prefix is on the search path: no access to the imr source or build tree.
    return RunShell(kCmake + " -S " + Quote((where / "src").string()) + " -B " +
               Quote((where / "build").string()) + " -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=" +
               Quote(prefix.string()) + " && " + kCmake + " --build " +
               Quote((where / "build").string()));
  }

  static ScratchDir* scratch_;
  static fs::path prefix_;
  static bool install_ok_;
  static std::string install_log_;
};
ScratchDir* OutOfTree::scratch_ = nullptr;
fs::path OutOfTree::prefix_;
bool OutOfTree::install_ok_ = false;
std::string OutOfTree::install_log_;

TEST_F(OutOfTree, InstallHasTheSdkPackageAndAWorkingImr) {
  ASSERT_TRUE(install_ok_) << install_log_;
  EXPECT_TRUE(fs::exists(prefix_ / "include" / "imr" / "sdk" / "plugin.h"));
  EXPECT_TRUE(fs::exists(prefix_ / "lib" / "cmake" / "imr_sdk" / "imr_sdkConfig.cmake"));
  // The SDK's documentation (its headers, the contract in plugin.h) and examples install with it
  // and point to nothing outside it.
  const fs::path examples = prefix_ / "share" / "doc" / "imr_sdk" / "examples";
  EXPECT_TRUE(fs::exists(examples / "max_policy" / "max_policy.cc"));
  EXPECT_TRUE(fs::exists(examples / "vertex_color_exporter" / "vertex_color_exporter.cc"));
  EXPECT_NE(ReadText(prefix_ / "include" / "imr" / "sdk" / "plugin.h").find("THE CONTRACT"),
            std::string::npos);
  for (const fs::path& root : {prefix_ / "include" / "imr", examples}) {
    for (const auto& entry : fs::recursive_directory_iterator(root)) {
      if (!entry.is_regular_file()) continue;
      EXPECT_EQ(ReadText(entry.path()).find("DESIGN"), std::string::npos) << entry.path();
    }
  }
  // The installed imr finds the installed plugins with no configuration.
  auto r = RunShell(Quote((prefix_ / "bin" / "imr").string()) + " plugins");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("org.imr.policy.nearest"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find((prefix_ / "lib" / "imr" / "plugins").string()), std::string::npos) << r.out;
}

TEST_F(OutOfTree, PluginBuiltAgainstTheInstalledSdkLoadsAndRuns) {
  ASSERT_TRUE(install_ok_) << install_log_;
  const fs::path where = scratch_->path() / "plugin";
  auto b = BuildExample(prefix_, where);
  ASSERT_EQ(b.status, 0) << b.out << b.err;
  const fs::path so = where / "build" / "example_max_policy.so";
  ASSERT_TRUE(fs::exists(so));

  const std::string env = "IMR_PLUGIN_PATH=" + Quote((where / "build").string()) + " ";
  auto r = RunShell(env + IMR_EXE + " plugins");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("org.imr.example.policy.max"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(so.string()), std::string::npos) << r.out;

  // A job uses it as its weight policy, with a parameter.
  nlohmann::json job = {
      {"sequences", {"street"}},
      {"input", {{"format", "synthetic"}, {"options", {{"frames", 30}}}}},
      {"pipeline",
       {{{"kind", "weight_policy"}, {"plugin", "org.imr.example.policy.max"}, {"params", {{"radius", 0.5}}}},
        {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", "out/{sequence}"}, {"formats", {"ply"}}}}};
  WriteText(where / "job.json", job.dump(2));
  auto run = RunShell(env + IMR_EXE + " run -q " + Quote((where / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.out << run.err;
  const auto report = nlohmann::json::parse(ReadText(where / "out" / "street" / "report.json"));
  EXPECT_EQ(report["plugins"][0]["id"], "org.imr.example.policy.max");
  EXPECT_EQ(report["plugins"][0]["params"]["radius"], 0.5);
  EXPECT_TRUE(fs::exists(where / "out" / "street" / "mesh.ply"));
}

TEST_F(OutOfTree, PluginOfAnotherAbiMajorIsRefused) {
  ASSERT_TRUE(install_ok_) << install_log_;
  // A future SDK: the same install with the ABI major bumped.
  const fs::path future = scratch_->path() / "future-prefix";
  fs::copy(prefix_, future, fs::copy_options::recursive);
  const fs::path header = future / "include" / "imr" / "sdk" / "plugin.h";
  std::string text = ReadText(header);
  const std::string from = "#define IMR_ABI_MAJOR 1", to = "#define IMR_ABI_MAJOR 2";
  ASSERT_NE(text.find(from), std::string::npos);
  text.replace(text.find(from), from.size(), to);
  WriteText(header, text);

  const fs::path where = scratch_->path() / "future-plugin";
  auto b = BuildExample(future, where);
  ASSERT_EQ(b.status, 0) << b.out << b.err;
  const fs::path so = where / "build" / "example_max_policy.so";
  auto r = RunShell("IMR_PLUGIN_PATH=" + Quote(so.string()) + " " + IMR_EXE + " plugins");
  ASSERT_EQ(r.status, 0) << r.err;
  const std::string minor = std::to_string(IMR_ABI_MINOR);
  EXPECT_NE(r.out.find(so.string() + ": plugin #0 refused: built for plugin ABI 2." + minor +
                       ", this host speaks ABI 1." + minor),
            std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("org.imr.example.policy.max "), std::string::npos) << r.out;
}

}  // namespace
}  // namespace imr::testing
