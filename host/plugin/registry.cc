#include "host/plugin/registry.h"

#include "host/io/schema.h"

#include <imr/sdk/host.hpp>

#include <boost/dll/runtime_symbol_info.hpp>
#include <boost/dll/shared_library.hpp>

#include <algorithm>
#include <cstdlib>
#include <sstream>

namespace imr::plugin {
namespace fs = std::filesystem;

std::string PluginInfo::kind() const { return imr::sdk::KindName(descriptor->kind); }
std::string PluginInfo::abi() const {
  return std::to_string(descriptor->abi_major) + "." + std::to_string(descriptor->abi_minor);
}

PluginRegistry::PluginRegistry() = default;
PluginRegistry::~PluginRegistry() = default;
PluginRegistry::PluginRegistry(PluginRegistry&&) noexcept = default;
PluginRegistry& PluginRegistry::operator=(PluginRegistry&&) noexcept = default;

fs::path PluginRegistry::InstalledPluginDirectory() {
  std::error_code ec;
  fs::path exe = boost::dll::program_location().native();
  return (exe.parent_path() / ".." / "lib" / "imr" / "plugins").lexically_normal();
}

std::vector<fs::path> PluginRegistry::DefaultSearchPaths() {
  std::vector<fs::path> paths;
  if (const char* env = std::getenv("IMR_PLUGIN_PATH")) {
    std::stringstream ss(env);
    for (std::string item; std::getline(ss, item, ':');)
      if (!item.empty()) paths.emplace_back(item);
  }
  paths.push_back(InstalledPluginDirectory());
  return paths;
}

void PluginRegistry::Scan(const std::vector<fs::path>& paths) {
  for (const auto& entry : paths) {
    searched_.push_back(entry);
    std::error_code ec;
    if (fs::is_directory(entry, ec)) {
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(entry, ec))
        if (e.is_regular_file() && e.path().extension() == ".so") files.push_back(e.path());
      std::sort(files.begin(), files.end());  // deterministic precedence within a folder
      for (const auto& f : files) LoadFile(f);
    } else if (fs::is_regular_file(entry, ec)) {
      LoadFile(entry);
    } else {
      refusals_.push_back({entry, "plugin path does not exist"});
    }
  }
}

bool PluginRegistry::LoadFile(const fs::path& file) {
  auto lib = std::make_shared<boost::dll::shared_library>();
  try {
    // RTLD_NOW: an unresolved symbol fails here, with the loader's message, not mid-run.
    lib->load(boost::dll::fs::path(file.string()),
              boost::dll::load_mode::rtld_now | boost::dll::load_mode::rtld_local);
  } catch (const std::exception& e) {
    refusals_.push_back({file, std::string("cannot load: ") + e.what()});
    return false;
  }
  if (!lib->has(IMR_ENTRY_SYMBOL)) {
    refusals_.push_back({file, std::string("not an imr plugin: no entry symbol '") +
                                   IMR_ENTRY_SYMBOL + "'"});
    return false;
  }
  auto entry = lib->get<const imr_plugin_descriptor*(uint32_t)>(IMR_ENTRY_SYMBOL);
  bool any = false;
  for (uint32_t i = 0; i < 1024; ++i) {
    const imr_plugin_descriptor* d = entry(i);
    if (d == nullptr) break;
    // The prefix (size, ABI) is readable in every ABI version; check it before anything else.
    const std::string problem = imr::sdk::CheckDescriptor(d);
    if (!problem.empty()) {
      std::string who = d->abi_major == IMR_ABI_MAJOR && d->id ? std::string(" (") + d->id + ")" : "";
      refusals_.push_back({file, "plugin #" + std::to_string(i) + who + " refused: " + problem});
      continue;
    }
    nlohmann::json schema = nlohmann::json::object();
    if (d->params_schema != nullptr && *d->params_schema != '\0') {
      schema = nlohmann::json::parse(d->params_schema, nullptr, false);
      auto problems = io::CheckSchema(schema, "params_schema");
      if (schema.is_discarded()) problems.push_back({"params_schema", "malformed JSON"});
      if (!problems.empty()) {
        refusals_.push_back({file, std::string(d->id) + " refused: " + problems[0].ToString()});
        continue;
      }
    }
    if (const PluginInfo* existing = Find(d->id)) {
      refusals_.push_back({file, std::string(d->id) + " ignored: already provided by " +
                                     existing->file.string()});
      continue;
    }
    plugins_.push_back(PluginInfo{file, d, lib, std::move(schema)});
    any = true;
  }
  return any;
}

const PluginInfo* PluginRegistry::Find(const std::string& id) const {
  for (const auto& p : plugins_)
    if (id == p.descriptor->id) return &p;
  return nullptr;
}

std::vector<std::string> PluginRegistry::Ids(const std::string& kind) const {
  std::vector<std::string> ids;
  for (const auto& p : plugins_)
    if (kind.empty() || p.kind() == kind) ids.push_back(p.id());
  std::sort(ids.begin(), ids.end());
  return ids;
}

}  // namespace imr::plugin
