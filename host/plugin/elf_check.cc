#include "host/plugin/elf_check.h"

#include "host/util/input_file.h"

#include <elf.h>

#include <cstring>
#include <algorithm>
#include <fstream>
#include <optional>
#include <string_view>
#include <vector>

namespace imr::plugin {
namespace fs = std::filesystem;
namespace {

#if defined(__x86_64__)
constexpr int kHostMachine = EM_X86_64;
#elif defined(__aarch64__)
constexpr int kHostMachine = EM_AARCH64;
#elif defined(__i386__)
constexpr int kHostMachine = EM_386;
#elif defined(__arm__)
constexpr int kHostMachine = EM_ARM;
#elif defined(__riscv)
constexpr int kHostMachine = EM_RISCV;
#elif defined(__powerpc64__)
constexpr int kHostMachine = EM_PPC64;
#elif defined(__s390x__)
constexpr int kHostMachine = EM_S390;
#else
constexpr int kHostMachine = -1;  // unknown: not checked
#endif

std::string MachineName(int machine) {
  switch (machine) {
    case EM_X86_64: return "x86-64";
    case EM_AARCH64: return "AArch64";
    case EM_386: return "x86 (32-bit)";
    case EM_ARM: return "ARM (32-bit)";
    case EM_RISCV: return "RISC-V";
    case EM_PPC64: return "PowerPC 64";
    case EM_S390: return "s390x";
    default: return "machine " + std::to_string(machine);
  }
}

// Reads `size` bytes at `offset`; false when the file is shorter.
bool ReadAt(std::istream& in, uint64_t offset, void* out, std::size_t size) {
  in.clear();
  in.seekg(static_cast<std::streamoff>(offset));
  in.read(static_cast<char*>(out), static_cast<std::streamsize>(size));
  return in.gcount() == static_cast<std::streamsize>(size);
}

}  // namespace

ElfCheck CheckElfFile(const fs::path& file, const std::string& entry_symbol) {
  ElfCheck r;
  std::error_code ec;
  const uint64_t size = fs::file_size(file, ec);
  if (ec) {
    r.problem = "cannot read: " + ec.message();
    return r;
  }
  // The open rule (host/util/input_file.h): a FIFO or a device is refused by name.
  std::optional<InputStream> opened;
  try {
    opened.emplace(file, "a plugin (an ELF shared library)");
  } catch (const std::runtime_error& e) {
    const std::string what = e.what(), prefix = file.string() + ": ";
    r.problem = what.rfind(prefix, 0) == 0 ? what.substr(prefix.size()) : what;
    return r;
  }
  InputStream& in = *opened;
  unsigned char ident[EI_NIDENT] = {};
  if (!ReadAt(in, 0, ident, sizeof(ident)) || std::memcmp(ident, ELFMAG, SELFMAG) != 0) {
    r.problem = "not an ELF shared library (a linker script, or another kind of file)";
    return r;
  }
  if (ident[EI_CLASS] != ELFCLASS64 || ident[EI_DATA] != ELFDATA2LSB) {
    r.problem = std::string("built as ") + (ident[EI_CLASS] == ELFCLASS32 ? "32-bit" : "64-bit") +
                (ident[EI_DATA] == ELFDATA2MSB ? " big-endian" : "") +
                " ELF; this imr loads 64-bit little-endian libraries";
    return r;
  }
  Elf64_Ehdr eh{};
  if (!ReadAt(in, 0, &eh, sizeof(eh))) {
    r.problem = "truncated: " + std::to_string(size) + " bytes, less than an ELF header";
    return r;
  }
  if (eh.e_type != ET_DYN) {
    r.problem = "not a shared library (ELF type " + std::to_string(eh.e_type) +
                ": an executable or an object file); build it as a MODULE or SHARED library";
    return r;
  }
  if (kHostMachine >= 0 && eh.e_machine != kHostMachine) {
    r.problem = "built for " + MachineName(eh.e_machine) + " (ELF machine " +
                std::to_string(eh.e_machine) + "); this imr runs on " + MachineName(kHostMachine);
    return r;
  }
  // Every byte the loader maps, and the header tables, must be in the file.
  uint64_t needed = sizeof(eh);
  if (eh.e_phentsize != sizeof(Elf64_Phdr) && eh.e_phnum > 0) {
    r.problem = "malformed ELF: program header entries of " + std::to_string(eh.e_phentsize) + " bytes";
    return r;
  }
  needed = std::max<uint64_t>(needed, eh.e_phoff + uint64_t{eh.e_phnum} * sizeof(Elf64_Phdr));
  std::vector<Elf64_Phdr> ph(eh.e_phnum);
  if (needed <= size && eh.e_phnum > 0 && ReadAt(in, eh.e_phoff, ph.data(), ph.size() * sizeof(Elf64_Phdr)))
    for (const Elf64_Phdr& p : ph)
      if (p.p_type == PT_LOAD || p.p_type == PT_DYNAMIC)
        needed = std::max<uint64_t>(needed, p.p_offset + p.p_filesz);
  if (eh.e_shnum > 0)
    needed = std::max<uint64_t>(needed, eh.e_shoff + uint64_t{eh.e_shnum} * eh.e_shentsize);
  if (needed > size) {
    r.problem = "truncated: " + std::to_string(size) + " bytes, its ELF headers need at least " +
                std::to_string(needed) + " (a copy cut short?)";
    return r;
  }
  // The dynamic symbol table, through the section headers.
  if (eh.e_shnum == 0 || eh.e_shentsize != sizeof(Elf64_Shdr)) return r;
  std::vector<Elf64_Shdr> sh(eh.e_shnum);
  if (!ReadAt(in, eh.e_shoff, sh.data(), sh.size() * sizeof(Elf64_Shdr))) return r;
  for (const Elf64_Shdr& s : sh) {
    if (s.sh_type != SHT_DYNSYM || s.sh_entsize != sizeof(Elf64_Sym) || s.sh_link >= sh.size()) continue;
    const Elf64_Shdr& strtab = sh[s.sh_link];
    if (s.sh_offset + s.sh_size > size || strtab.sh_offset + strtab.sh_size > size) {
      r.problem = "malformed ELF: its dynamic symbol table lies past the end of the file";
      return r;
    }
    std::vector<Elf64_Sym> symbols(s.sh_size / sizeof(Elf64_Sym));
    std::string names(strtab.sh_size, '\0');
    if (!ReadAt(in, s.sh_offset, symbols.data(), symbols.size() * sizeof(Elf64_Sym)) ||
        !ReadAt(in, strtab.sh_offset, names.data(), names.size()))
      return r;
    r.symbols_known = true;
    for (const Elf64_Sym& sym : symbols) {
      if (sym.st_shndx == SHN_UNDEF || sym.st_name >= names.size()) continue;
      const int binding = ELF64_ST_BIND(sym.st_info);
      if (binding != STB_GLOBAL && binding != STB_WEAK) continue;
      const char* name = names.data() + sym.st_name;
      if (std::string_view(name, ::strnlen(name, names.size() - sym.st_name)) == entry_symbol) {
        r.has_entry = true;
        break;
      }
    }
  }
  return r;
}

}  // namespace imr::plugin
