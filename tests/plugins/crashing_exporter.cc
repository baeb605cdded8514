// A test exporter that takes its process down on purpose, for the batch's isolation tests: it
// segfaults, aborts, keeps allocating memory or hangs (for the stage timeout) when the output
// folder it is asked to write into contains a given string (the sequence's name, with a
// "runs/{sequence}" template), and otherwise writes a small <stem>.crash text file. Format
// "crash" only.
#include <imr/sdk/plugin.hpp>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <thread>
#include <vector>

namespace {

class CrashingExporter : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.test.exporter.crashing";
  static constexpr const char* kVersion = "0.0.1";
  static constexpr const char* kDescription = "test: crashes when the output folder says so";
  static constexpr const char* kFormats = "crash";
  static constexpr const char* kParamsSchema = R"({
    "segv_in": {"type": "string", "default": "", "description": "segfault when the folder contains this"},
    "abort_in": {"type": "string", "default": "", "description": "abort() when the folder contains this"},
    "allocate_in": {"type": "string", "default": "", "description": "allocate memory until killed; 4 GiB at most, then abort"},
    "hang_in": {"type": "string", "default": "", "description": "write half a file, then never return"}
  })";
  CrashingExporter(const imr::sdk::Params& p, const imr::sdk::Host&)
      : segv_in_(p.Get<std::string>("segv_in", "")),
        abort_in_(p.Get<std::string>("abort_in", "")),
        allocate_in_(p.Get<std::string>("allocate_in", "")),
        hang_in_(p.Get<std::string>("hang_in", "")) {}

  void Export(const imr::sdk::MeshView& mesh, const std::string& directory, const std::string& stem,
              const std::string&) override {
    auto in = [&](const std::string& s) { return !s.empty() && directory.find(s) != std::string::npos; };
    if (in(segv_in_)) {
      volatile int* nowhere = nullptr;
      *nowhere = 42;
    }
    if (in(abort_in_)) std::abort();
    if (in(hang_in_)) {
      // Stalled mid-write: a half file in the folder it writes into (the host's staging folder).
      std::ofstream(directory + "/" + stem + ".crash") << "half a mesh";
      for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
    }
    if (in(allocate_in_)) {
      // 16 MiB every 10 ms, each page touched so that it is resident.
      std::vector<char*> blocks;
      for (int i = 0; i < 256; ++i) {
        char* b = static_cast<char*>(std::malloc(16 << 20));
        std::memset(b, i, 16 << 20);
        blocks.push_back(b);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      std::abort();
    }
    std::ofstream(directory + "/" + stem + ".crash") << mesh.face_count() << " faces\n";
  }

 private:
  std::string segv_in_, abort_in_, allocate_in_, hang_in_;
};

}  // namespace

IMR_PLUGIN_EXPORT(CrashingExporter)
