// A mesh refiner (SDK 1.4) for the host's side of the contract: it shifts the vertices it is
// asked to refine by a fixed vector, or answers what the host must refuse (a non-finite position,
// a subdivision that is no manifold, fewer vertices), waits for a cancel request, or subdivides properly (each face split at
// its centroid: a manifold with the same boundary). Every call is appended as one JSON line to
// `log` (flag counts, keyframes, recent begin, final), so a test can check what the host sent.
#include <imr/sdk/plugin.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <string>
#include <thread>

namespace {

class TestMeshRefiner : public imr::sdk::MeshRefiner {
 public:
  static constexpr const char* kId = "org.imr.test.refine.shift";
  static constexpr const char* kVersion = "0.0.1";
  static constexpr const char* kDescription = "test: shifts the vertices it refines, or misbehaves";
  static constexpr const char* kParamsSchema = R"({
    "dz": {"type": "number", "default": 0.01, "description": "shift along z of each refined vertex"},
    "only_changed": {"type": "boolean", "default": true, "description": "shift only vertices flagged changed"},
    "misbehave": {"type": "string", "default": "", "enum": ["", "nan", "few", "bad_faces", "subdivide", "throw", "wait_for_cancel"]},
    "log": {"type": "string", "default": "", "description": "append one JSON line per call here"}
  })";
  TestMeshRefiner(const imr::sdk::Params& p, const imr::sdk::Host& host)
      : host_(host),
        dz_(p.Get<double>("dz")),
        only_changed_(p.Get<bool>("only_changed")),
        misbehave_(p.Get<std::string>("misbehave")),
        log_(p.Get<std::string>("log")) {}

  // The C view filled directly: the wrapper's own checks would catch "few" before the host.
  void RefineC(const imr::sdk::RefineRequest& r, imr_refine_result* out) override {
    result_ = {};
    Refine(r, &result_);
    out->struct_size = sizeof(imr_refine_result);
    out->vertices = result_.vertices.data();
    out->vertex_count = result_.vertices.size() / 3;
    out->faces = result_.faces.empty() ? nullptr : result_.faces.data();
    out->face_count = result_.faces.size() / 3;
  }

  void Refine(const imr::sdk::RefineRequest& r, imr::sdk::RefineResult* out) override {
    const std::size_t n = r.mesh.vertex_count();
    std::size_t changed = 0, fixed = 0;
    for (std::size_t v = 0; v < n; ++v) {
      changed += r.Changed(v) ? 1 : 0;
      fixed += r.Fixed(v) ? 1 : 0;
    }
    if (!log_.empty()) {
      std::ofstream(log_, std::ios::app)
          << "{\"vertices\": " << n << ", \"faces\": " << r.mesh.face_count()
          << ", \"changed\": " << changed << ", \"fixed\": " << fixed
          << ", \"keyframes\": " << r.keyframes.size()
          << ", \"recent_begin\": " << r.recent_keyframes_begin
          << ", \"final\": " << (r.final_call ? "true" : "false") << "}\n";
    }
    if (misbehave_ == "throw") throw std::runtime_error("test refiner: failed on purpose");
    // A long refinement that stops when the host asks (Ctrl-C): at most 60 s.
    if (misbehave_ == "wait_for_cancel") {
      for (int i = 0; i < 6000 && !host_.IsCancelled(); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      host_.CheckCancelled();
    }
    out->vertices.assign(r.mesh.vertices.begin(), r.mesh.vertices.end());
    for (std::size_t v = 0; v < n; ++v)
      if (!r.Fixed(v) && (!only_changed_ || r.Changed(v))) out->vertices[3 * v + 2] += dz_;
    if (misbehave_ == "nan" && n > 0) out->vertices[3 * (n / 2)] = std::numeric_limits<double>::quiet_NaN();
    if (misbehave_ == "few") out->vertices.resize(3 * (n / 2));
    if (misbehave_ == "bad_faces") {  // every face twice: edges in four faces
      out->faces.assign(r.mesh.faces.begin(), r.mesh.faces.end());
      out->faces.insert(out->faces.end(), r.mesh.faces.begin(), r.mesh.faces.end());
    }
    if (misbehave_ == "subdivide") {
      for (std::size_t f = 0; f < r.mesh.face_count(); ++f) {
        const uint32_t a = r.mesh.faces[3 * f], b = r.mesh.faces[3 * f + 1], c = r.mesh.faces[3 * f + 2];
        const auto m = static_cast<uint32_t>(out->vertices.size() / 3);
        for (int k = 0; k < 3; ++k)
          out->vertices.push_back((out->vertices[3 * a + k] + out->vertices[3 * b + k] +
                                   out->vertices[3 * c + k]) / 3.0);
        out->faces.insert(out->faces.end(), {a, b, m, b, c, m, c, a, m});
      }
    }
  }

 private:
  imr::sdk::Host host_;
  double dz_;
  bool only_changed_;
  std::string misbehave_;
  std::string log_;
  imr::sdk::RefineResult result_;
};

}  // namespace

IMR_PLUGIN_EXPORT(TestMeshRefiner)
