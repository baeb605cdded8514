#include "host/engine/mesh_topology.h"

#include <gtest/gtest.h>

#include <iostream>

#include <cstdint>
#include <string>
#include <vector>

namespace imr::engine {
namespace {

// The other diagonal of a quad: each vertex keeps one open fan between the same two neighbours.
TEST(SameVertexLinks, AFlippedDiagonalKeepsEveryFan) {
  const std::vector<uint32_t> before = {0, 1, 2, 0, 2, 3};
  const std::vector<uint32_t> after = {0, 1, 3, 1, 2, 3};
  EXPECT_EQ(SameVertexLinks(before, before, 4), "");
  EXPECT_EQ(SameVertexLinks(before, after, 4), "");
}

// A face of a closed fan turned over: its vertex meets a neighbour twice.
TEST(SameVertexLinks, AFaceTurnedOverIsNamed) {
  std::vector<uint32_t> before;
  for (uint32_t i = 1; i <= 6; ++i) before.insert(before.end(), {0, i, i % 6 + 1});
  std::vector<uint32_t> after = before;
  std::swap(after[1], after[2]);  // (0, 2, 1)
  EXPECT_NE(SameVertexLinks(before, after, 7).find("a neighbour twice"), std::string::npos);
}

// What other pieces of a streamed surface could not meet: a cap of three faces over the open
// edge (7, 8) triangulated again so that the edge gets a face on each side (the fold
// plane_retriangulation_test's folded_cap_parts.txt has); one vertex's fan split in two; a
// face naming a vertex that is not there.
TEST(SameVertexLinks, FansThatOtherPiecesCouldNotMeetAreNamed) {
  const std::vector<uint32_t> cap = {5, 6, 7, 5, 7, 8, 5, 8, 6};
  const std::vector<uint32_t> folded = {5, 8, 7, 6, 8, 5, 8, 6, 7};
  const std::string fold = SameVertexLinks(cap, folded, 9);
  EXPECT_NE(fold, "");
  std::cout << "fold: " << fold << "\n";
  std::vector<uint32_t> fan;
  for (uint32_t i = 1; i <= 6; ++i) fan.insert(fan.end(), {0, i, i % 6 + 1});
  const std::vector<uint32_t> pinched = {0, 1, 2, 0, 2, 3, 0, 3, 1, 0, 4, 5, 0, 5, 6, 0, 6, 4};
  const std::string pinch = SameVertexLinks(fan, pinched, 7);
  EXPECT_NE(pinch.find("vertex 0: its fans changed (0 open, 1 closed -> 0 open, 2 closed"), std::string::npos)
      << pinch;
  EXPECT_NE(SameVertexLinks(fan, {0, 1, 9}, 7).find("names vertex 9"), std::string::npos);
  const std::vector<uint32_t> twice = {0, 1, 2, 0, 1, 3};  // vertex 0 meets 1 twice as a first
  EXPECT_NE(SameVertexLinks({0, 1, 2}, twice, 4).find("a neighbour twice"), std::string::npos);
}

// An octahedron is closed: every vertex's fan is a cycle. Without one face the three vertices
// of its hole are on the boundary; a face turned over breaks its vertices' cycles.
TEST(ClosedFans, InnerVerticesOfAManifoldOnly) {
  std::vector<uint32_t> octahedron = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4,
                                      2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
  std::vector<uint32_t> start, fan;
  VertexFans(octahedron, 6, &start, &fan);
  EXPECT_EQ(ClosedFans(octahedron, start, fan), std::vector<uint8_t>(6, 1));

  std::vector<uint32_t> holed(octahedron.begin() + 3, octahedron.end());  // without 0 2 4
  VertexFans(holed, 6, &start, &fan);
  EXPECT_EQ(ClosedFans(holed, start, fan), (std::vector<uint8_t>{0, 1, 0, 1, 0, 1}));

  std::vector<uint32_t> turned = octahedron;
  std::swap(turned[0], turned[1]);  // 2 0 4
  VertexFans(turned, 6, &start, &fan);
  EXPECT_EQ(ClosedFans(turned, start, fan), (std::vector<uint8_t>{0, 1, 0, 1, 0, 1}));

  // A vertex no face holds.
  VertexFans(octahedron, 7, &start, &fan);
  EXPECT_EQ(ClosedFans(octahedron, start, fan), (std::vector<uint8_t>{1, 1, 1, 1, 1, 1, 0}));
}

}  // namespace
}  // namespace imr::engine
