#include "host/io/json_fields.h"

#include "host/io/schema.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace imr::io {
using nlohmann::json;

void JsonFields::Fail(const std::string& path, const std::string& what) const {
  throw std::runtime_error(file_ + ": " + path + ": " + what);
}

const json& JsonFields::Member(const json& j, const std::string& key, const std::string& path) const {
  const json* m = Optional(j, key, path);
  if (m == nullptr) Fail(path, "missing field \"" + key + "\"");
  return *m;
}

const json* JsonFields::Optional(const json& j, const std::string& key, const std::string& path) const {
  if (!j.is_object()) Fail(path, "expected an object, got " + Describe(j));
  auto it = j.find(key);
  return it == j.end() ? nullptr : &*it;
}

double JsonFields::Number(const json& j, const std::string& path) const {
  if (!j.is_number()) Fail(path, "expected a number, got " + Describe(j));
  const double v = j.get<double>();
  if (!std::isfinite(v)) Fail(path, "expected a finite number, got " + Describe(j));
  return v;
}

uint64_t JsonFields::Id(const json& j, const std::string& path) const {
  if (j.is_number_unsigned()) return j.get<uint64_t>();
  if (j.is_number_integer() && j.get<int64_t>() >= 0) return static_cast<uint64_t>(j.get<int64_t>());
  Fail(path, "expected an id (integer >= 0), got " + Describe(j));
}

int64_t JsonFields::Integer(const json& j, const std::string& path) const {
  // An unsigned beyond int64 would wrap to a negative number.
  if (j.is_number_unsigned() && j.get<uint64_t>() > static_cast<uint64_t>(INT64_MAX))
    Fail(path, "expected an integer that fits in 64 bits, got " + Describe(j));
  if (j.is_number_integer()) return j.get<int64_t>();
  Fail(path, "expected an integer, got " + Describe(j));
}

std::string JsonFields::String(const json& j, const std::string& path) const {
  if (!j.is_string()) Fail(path, "expected a string, got " + Describe(j));
  return j.get<std::string>();
}

Vec3 JsonFields::Vector3(const json& j, const std::string& path) const {
  if (!j.is_array() || j.size() != 3) Fail(path, "expected 3 numbers, got " + Describe(j));
  const Vec3 v = {Number(j[0], path + "[0]"), Number(j[1], path + "[1]"), Number(j[2], path + "[2]")};
  // A position this far out is a broken export, not a scene: squared distances overflow to inf
  // and the engine's geometry stops meaning anything.
  for (int i = 0; i < 3; ++i)
    if (const std::string p = CoordinateProblem(v[i]); !p.empty())
      Fail(path + "[" + std::to_string(i) + "]", p);
  return v;
}

std::vector<double> JsonFields::Numbers(const json& j, const std::string& path) const {
  if (!j.is_array()) Fail(path, "expected an array of numbers, got " + Describe(j));
  std::vector<double> out;
  for (std::size_t i = 0; i < j.size(); ++i)
    out.push_back(Number(j[i], path + "[" + std::to_string(i) + "]"));
  return out;
}

Mat3 JsonFields::Rotation(const json& j, const std::string& path) const {
  if (!j.is_array() || j.size() != 3) Fail(path, "expected 3 rows of 3 numbers, got " + Describe(j));
  Mat3 r;
  for (int i = 0; i < 3; ++i) {
    const std::string row = path + "[" + std::to_string(i) + "]";
    if (!j[i].is_array() || j[i].size() != 3)
      Fail(row, "expected a row of 3 numbers, got " + Describe(j[i]));
    for (int k = 0; k < 3; ++k) r[i][k] = Number(j[i][k], row + "[" + std::to_string(k) + "]");
  }
  const std::string problem = CheckRotation(&r);
  if (!problem.empty()) Fail(path, "the rotation " + problem);
  return r;
}

}  // namespace imr::io
