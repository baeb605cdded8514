// Example imr plugin: a weight-transfer policy.
//
// When the engine moves or inserts a point, the Delaunay triangulation replaces some tetrahedra
// (the "removed" cells R) by new ones (the "added" cells A). A weight policy decides the
// free-space weight of each new cell from the removed cells, without re-casting rays.
//
// This one gives each new cell the largest weight among the removed cells within `radius` of its
// centroid (or the nearest removed cell when none is that close): free space wins ties, which
// carves more aggressively than the paper's "nearest" policy. It shows every part of a plugin:
// identity, a parameter with a schema, validation in the constructor, host logging, the work.
#include <imr/sdk/plugin.hpp>

#include <cmath>
#include <limits>

namespace {

class MaxPolicy : public imr::sdk::WeightPolicy {
 public:
  // Identity: a reverse-DNS id that is unique among all plugins, and the plugin's own version.
  static constexpr const char* kId = "org.imr.example.policy.max";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Example: largest removed weight within a radius (sdk/examples/max_policy)";
  // Parameters the job may set under `params`. The host checks a job against this schema in
  // `imr validate` and fills in the defaults before the constructor sees them.
  static constexpr const char* kParamsSchema = R"({
    "radius": {"type": "number", "default": 1.0, "minimum": 0.0,
               "description": "metres around a new cell's centroid to look for removed cells"}
  })";

  MaxPolicy(const imr::sdk::Params& params, const imr::sdk::Host& host)
      : radius_(params.Get<double>("radius")) {  // the schema's default when the job gives none
    // Defence in depth: a plugin may be driven by a host that did not validate.
    if (!(radius_ >= 0.0)) throw imr::sdk::InvalidArgument("params.radius: expected >= 0");
    host.Debug("max policy, radius " + std::to_string(radius_));
  }

  // Called on the engine's hot path: no allocation, no logging.
  void Transfer(const imr::sdk::TransferRequest& r) override {
    const double r2 = radius_ * radius_;
    for (std::size_t i = 0; i < r.added_count(); ++i) {
      const double* a = &r.added_centroids[3 * i];
      double best = -std::numeric_limits<double>::infinity();
      double nearest_d2 = std::numeric_limits<double>::infinity();
      double nearest_w = 0.0;
      for (std::size_t k = 0; k < r.removed_count(); ++k) {
        const double* c = &r.removed_centroids[3 * k];
        const double d2 = (a[0] - c[0]) * (a[0] - c[0]) + (a[1] - c[1]) * (a[1] - c[1]) +
                          (a[2] - c[2]) * (a[2] - c[2]);
        if (d2 <= r2 && r.removed_weights[k] > best) best = r.removed_weights[k];
        if (d2 < nearest_d2) {
          nearest_d2 = d2;
          nearest_w = r.removed_weights[k];
        }
      }
      r.added_weights[i] = std::isfinite(best) ? best : nearest_w;
    }
  }

 private:
  double radius_;
};

}  // namespace

// The one exported symbol: lists this library's plugin classes.
IMR_PLUGIN_EXPORT(MaxPolicy)
