#include "host/plugin/registry.h"

#include "host/io/schema.h"
#include "host/plugin/elf_check.h"

#include <imr/sdk/host.hpp>

#include <boost/dll/runtime_symbol_info.hpp>
#include <boost/dll/shared_library.hpp>

#include <dlfcn.h>

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

namespace {
fs::path& InstalledPluginDirectoryOverride() {
  static fs::path directory;
  return directory;
}
}  // namespace

void PluginRegistry::SetInstalledPluginDirectory(const fs::path& directory) {
  InstalledPluginDirectoryOverride() = directory;
}

fs::path PluginRegistry::InstalledPluginDirectory() {
  if (!InstalledPluginDirectoryOverride().empty()) return InstalledPluginDirectoryOverride();
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
      // Never throws: an entry that cannot be read (a symbolic link loop) is a refusal.
      for (auto it = fs::directory_iterator(entry, ec); !ec && it != fs::directory_iterator();
           it.increment(ec)) {
        if (it->path().extension() != ".so") continue;
        std::error_code entry_ec;
        if (it->is_regular_file(entry_ec)) files.push_back(it->path());
        else if (entry_ec) refusals_.push_back({it->path(), "cannot read: " + entry_ec.message()});
      }
      if (ec) refusals_.push_back({entry, "cannot list the folder: " + ec.message()});
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
  // Its headers first: a file cut short would crash the process (SIGBUS) inside dlopen, and a
  // library without the entry symbol is not loaded at all (its constructors would run).
  const ElfCheck elf = CheckElfFile(file, IMR_ENTRY_SYMBOL);
  if (!elf.problem.empty()) {
    refusals_.push_back({file, "cannot load: " + elf.problem});
    return false;
  }
  if (elf.symbols_known && !elf.has_entry) {
    refusals_.push_back({file, std::string("not an imr plugin: no entry symbol '") +
                                   IMR_ENTRY_SYMBOL + "' in its dynamic symbol table"});
    return false;
  }
  // dlopen itself for the loader's own message (Boost.DLL's adds an unrelated errno text);
  // RTLD_NOW: an unresolved symbol fails here, not mid-run.
  void* handle = ::dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    const char* e = ::dlerror();
    std::string why = e != nullptr ? e : "unknown error";
    if (why.rfind(file.string() + ": ", 0) == 0) why.erase(0, file.string().size() + 2);
    refusals_.push_back({file, "cannot load: " + why});
    return false;
  }
  auto lib = std::make_shared<boost::dll::shared_library>();
  try {
    lib->load(boost::dll::fs::path(file.string()),
              boost::dll::load_mode::rtld_now | boost::dll::load_mode::rtld_local);
  } catch (const std::exception& e) {
    ::dlclose(handle);
    refusals_.push_back({file, std::string("cannot load: ") + e.what()});
    return false;
  }
  ::dlclose(handle);  // the library stays loaded: `lib` holds its own reference
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
