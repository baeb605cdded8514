// The engine's update API (host/engine/engine.h): a few keyframe updates with cameras, new,
// moved and removed points decoded from the input (coordinates on a coarse grid, so that
// coplanar, cospherical and coincident configurations are common). Bad updates must be refused
// as a whole; after every update the full invariant check (CheckInvariants) and the exported
// meshes' manifold check (CheckMesh) are the oracle: a failure aborts with the message.
#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <vector>

#include "host/engine/engine.h"
#include "host/engine/testing/policies.h"

namespace {

using imr::engine::Vec3;

[[noreturn]] void Fail(const char* what, int update, const std::string& message) {
  std::fprintf(stderr, "engine_fuzz: %s after update %d: %s\n", what, update, message.c_str());
  std::abort();
}

double Coordinate(FuzzedDataProvider* in, double extent) {
  // Mostly a 0.25 grid in [-extent, extent]; rarely NaN or inf (must be refused).
  const uint8_t b = in->ConsumeIntegral<uint8_t>();
  if (b == 255) return std::numeric_limits<double>::quiet_NaN();
  if (b == 254) return std::numeric_limits<double>::infinity();
  return (static_cast<double>(b) - 127.0) / 127.0 * extent;
}

Vec3 Position(FuzzedDataProvider* in, double extent) {
  const double x = Coordinate(in, extent);
  const double y = Coordinate(in, extent);
  const double z = Coordinate(in, extent);
  return {x, y, z};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  imr::engine::EngineOptions o;
  // A small world (cameras within 1.5, points within 2.5 of the origin) and a coarse Steiner grid,
  // so that an input runs in milliseconds under the sanitizers.
  o.steiner_spacing = 4.0;
  o.steiner_margin = 0.5;
  o.max_ray_length = 4.0;
  o.shrink_radius = 2.0;
  o.window = in.ConsumeIntegralInRange<int>(1, 4);
  const uint8_t mode = in.ConsumeIntegral<uint8_t>();
  o.visibility_mode = mode & 1 ? imr::engine::VisibilityMode::kRays
                               : imr::engine::VisibilityMode::kWeights;
  o.transfer_on_insert = mode & 2;
  o.steiner_export = static_cast<imr::engine::SteinerExportRule>((mode >> 2) % 3);
  const auto policy_kind = static_cast<imr::engine::testing::PolicyKind>((mode >> 4) % 3);
  imr::engine::testing::ArrayPolicy policy(policy_kind);
  imr::engine::Engine engine(o, &policy);
  if (!engine.init_status().ok()) Fail("init", 0, engine.init_status().message());

  std::vector<uint64_t> cameras;  // ids sent so far
  std::vector<uint64_t> points;   // ids sent so far (the engine may have dropped some)
  uint64_t next_camera = 0, next_point = 0;
  const int updates = in.ConsumeIntegralInRange<int>(1, 6);
  for (int k = 0; k < updates && in.remaining_bytes() > 0; ++k) {
    imr::engine::KeyframeUpdate u;
    const int new_cameras = in.ConsumeIntegralInRange<int>(cameras.empty() ? 1 : 0, 2);
    for (int i = 0; i < new_cameras; ++i) {
      imr::engine::Camera c;
      c.id = next_camera++;
      c.center = Position(&in, 1.5);
      u.cameras.push_back(c);
    }
    std::vector<uint64_t> known = cameras;
    for (const auto& c : u.cameras) known.push_back(c.id);
    const auto pick_cameras = [&](std::vector<uint64_t>* ids, int max) {
      const int n = in.ConsumeIntegralInRange<int>(0, max);
      for (int i = 0; i < n; ++i) {
        const uint8_t b = in.ConsumeIntegral<uint8_t>();
        // b == 255: an unknown camera (the update must be refused).
        ids->push_back(b == 255 ? 1000000 : known[b % known.size()]);
      }
    };
    const int new_points = in.ConsumeIntegralInRange<int>(0, 16);
    for (int i = 0; i < new_points; ++i) {
      imr::engine::NewPoint p;
      p.id = next_point++;
      p.position = Position(&in, 2.5);
      pick_cameras(&p.camera_ids, 3);
      u.new_points.push_back(p);
    }
    if (!points.empty()) {
      const int moves = in.ConsumeIntegralInRange<int>(0, 6);
      for (int i = 0; i < moves; ++i) {
        imr::engine::MovedPoint m;
        m.id = points[in.ConsumeIntegral<uint16_t>() % points.size()];
        const Vec3 d = Position(&in, 1.0);
        Vec3 at{};
        m.position = engine.PointPosition(m.id, &at)
                         ? Vec3{at[0] + d[0], at[1] + d[1], at[2] + d[2]}
                         : d;
        pick_cameras(&m.camera_ids, 1);
        u.moved_points.push_back(m);
      }
      const int removals = in.ConsumeIntegralInRange<int>(0, 3);
      for (int i = 0; i < removals; ++i)
        u.removed_points.push_back(points[in.ConsumeIntegral<uint16_t>() % points.size()]);
    }
    const imr::engine::Status s = engine.ApplyUpdate(u);
    if (s.ok()) {
      for (const auto& c : u.cameras) cameras.push_back(c.id);
      for (const auto& p : u.new_points) points.push_back(p.id);
    }
    const imr::engine::ManifoldCheckResult inv = engine.CheckInvariants();
    if (!inv.ok) Fail("CheckInvariants", k, inv.message);
    const imr::engine::ManifoldCheckResult boundary = CheckMesh(engine.ExtractBoundary(), true);
    if (!boundary.ok) Fail("CheckMesh(ExtractBoundary, closed)", k, boundary.message);
    const imr::engine::ManifoldCheckResult mesh = CheckMesh(engine.ExtractMesh(), false);
    if (!mesh.ok) Fail("CheckMesh(ExtractMesh)", k, mesh.message);
  }
  return 0;
}
