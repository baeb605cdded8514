// COLMAP with CGAL (`colmap delaunay_mesher`) for the benches that compare with it (peers,
// quality): where tools/bench/peers/build_colmap.sh put it.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace imr::bench {

// `given` when not empty, else $IMR_COLMAP, else the build script's cache
// (${XDG_CACHE_HOME:-~/.cache}/imr-peers/colmap-*/build/src/exe/colmap); "" when none.
inline std::string FindColmap(const std::string& given) {
  namespace fs = std::filesystem;
  if (!given.empty()) return given;
  if (const char* e = std::getenv("IMR_COLMAP")) return e;
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  const char* home = std::getenv("HOME");
  const fs::path cache =
      xdg ? fs::path(xdg) / "imr-peers" : fs::path(home ? home : "/tmp") / ".cache/imr-peers";
  std::error_code ec;
  for (const auto& d : fs::directory_iterator(cache, ec)) {
    const fs::path bin = d.path() / "build/src/exe/colmap";
    if (d.path().filename().string().rfind("colmap-", 0) == 0 && fs::exists(bin))
      return bin.string();
  }
  return "";
}

}  // namespace imr::bench
