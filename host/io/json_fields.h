// Typed access to fields of a parsed JSON value with errors that name the file and the JSON path
// ("dinoRing.json: extrinsics[3].value.rotation: expected 3 rows of 3 numbers"). Used by the
// OpenMVG and SLAM JSON readers.
#pragma once

#include "host/io/camera_model.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

namespace imr::io {

class JsonFields {
 public:
  explicit JsonFields(std::string file) : file_(std::move(file)) {}
  const std::string& file() const { return file_; }

  [[noreturn]] void Fail(const std::string& path, const std::string& what) const;

  // The member `key` of object `j` (at `path`); throws when `j` is not an object or lacks it.
  const nlohmann::json& Member(const nlohmann::json& j, const std::string& key,
                               const std::string& path) const;
  // nullptr when absent; throws when `j` is not an object.
  const nlohmann::json* Optional(const nlohmann::json& j, const std::string& key,
                                 const std::string& path) const;
  double Number(const nlohmann::json& j, const std::string& path) const;  // finite
  uint64_t Id(const nlohmann::json& j, const std::string& path) const;    // integer >= 0
  int64_t Integer(const nlohmann::json& j, const std::string& path) const;
  std::string String(const nlohmann::json& j, const std::string& path) const;
  Vec3 Vector3(const nlohmann::json& j, const std::string& path) const;  // |x| <= kMaxCoordinate
  std::vector<double> Numbers(const nlohmann::json& j, const std::string& path) const;
  // 3x3 rows; also checks that it is a rotation (re-orthonormalised within kRotationTolerance).
  Mat3 Rotation(const nlohmann::json& j, const std::string& path) const;

 private:
  std::string file_;
};

}  // namespace imr::io
