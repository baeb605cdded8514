// An exporter built against the frozen ABI 1.0 headers (tests/sdk_1_0), as a plugin shipped
// before ABI 1.1 would be: it writes the geometry as an ASCII OFF file (format "off") and knows
// nothing of keyframes, images or colours. tests/sdk_compat_test runs it in today's host.
#include <imr/sdk/plugin.hpp>

#include <cstdio>
#include <stdexcept>

static_assert(IMR_ABI_MINOR == 0, "this plugin must build against the ABI 1.0 copy of the SDK");

namespace {

class OffExporter : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.test.exporter.off_sdk_1_0";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription = "test: ASCII OFF, built against the ABI 1.0 SDK";
  static constexpr const char* kFormats = "off";
  static constexpr const char* kParamsSchema = R"({})";
  OffExporter(const imr::sdk::Params&, const imr::sdk::Host& host) : host_(host) {}

  void Export(const imr::sdk::MeshView& mesh, const std::string& directory, const std::string& stem,
              const std::string&) override {
    const std::string path = directory + "/" + stem + ".off";
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (f == nullptr) throw std::runtime_error(path + ": cannot write");
    std::fprintf(f, "OFF\n%zu %zu 0\n", mesh.vertex_count(), mesh.face_count());
    for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
      std::fprintf(f, "%.9g %.9g %.9g\n", mesh.vertices[3 * i], mesh.vertices[3 * i + 1], mesh.vertices[3 * i + 2]);
    for (std::size_t t = 0; t < mesh.face_count(); ++t)
      std::fprintf(f, "3 %u %u %u\n", mesh.faces[3 * t], mesh.faces[3 * t + 1], mesh.faces[3 * t + 2]);
    if (std::fclose(f) != 0) throw std::runtime_error(path + ": write failed");
    host_.Info("wrote " + path + " (ABI 1.0 plugin)");
  }

 private:
  imr::sdk::Host host_;
};

}  // namespace

IMR_PLUGIN_EXPORT(OffExporter)
