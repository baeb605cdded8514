// Finding and loading plugins. Search order (first plugin with a given id wins): a job's
// plugin_paths, then IMR_PLUGIN_PATH (':'-separated), then the installed plugin folder
// (<exe dir>/../lib/imr/plugins, the same relative layout in the build tree and after install).
// An entry is a folder (every *.so in it) or a single .so file. Libraries stay loaded as long as
// the registry, or any instance made from one of its plugins, lives.
#pragma once

#include <imr/sdk/plugin.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace boost::dll {
class shared_library;
}

namespace imr::plugin {

struct PluginInfo {
  std::filesystem::path file;
  const imr_plugin_descriptor* descriptor = nullptr;
  std::shared_ptr<boost::dll::shared_library> library;  // keeps the code mapped
  nlohmann::json params_schema;                           // parsed descriptor->params_schema

  std::string id() const { return descriptor->id; }
  std::string version() const { return descriptor->version; }
  std::string kind() const;
  std::string abi() const;
};

// A library or descriptor that was found but not accepted, and why.
struct Refusal {
  std::filesystem::path file;
  std::string reason;
  std::string ToString() const { return file.string() + ": " + reason; }
};

class PluginRegistry {
 public:
  PluginRegistry();
  ~PluginRegistry();
  PluginRegistry(PluginRegistry&&) noexcept;
  PluginRegistry& operator=(PluginRegistry&&) noexcept;

  // The default search path: IMR_PLUGIN_PATH entries, then the installed folder.
  static std::vector<std::filesystem::path> DefaultSearchPaths();
  // The installed plugin folder next to the running executable, or the one a host that is not
  // the imr executable set (SetInstalledPluginDirectory).
  static std::filesystem::path InstalledPluginDirectory();
  // For hosts whose executable is not imr's (the Python module, whose executable is python3):
  // where their plugins are. Empty: next to the executable again.
  static void SetInstalledPluginDirectory(const std::filesystem::path& directory);

  // Loads every plugin found in `paths`, in order. Entries that do not exist are refusals.
  void Scan(const std::vector<std::filesystem::path>& paths);
  // Loads one library file; returns false (and records a refusal) when it is not usable.
  bool LoadFile(const std::filesystem::path& file);

  const PluginInfo* Find(const std::string& id) const;
  std::vector<std::string> Ids(const std::string& kind = {}) const;
  const std::vector<PluginInfo>& plugins() const { return plugins_; }
  const std::vector<Refusal>& refusals() const { return refusals_; }
  const std::vector<std::filesystem::path>& searched() const { return searched_; }

 private:
  std::vector<PluginInfo> plugins_;
  std::vector<Refusal> refusals_;
  std::vector<std::filesystem::path> searched_;
};

}  // namespace imr::plugin
