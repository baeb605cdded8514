// COLMAP sparse models: cameras, images and points3D, as text (cameras.txt, images.txt,
// points3D.txt) or binary (cameras.bin, images.bin, points3D.bin; little-endian, the layout of
// COLMAP's scene/reconstruction_io.cc). Images store the world -> camera pose as a unit
// quaternion (qw, qx, qy, qz; scalar first) and a translation t, so C = -R^T t (camera_model.h).
// Every image lists its 2D points (x, y, point3D id or -1); every 3D point lists its track of
// (image id, index of the 2D point in that image).
//
// Memory: the model is held once in these structs (every 2D point of every image, 24 bytes each,
// until it is converted), never as file text.
#pragma once

#include "host/io/sfm_source.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace imr::io {

struct ColmapModel {
  struct Camera {
    uint32_t id = 0;
    std::string model;  // COLMAP model name, e.g. "PINHOLE"
    uint64_t width = 0, height = 0;
    std::vector<double> params;
  };
  struct Point2D {
    double x = 0.0, y = 0.0;
    int64_t point3d_id = -1;  // -1: not triangulated
  };
  struct Image {
    uint32_t id = 0;
    std::array<double, 4> qvec{1, 0, 0, 0};  // qw, qx, qy, qz: R world -> camera
    Vec3 tvec{};                             // t
    uint32_t camera_id = 0;
    std::string name;
    std::vector<Point2D> points2d;
  };
  struct TrackElement {
    uint32_t image_id = 0;
    uint32_t point2d_idx = 0;
  };
  struct Point3D {
    uint64_t id = 0;
    Vec3 xyz{};
    std::array<uint8_t, 3> rgb{128, 128, 128};
    double error = 0.0;
    std::vector<TrackElement> track;
  };
  std::vector<Camera> cameras;
  std::vector<Image> images;
  std::vector<Point3D> points;
  std::string ext;  // ".txt" or ".bin": the files it was read from (empty: made in memory)
};

// Reads the model in `dir`: binary when cameras.bin, images.bin and points3D.bin are all there,
// else text. COLMAP >= 3.12 also writes rigs and frames (.bin/.txt) beside them; imr does not
// read them: images.* still hold every registered image's world -> camera pose, all imr needs. Throws std::runtime_error naming the file and the line (text) or byte offset
// (binary) and the id: malformed or truncated files, dangling ids (an image's camera, a track's
// image or 2D point index, a 2D point's 3D point), a quaternion of zero length.
ColmapModel ReadColmapModel(const std::filesystem::path& dir);
// For a folder that is not a COLMAP model: what it is instead, as a sentence that says what to
// do (sub-models 0, 1, ... of a mapper's sparse/: name one; a folder of photos: an SfM run must
// make a model first); "" when it is neither.
std::string ColmapFolderHint(const std::filesystem::path& dir);
ColmapModel ReadColmapText(const std::filesystem::path& dir);
ColmapModel ReadColmapBinary(const std::filesystem::path& dir);

// Checks the cross references (every id above); throws naming `where` and the id, and the file as
// where/<name><ext> (ext: ".txt" or ".bin", the files the model was read from).
void CheckColmapModel(const ColmapModel& m, const std::string& where,
                      const std::string& ext = "");

// The model in the convention of camera_model.h (observation pixels from the tracks).
SfmModel ColmapToSfm(const ColmapModel& m, const std::string& where);

// Writes cameras.bin, images.bin and points3D.bin into `dir` (created if needed), each
// atomically, in COLMAP's layout. Throws naming the path on failure or a camera model that has no
// COLMAP model id.
void WriteColmapBinary(const ColmapModel& m, const std::filesystem::path& dir);

// Writes cameras.txt, images.txt and points3D.txt into `dir` (created if needed), each
// atomically, numbers with round-trip precision. Throws naming the path on failure.
void WriteColmapText(const ColmapModel& m, const std::filesystem::path& dir);
// The text files' parts, for writers that stream a model too large to hold (io/stream_recorder.h):
// cameras.txt whole; images.txt's header, an image's first line, one 2D point of its second line
// (first: the line's first, no space before it); points3D.txt's header and one point's line.
std::string ColmapCamerasText(const std::vector<ColmapModel::Camera>& cameras);
std::string ColmapImagesHeader(std::size_t images, std::size_t observations);
void AppendColmapImageHead(const ColmapModel::Image& image, std::string* s);
void AppendColmapPoint2D(const ColmapModel::Point2D& point, bool first, std::string* s);
std::string ColmapPointsHeader(std::size_t points, std::size_t track_entries);
void AppendColmapPoint3D(const ColmapModel::Point3D& point, std::string* s);

}  // namespace imr::io
