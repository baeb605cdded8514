#include "host/engine/engine.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>

#include "host/engine/testing/policies.h"
#include "host/engine/testing/stream_update.h"
#include "host/synthetic/evaluation.h"

namespace imr::engine {
namespace {

TEST(Engine, SmokeStreet) {
  synthetic::StreamOptions so;
  so.frames = 100;
  if (getenv("N")) so.noise_at_10m = atof(getenv("N"));
  if (getenv("P")) so.points_per_keyframe = atoi(getenv("P"));
  if (getenv("MR")) so.max_range = atof(getenv("MR"));
  synthetic::SyntheticStream stream(so);
  auto policy = testing::MakePolicy(getenv("POL") ? getenv("POL") : "nearest");
  EngineOptions eo;
  if (getenv("RAYS")) { eo.visibility_mode = VisibilityMode::kRays; eo.rays_per_cell = atoi(getenv("RAYS")); }
  if (getenv("W2")) { eo.w2 = atof(getenv("W2")); eo.w3 = atof(getenv("W3")); }
  if (getenv("TW")) eo.free_threshold = atof(getenv("TW"));
  if (getenv("R")) eo.shrink_radius = atof(getenv("R"));
  if (getenv("N")) so.noise_at_10m = atof(getenv("N"));
  Engine engine(eo, policy.get());
  synthetic::StreamKeyframe kf;
  while (stream.Next(&kf)) {
    Status s = engine.ApplyUpdate(testing::ToUpdate(kf));
    ASSERT_TRUE(s.ok()) << s.message();
    auto r = engine.CheckInvariants();
    ASSERT_TRUE(r.ok) << "keyframe " << kf.index << ": " << r.message;
  }
  const auto& st = engine.Stats();
  std::printf("pts %ld moved %ld dropped %ld skipped %ld inO %ld rays %ld cells/ray %.1f t %.2f\n",
              (long)st.points_inserted, (long)st.points_moved, (long)st.points_dropped,
              (long)st.moves_skipped, (long)st.cells_in_o, (long)st.rays_cast,
              double(st.cells_traversed) / std::max<int64_t>(1, st.rays_cast + st.rays_cast_backward),
              st.time.total);
  for (auto rule : {SteinerExportRule::kNone, SteinerExportRule::kAllSteiner, SteinerExportRule::kAnySteiner}) {
    EngineOptions o2 = eo; (void)o2;
    Mesh m = engine.ExtractBoundary();
    // filter
    Mesh f; 
    for (size_t t = 0; t < m.faces.size(); t += 3) {
      int st = 0; for (int k=0;k<3;++k) st += m.point_ids[m.faces[t+k]] < 0;
      if (rule == SteinerExportRule::kAllSteiner && st == 3) continue;
      if (rule == SteinerExportRule::kAnySteiner && st > 0) continue;
      for (int k=0;k<3;++k) f.faces.push_back(m.faces[t+k]);
    }
    auto acc = synthetic::EvaluateMesh(stream.scene(), m.vertices, f.faces, stream.TruePoints(), 0.2);
    std::printf("%s tris %zu area %.0f mean %.3f prec %.3f compl %.3f truth->mesh %.3f\n", ToString(rule).c_str(), acc.triangles, acc.area,
              acc.mean_mesh_to_scene, acc.precision, acc.completeness, acc.mean_truth_to_mesh);
  }
}

}  // namespace
}  // namespace imr::engine
