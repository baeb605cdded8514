// Test and benchmark support: run a synthetic stream through an engine.
#pragma once

#include <functional>
#include <string>

#include "host/engine/engine.h"
#include "host/engine/testing/policies.h"
#include "host/engine/testing/stream_update.h"
#include "host/synthetic/evaluation.h"
#include "host/synthetic/stream.h"

namespace imr::engine::testing {

// A visibility mode as one name: exact (per-cell ray sets, no policy), nearest, mean,
// weighted_mean (weights mode with that policy), rays5, rays1 (the baseline with K = 5 or K = 1).
inline bool ConfigureMode(const std::string& mode, EngineOptions* options,
                          std::unique_ptr<WeightTransferPolicy>* policy) {
  if (mode == "exact" || mode == "exact_4threads") {
    options->visibility_mode = VisibilityMode::kExact;
    options->num_threads = mode == "exact" ? 1 : 4;
    policy->reset();
    return true;
  }
  if (mode == "rays5" || mode == "rays1") {
    options->visibility_mode = VisibilityMode::kRays;
    options->rays_per_cell = mode == "rays5" ? 5 : 1;
    policy->reset();
    return true;
  }
  options->visibility_mode = VisibilityMode::kWeights;
  *policy = MakePolicy(mode);
  return *policy != nullptr;
}

// Feeds every keyframe; after each one calls `after` (if set), which may return false to stop.
inline Status RunStream(synthetic::SyntheticStream* stream, Engine* engine,
                        const std::function<bool(const synthetic::StreamKeyframe&)>& after = {}) {
  synthetic::StreamKeyframe kf;
  while (stream->Next(&kf)) {
    Status s = engine->ApplyUpdate(ToUpdate(kf));
    if (!s.ok()) return s;
    if (after && !after(kf)) break;
  }
  return Status::Ok();
}

// Accuracy of the exported mesh against the stream's scene and the true points emitted so far.
inline synthetic::MeshAccuracy Accuracy(const synthetic::SyntheticStream& stream,
                                        const Mesh& mesh, double tau) {
  return synthetic::EvaluateMesh(stream.scene(), mesh.vertices, mesh.faces, stream.TruePoints(),
                                 tau);
}

}  // namespace imr::engine::testing
