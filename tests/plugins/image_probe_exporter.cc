// A test exporter of ABI 1.1 that asks the host for one keyframe image: index = the request's
// keyframe count + `beyond` (out of range for beyond >= 0; -1 is the last keyframe). It writes
// <stem>.probe with the image's size, or lets the host's error through: what an exporter that
// asks for an image out of range meets (tests/sdk_compat_test). Format "probe".
#include <imr/sdk/plugin.hpp>

#include <fstream>

namespace {

class ImageProbe : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.test.exporter.image_probe";
  static constexpr const char* kVersion = "1.1.0";
  static constexpr const char* kDescription = "test: fetches one keyframe image";
  static constexpr const char* kFormats = "probe";
  static constexpr const char* kParamsSchema = R"({
    "beyond": {"type": "integer", "default": 0, "description": "index = keyframe count + beyond"}
  })";
  ImageProbe(const imr::sdk::Params& p, const imr::sdk::Host& host)
      : host_(host), beyond_(p.Get<int64_t>("beyond", 0)) {}

  void ExportMesh(const imr::sdk::ExportRequest& r) override {
    const auto index = static_cast<uint64_t>(static_cast<int64_t>(r.keyframes.size()) + beyond_);
    const imr::sdk::KeyframeImage image = host_.GetKeyframeImage(index);
    std::ofstream(r.directory + "/" + r.stem + ".probe")
        << index << " " << image.width() << "x" << image.height() << "x" << image.channels() << "\n";
  }

 private:
  imr::sdk::Host host_;
  int64_t beyond_;
};

}  // namespace

IMR_PLUGIN_EXPORT(ImageProbe)
