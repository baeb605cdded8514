// Vertex colours of a mesh read in blocks (SDK 1.3's stream: a long drive's single mesh, which the
// host keeps on disk and never holds whole), made one block of vertices at a time from the piece
// of the surface that can hold or hide them (issue 46: a coloured PLY of a 1,000-frame drive read
// the mesh whole at the end).
//
// A block's vertices are seen by the views within the colour reach (texturing.hpp, ColourFrame)
// of the box of their faces; every face that can stand between such a view and one of them lies in
// the box around that box and the views' centres (widened by a few pixels' footprint): the piece is
// the faces that meet it. Within it a vertex that some view within the reach sees gets the colour
// ColorAndTexture gives it in the whole mesh (up to the order of float sums); one no such view
// sees takes what the piece's views beyond the reach, then its neighbours within the piece, give
// it. The memory is the piece's: along a drive, the block and twice the reach of road, however
// long the drive.
#pragma once

#include "texturing.hpp"

#include <imr/sdk/plugin.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace imr::exporter_assimp {

struct StreamedColourStats {
  int64_t blocks = 0;           // Colour calls
  int64_t piece_faces = 0;      // faces rasterised, summed over the blocks
  int64_t max_piece_faces = 0;  // the largest piece
  int64_t views = 0;            // views used, summed over the blocks
  double seconds = 0.0;
};

class StreamedVertexColours {
 public:
  // Reads the faces once (a box and a vertex range per run of kFaceBlock faces). Throws
  // std::invalid_argument for bad options.
  StreamedVertexColours(const imr::sdk::MeshStream& mesh, std::span<const imr_camera> keyframes,
                        KeyframeImageFetch fetch, const TexturingOptions& options,
                        std::function<void()> check_cancelled = {});
  // The colours of vertices [first, first + count), 3 bytes each, into rgb.
  void Colour(std::size_t first, std::size_t count, uint8_t* rgb);
  const StreamedColourStats& stats() const { return stats_; }

  static constexpr std::size_t kFaceBlock = 1 << 12;

 private:
  using Box = std::array<double, 6>;  // min xyz, max xyz
  struct FaceBlock {
    uint32_t lo = 0, hi = 0;  // the vertices its faces name
    Box box{};
  };
  // Positions of `indices` (sorted, unique), read in runs.
  void ReadPositions(const std::vector<uint32_t>& indices, std::vector<double>* xyz) const;

  const imr::sdk::MeshStream& mesh_;
  std::span<const imr_camera> keyframes_;
  KeyframeImageFetch fetch_;
  std::function<void()> check_cancelled_;
  ColourFrame frame_;
  std::vector<FaceBlock> blocks_;
  StreamedColourStats stats_;
};

}  // namespace imr::exporter_assimp
