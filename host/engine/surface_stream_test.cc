// SurfaceStream: the exported surface made part by part is the whole surface's export, exactly.
#include "host/engine/surface_stream.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <string>

#include "host/engine/testing/run_stream.h"
#include "host/engine/testing/slice_parts.h"

namespace imr::engine {
namespace {

using testing::CutOrder;
using testing::SliceIntoParts;

// A synthetic street's closed dO and its export, for one set of options (made once per options).
struct Street {
  Mesh boundary;
  Mesh exported;  // ExtractMesh
};

const Street& StreetRun(const EngineOptions& eo) {
  static std::map<std::string, Street> cache;
  const std::string key = ToString(eo.steiner_export) + "/" + std::to_string(eo.fill_holes_perimeter) +
                          "/" + std::to_string(eo.smoothing_iterations) + "/" +
                          std::to_string(eo.min_component_area);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = 60;
  so.points_per_keyframe = 150;
  synthetic::SyntheticStream stream(so);
  Engine engine(eo, nullptr);
  EXPECT_TRUE(testing::RunStream(&stream, &engine).ok());
  Street s;
  s.boundary = engine.ExtractBoundary();
  s.exported = engine.ExtractMesh();
  return cache.emplace(key, std::move(s)).first->second;
}

EngineOptions Options() {
  EngineOptions eo;
  eo.num_threads = 1;
  return eo;
}

// Every part through the stream; what it released, merged by key and in canonical order.
Mesh Streamed(const std::vector<SurfacePart>& parts, const EngineOptions& eo,
              SurfaceStreamStats* stats = nullptr) {
  SurfaceStream stream(SurfaceStreamOptions::FromEngine(eo));
  std::vector<SurfacePart> released;
  for (const SurfacePart& p : parts) {
    EXPECT_EQ(stream.Add(p), "");
    released.push_back(stream.TakeReleased());
  }
  EXPECT_EQ(stream.Finish(), "");
  Mesh m;
  EXPECT_EQ(MergeSurfaceParts(released, &m), "");
  CanonicalizeMesh(&m);
  if (stats != nullptr) *stats = stream.stats();
  return m;
}

Mesh Batch(const std::vector<SurfacePart>& parts, const EngineOptions& eo) {
  Mesh m;
  EXPECT_EQ(MergeSurfaceParts(parts, &m), "");
  FinishExportedMesh(&m, eo);
  return m;
}

void ExpectSame(const Mesh& a, const Mesh& b, const std::string& what) {
  EXPECT_EQ(a.faces, b.faces) << what;
  EXPECT_EQ(a.vertices, b.vertices) << what;
  EXPECT_EQ(a.point_ids, b.point_ids) << what;
}

TEST(SurfaceStreamTest, PartByPartIsTheWholeExportForEveryCut) {
  const EngineOptions eo = Options();
  const Street& street = StreetRun(eo);
  ASSERT_GT(street.exported.faces.size(), 3000u);
  const int64_t total = static_cast<int64_t>(street.exported.faces.size() / 3);
  for (CutOrder order : {CutOrder::kAlongY, CutOrder::kAlongX, CutOrder::kBackward, CutOrder::kShuffled})
    for (int k : {1, 2, 5, 17, 60}) {
      const std::string what = "order " + std::to_string(static_cast<int>(order)) + ", " +
                               std::to_string(k) + " parts";
      const std::vector<SurfacePart> parts = SliceIntoParts(street.boundary, eo.steiner_export, k, order);
      const Mesh batch = Batch(parts, eo);
      ExpectSame(batch, street.exported, what + ": merged parts vs ExtractMesh");
      SurfaceStreamStats stats;
      ExpectSame(Streamed(parts, eo, &stats), batch, what);
      // The street has both fix-ups to make, and every triangle came out.
      EXPECT_GT(stats.holes_filled, 0) << what;
      EXPECT_GT(stats.vertices_split, 0) << what;
      EXPECT_EQ(stats.triangles_released, total) << what;
      EXPECT_EQ(stats.held_triangles, 0) << what;
      // Cut along the drive, the stream holds the seam, not the street.
      if (order == CutOrder::kAlongY && k == 60) {
        EXPECT_LT(stats.peak_held_triangles, total / 10) << what;
      }
    }
}

TEST(SurfaceStreamTest, OtherSteinerRulesAndNoFilling) {
  for (const auto& [rule, fill] : {std::pair{SteinerExportRule::kAllSteiner, 16.0},
                                   std::pair{SteinerExportRule::kNone, 16.0},
                                   std::pair{SteinerExportRule::kAnySteiner, 0.0},
                                   std::pair{SteinerExportRule::kAnySteiner, 40.0}}) {
    EngineOptions eo = Options();
    eo.steiner_export = rule;
    eo.fill_holes_perimeter = fill;
    const Street& street = StreetRun(eo);
    for (CutOrder order : {CutOrder::kAlongY, CutOrder::kShuffled})
      for (int k : {3, 25}) {
        const std::string what = ToString(rule) + ", fill " + std::to_string(fill) + ", order " +
                                 std::to_string(static_cast<int>(order)) + ", " + std::to_string(k);
        const std::vector<SurfacePart> parts = SliceIntoParts(street.boundary, rule, k, order);
        const Mesh batch = Batch(parts, eo);
        ExpectSame(batch, street.exported, what + ": merged parts vs ExtractMesh");
        ExpectSame(Streamed(parts, eo), batch, what);
      }
  }
}

// open_steiner on a real engine's street, with many points and with few: between any_steiner and
// all_steiner (triangles compared by their corners' positions, holes left open), the merged parts
// finished as ExtractMesh; with few points, sheets that border nothing are there to drop.
TEST(SurfaceStreamTest, OpenSteinerLiesBetweenAnyAndAllSteiner) {
  using Triangles = std::set<std::array<double, 9>>;
  auto triangles = [](const Mesh& m) {
    Triangles out;
    for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
      std::array<std::array<double, 3>, 3> c;
      for (int k = 0; k < 3; ++k)
        for (int d = 0; d < 3; ++d) c[k][d] = m.vertices[3 * m.faces[3 * f + k] + d];
      std::sort(c.begin(), c.end());
      out.insert({c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1], c[2][2]});
    }
    return out;
  };
  for (int points : {150, 10}) {
    synthetic::StreamOptions so;
    so.scene = synthetic::SceneKind::kStreet;
    so.frames = 60;
    so.points_per_keyframe = points;
    std::map<SteinerExportRule, Triangles> by_rule;
    for (SteinerExportRule rule :
         {SteinerExportRule::kAnySteiner, SteinerExportRule::kAllSteiner, SteinerExportRule::kOpenSteiner}) {
      EngineOptions eo = Options();
      eo.steiner_export = rule;
      eo.fill_holes_perimeter = 0.0;
      eo.min_component_area = 0.0;
      synthetic::SyntheticStream stream(so);
      Engine engine(eo, nullptr);
      ASSERT_TRUE(testing::RunStream(&stream, &engine).ok());
      const Mesh exported = engine.ExtractMesh();
      by_rule[rule] = triangles(exported);
      if (rule == SteinerExportRule::kOpenSteiner)
        ExpectSame(Batch(SliceIntoParts(engine.ExtractBoundary(), rule, 5, CutOrder::kShuffled), eo),
                   exported, "open_steiner: merged parts vs ExtractMesh");
    }
    const Triangles& any = by_rule[SteinerExportRule::kAnySteiner];
    const Triangles& all = by_rule[SteinerExportRule::kAllSteiner];
    const Triangles& open = by_rule[SteinerExportRule::kOpenSteiner];
    const std::string what = std::to_string(points) + " points per keyframe";
    EXPECT_TRUE(std::includes(open.begin(), open.end(), any.begin(), any.end())) << what;
    EXPECT_TRUE(std::includes(all.begin(), all.end(), open.begin(), open.end())) << what;
    EXPECT_GT(open.size(), any.size()) << what;  // gaps closed
    std::printf("%s: any_steiner %zu, open_steiner %zu, all_steiner %zu triangles\n", what.c_str(),
                any.size(), open.size(), all.size());
    if (points < 150) {
      EXPECT_LT(open.size(), all.size()) << what;  // sheets dropped
    }
  }
}

// Smoothing is per part: with one part it is FinishExportedMesh's, bit for bit; with several the
// surface is the same one (same faces by count, a manifold) and close to it.
TEST(SurfaceStreamTest, SmoothingPerPart) {
  EngineOptions eo = Options();
  eo.smoothing_iterations = 3;
  const Street& street = StreetRun(eo);
  ExpectSame(Streamed(SliceIntoParts(street.boundary, eo.steiner_export, 1, CutOrder::kAlongY), eo),
             street.exported, "one part");
  const Mesh parts = Streamed(SliceIntoParts(street.boundary, eo.steiner_export, 12, CutOrder::kAlongY), eo);
  EXPECT_EQ(parts.faces.size(), street.exported.faces.size());
  EXPECT_EQ(parts.vertices.size(), street.exported.vertices.size());
  EXPECT_TRUE(CheckMesh(parts, false).ok) << CheckMesh(parts, false).message;
  // The seams left unsmoothed change the surface little: its centre and extent within 1 cm.
  auto extent = [](const Mesh& m) {
    std::array<double, 6> e = {1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
    std::array<double, 3> mean{};
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      e[i % 3] = std::min(e[i % 3], m.vertices[i]);
      e[3 + i % 3] = std::max(e[3 + i % 3], m.vertices[i]);
      mean[i % 3] += m.vertices[i] / static_cast<double>(m.vertices.size() / 3);
    }
    return std::pair{e, mean};
  };
  const auto [e1, m1] = extent(parts);
  const auto [e2, m2] = extent(street.exported);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(e1[k], e2[k], 0.01) << k;
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(m1[k], m2[k], 0.01) << k;
  EXPECT_NE(parts.vertices, street.exported.vertices);  // the seams are not smoothed
}

// A grid with a small square hole, and a strip touching the grid at one corner only (a pinched
// vertex), handed out a triangle at a time: the corner becomes two vertices, the hole a fan
// around its centre; the outer boundaries (16 and 12 m) stay open.
TEST(SurfaceStreamTest, HandBuiltPinchAndHole) {
  SurfacePart all;
  std::map<std::pair<int, int>, uint32_t> at;  // vertices made as triangles use them
  auto vertex = [&](int x, int y) {
    const auto [it, fresh] = at.emplace(std::pair{x, y}, static_cast<uint32_t>(all.keys.size()));
    if (fresh) {
      all.keys.push_back(static_cast<int64_t>(all.keys.size()) * 7 + 3);  // keys are any int64
      all.point_ids.push_back(static_cast<int64_t>(all.point_ids.size()));
      all.vertices.insert(all.vertices.end(), {double(x), double(y), 0.0});
    }
    return it->second;
  };
  auto square = [&](int x, int y) {
    all.faces.insert(all.faces.end(), {vertex(x, y), vertex(x + 1, y), vertex(x + 1, y + 1),
                                       vertex(x, y), vertex(x + 1, y + 1), vertex(x, y + 1)});
  };
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x)
      if (!((x == 1 || x == 2) && (y == 1 || y == 2))) square(x, y);  // a 2 x 2 hole: 8 m
  for (int x = 4; x < 9; ++x) square(x, 4);  // the strip, touching the grid at (4, 4)
  // One triangle per part; each vertex completed with its last triangle.
  const std::size_t nf = all.faces.size() / 3;
  std::vector<int64_t> last(all.keys.size(), -1);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) last[all.faces[3 * f + k]] = static_cast<int64_t>(f);
  EngineOptions eo = Options();
  eo.fill_holes_perimeter = 8.5;
  eo.min_component_area = 0.0;  // the strip (5 m^2) is a piece of its own once split
  SurfaceStream stream(SurfaceStreamOptions::FromEngine(eo));
  std::vector<SurfacePart> released;
  for (std::size_t f = 0; f < nf; ++f) {
    SurfacePart p;
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = all.faces[3 * f + k];
      p.keys.push_back(all.keys[v]);
      p.point_ids.push_back(all.point_ids[v]);
      p.vertices.insert(p.vertices.end(), &all.vertices[3 * v], &all.vertices[3 * v] + 3);
      p.faces.push_back(static_cast<uint32_t>(k));
    }
    for (std::size_t v = 0; v < last.size(); ++v)
      if (last[v] == static_cast<int64_t>(f)) p.completed.push_back(all.keys[v]);
    ASSERT_EQ(stream.Add(p), "");
    released.push_back(stream.TakeReleased());
  }
  EXPECT_EQ(stream.Finish(), "");
  EXPECT_EQ(stream.stats().holes_filled, 1);
  EXPECT_EQ(stream.stats().vertices_split, 1);
  // The hole's 8 boundary vertices held until the loop closed; then nothing.
  EXPECT_EQ(stream.stats().held_vertices, 0);
  Mesh m;
  ASSERT_EQ(MergeSurfaceParts(released, &m), "");
  CanonicalizeMesh(&m);
  Mesh whole;
  ASSERT_EQ(MergeSurfaceParts({all}, &whole), "");
  FinishExportedMesh(&whole, eo);
  ExpectSame(m, whole, "hand-built");
  EXPECT_EQ(m.faces.size() / 3, nf + 8);           // the hole's fan: 8 triangles
  EXPECT_EQ(m.vertices.size() / 3, all.keys.size() + 2);  // the corner's copy, the centre
  EXPECT_TRUE(CheckMesh(m, false).ok) << CheckMesh(m, false).message;
  // A smaller limit leaves the hole open.
  eo.fill_holes_perimeter = 7.9;
  SurfaceStream open(SurfaceStreamOptions::FromEngine(eo));
  SurfacePart one = all;
  one.completed = all.keys;
  ASSERT_EQ(open.Add(one), "");
  EXPECT_EQ(open.stats().holes_filled, 0);
  EXPECT_EQ(open.TakeReleased().faces.size(), all.faces.size());
}

// A big piece (an 8 x 2 m grid at z 0) and closed specks (octahedra of 0.18 m^2 each).
struct Pieces {
  SurfacePart all;
  uint32_t Vertex(double x, double y, double z) {
    all.keys.push_back(static_cast<int64_t>(all.keys.size()) * 5 + 1);
    all.point_ids.push_back(static_cast<int64_t>(all.point_ids.size()));
    all.vertices.insert(all.vertices.end(), {x, y, z});
    return static_cast<uint32_t>(all.keys.size() - 1);
  }
  void Grid(int nx, int ny) {
    std::vector<uint32_t> v;
    for (int y = 0; y <= ny; ++y)
      for (int x = 0; x <= nx; ++x) v.push_back(Vertex(x, y, 0.0));
    auto at = [&](int x, int y) { return v[static_cast<std::size_t>(y * (nx + 1) + x)]; };
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        all.faces.insert(all.faces.end(), {at(x, y), at(x + 1, y), at(x + 1, y + 1), at(x, y),
                                           at(x + 1, y + 1), at(x, y + 1)});
  }
  void Speck(double cx, double cy, double cz, double r) {
    const uint32_t px = Vertex(cx + r, cy, cz), nx = Vertex(cx - r, cy, cz), py = Vertex(cx, cy + r, cz),
                   ny = Vertex(cx, cy - r, cz), pz = Vertex(cx, cy, cz + r), nz = Vertex(cx, cy, cz - r);
    all.faces.insert(all.faces.end(), {px, py, pz, py, nx, pz, nx, ny, pz, ny, px, pz,
                                       py, px, nz, nx, py, nz, ny, nx, nz, px, ny, nz});
  }
};

// One triangle per part, in face order; each vertex completed with its last triangle.
std::vector<SurfacePart> OneTrianglePerPart(const SurfacePart& all) {
  const std::size_t nf = all.faces.size() / 3;
  std::vector<int64_t> last(all.keys.size(), -1);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) last[all.faces[3 * f + static_cast<std::size_t>(k)]] = static_cast<int64_t>(f);
  std::vector<SurfacePart> parts;
  for (std::size_t f = 0; f < nf; ++f) {
    SurfacePart p;
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = all.faces[3 * f + static_cast<std::size_t>(k)];
      p.keys.push_back(all.keys[v]);
      p.point_ids.push_back(all.point_ids[v]);
      p.vertices.insert(p.vertices.end(), &all.vertices[3 * v], &all.vertices[3 * v] + 3);
      p.faces.push_back(static_cast<uint32_t>(k));
    }
    for (std::size_t v = 0; v < last.size(); ++v)
      if (last[v] == static_cast<int64_t>(f)) p.completed.push_back(all.keys[v]);
    parts.push_back(std::move(p));
  }
  return parts;
}

Mesh AsMesh(const SurfacePart& p) {
  Mesh m;
  m.vertices = p.vertices;
  m.faces = p.faces;
  m.point_ids = p.point_ids;
  return m;
}

TEST(SmallComponentsTest, AMeshLosesItsSpecksAndKeepsItsBigPiece) {
  Pieces p;
  p.Speck(2.0, 1.0, 5.0, 0.3);
  p.Grid(8, 2);
  p.Speck(6.0, 1.0, 5.0, 0.3);
  Mesh m = AsMesh(p.all);
  DroppedComponents d;
  DropSmallComponents(&m, 2.0, &d);
  EXPECT_EQ(d.components, 2);
  EXPECT_EQ(d.faces, 16);
  EXPECT_NEAR(d.area, 2 * 8 * std::sqrt(3.0) / 4 * 0.18, 1e-9);  // 8 faces of side 0.3 sqrt 2
  // The grid whole, its vertices in their order (the specks' gone: no face names them).
  ASSERT_EQ(m.faces.size(), 3u * 32);
  ASSERT_EQ(m.point_ids.size(), 27u);
  for (std::size_t i = 0; i < 27; ++i) {
    EXPECT_EQ(m.point_ids[i], static_cast<int64_t>(6 + i));
    EXPECT_EQ(m.vertices[3 * i + 2], 0.0);
  }
  Mesh grid;
  Pieces g;
  g.Grid(8, 2);
  grid = AsMesh(g.all);
  for (std::size_t f = 0; f < m.faces.size(); ++f) EXPECT_EQ(m.faces[f], grid.faces[f]);
  EXPECT_TRUE(CheckMesh(m, false).ok) << CheckMesh(m, false).message;
  // Under a threshold below the specks' area, or 0, nothing goes.
  for (double min_area : {0.0, 0.3}) {
    Mesh all = AsMesh(p.all);
    DroppedComponents none;
    DropSmallComponents(&all, min_area, &none);
    EXPECT_EQ(all.faces, p.all.faces);
    EXPECT_EQ(none.components, 0);
  }
  // Above the grid's 16 m^2, everything goes.
  Mesh all = AsMesh(p.all);
  DropSmallComponents(&all, 16.5);
  EXPECT_TRUE(all.faces.empty());
  EXPECT_TRUE(all.vertices.empty());
}

// Handed out a triangle at a time, each vertex completed with its last triangle: the grid's first
// triangles are a small piece until it grows (held, then released: a piece that crosses parts
// is kept when it is big), the specks are small when whole (dropped, one of them across 8 parts);
// what comes out is the whole mesh's export.
TEST(SmallComponentsTest, TheStreamWeighsAPieceWhenItIsWhole) {
  Pieces p;
  p.Speck(2.0, 1.0, 5.0, 0.3);
  p.Grid(8, 2);
  p.Speck(6.0, 1.0, 5.0, 0.3);
  // Threshold: 2 m^2 (min_component_area x steiner_spacing^2).
  EngineOptions eo = Options();
  eo.steiner_spacing = 1.0;
  eo.min_component_area = 2.0;
  for (bool one_part : {false, true}) {
    SCOPED_TRACE(one_part ? "one part" : "a triangle per part");
    const std::vector<SurfacePart> parts =
        one_part ? std::vector<SurfacePart>{p.all} : OneTrianglePerPart(p.all);
    std::vector<SurfacePart> in = parts;
    if (one_part) in[0].completed = p.all.keys;
    SurfaceStream stream(SurfaceStreamOptions::FromEngine(eo));
    std::vector<SurfacePart> released;
    for (const SurfacePart& part : in) {
      ASSERT_EQ(stream.Add(part), "");
      released.push_back(stream.TakeReleased());
    }
    EXPECT_EQ(stream.Finish(), "");
    EXPECT_EQ(stream.stats().held_small_triangles, 0);
    EXPECT_EQ(stream.stats().dropped.components, 2);
    EXPECT_EQ(stream.stats().dropped.faces, 16);
    if (!one_part) {
      EXPECT_GT(stream.stats().peak_held_small_triangles, 0);
    }
    EXPECT_EQ(stream.stats().triangles_released, 32);
    EXPECT_EQ(stream.stats().vertices_released, 27);
    Mesh m;
    ASSERT_EQ(MergeSurfaceParts(released, &m), "");
    CanonicalizeMesh(&m);
    Mesh whole;
    ASSERT_EQ(MergeSurfaceParts({p.all}, &whole), "");
    DroppedComponents d;
    FinishExportedMesh(&whole, eo, &d);
    EXPECT_EQ(d.components, 2);
    ExpectSame(m, whole, "streamed vs whole");
    EXPECT_EQ(m.faces.size(), 3u * 32);  // the grid, every triangle
    EXPECT_EQ(m.point_ids.size(), 27u);
    EXPECT_TRUE(CheckMesh(m, false).ok) << CheckMesh(m, false).message;
  }
}

// The street, cut every way, under a threshold that drops some of its pieces: the stream drops the
// same ones as the whole mesh's export.
TEST(SmallComponentsTest, TheStreetsPiecesGoAlikeForEveryCut) {
  EngineOptions eo = Options();
  eo.min_component_area = 4.0;  // 100 m^2
  const Street& street = StreetRun(eo);
  EngineOptions keep = Options();
  keep.min_component_area = 0.0;
  const Street& all = StreetRun(keep);
  ASSERT_LT(street.exported.faces.size(), all.exported.faces.size());  // some pieces went
  for (CutOrder order : {CutOrder::kAlongY, CutOrder::kBackward, CutOrder::kShuffled})
    for (int k : {1, 7, 40}) {
      const std::string what = "order " + std::to_string(static_cast<int>(order)) + ", " +
                               std::to_string(k) + " parts";
      const std::vector<SurfacePart> parts = SliceIntoParts(street.boundary, eo.steiner_export, k, order);
      SurfaceStreamStats stats;
      ExpectSame(Streamed(parts, eo, &stats), street.exported, what);
      EXPECT_GT(stats.dropped.components, 0) << what;
      EXPECT_EQ(stats.held_small_triangles, 0) << what;
    }
}

TEST(SurfaceStreamTest, RefusesPartsThatDoNotFit) {
  SurfacePart a;
  a.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  a.keys = {0, 1, 2};
  a.point_ids = {10, 11, 12};
  a.faces = {0, 1, 2};
  {
    SurfaceStream s({});
    ASSERT_EQ(s.Add(a), "");
    SurfacePart b = a;
    b.vertices[0] = 0.5;
    EXPECT_NE(s.Add(b).find("vertex key 0 is not where"), std::string::npos);
    EXPECT_NE(s.Add(a).find("failed before"), std::string::npos);
  }
  {
    SurfaceStream s({});
    SurfacePart b = a;
    b.faces = {0, 1, 3};
    EXPECT_NE(s.Add(b).find("out of range"), std::string::npos);
  }
  {
    SurfaceStream s({});
    SurfacePart b = a;
    b.completed = {7};
    EXPECT_NE(s.Add(b).find("completed key 7"), std::string::npos);
  }
  {
    SurfaceStream s({});
    SurfacePart b = a;
    b.completed = {0};
    ASSERT_EQ(s.Add(b), "");
    EXPECT_NE(s.Add(a).find("completed by an earlier part"), std::string::npos);
  }
  {
    SurfaceStream s({});
    ASSERT_EQ(s.Add(a), "");
    EXPECT_NE(s.Finish().find("never completed"), std::string::npos);
  }
}

}  // namespace
}  // namespace imr::engine
