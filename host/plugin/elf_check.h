// A look at a candidate plugin's ELF headers before it is loaded. dlopen maps the file and runs
// its constructors: a file cut short kills the process with SIGBUS when a page past its end is
// touched, and a foreign library (IMR_PLUGIN_PATH=/usr/lib/...) runs its own code. Only a whole
// shared library for this machine that exports the entry symbol is worth loading.
#pragma once

#include <filesystem>
#include <string>

namespace imr::plugin {

struct ElfCheck {
  // Empty when the file may be loaded; else why it cannot, e.g. "truncated: 89600 bytes, its
  // ELF headers need at least 178056 (a copy cut short?)" or "built for AArch64 (ELF machine
  // 183); this imr runs on x86-64".
  std::string problem;
  // Whether the dynamic symbol table defines `entry_symbol`; only meaningful when
  // symbols_known (a library stripped of its section headers cannot be told without loading).
  bool has_entry = false;
  bool symbols_known = false;
};

ElfCheck CheckElfFile(const std::filesystem::path& file, const std::string& entry_symbol);

}  // namespace imr::plugin
