#include "point_id_channel.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace imr::exporter_assimp {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<uint8_t>;

Bytes ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void WriteFile(const fs::path& path, const Bytes& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path.string() + ": " + std::strerror(errno));
}

template <typename T>
T Load(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

template <typename T>
void Store(uint8_t* p, T v) {
  std::memcpy(p, &v, sizeof(T));
}

[[noreturn]] void Fail(const fs::path& file, const std::string& what) {
  throw std::runtime_error("point ids: unexpected output from assimp in " + file.string() + ": " +
                           what);
}

// ---- PLY --------------------------------------------------------------------------------------

std::size_t PlyTypeSize(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

// ---- glTF -------------------------------------------------------------------------------------

constexpr uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;
constexpr uint32_t kChunkBin = 0x004E4942;
constexpr int kFloat = 5126;

std::size_t Padded4(std::size_t n) { return (n + 3) & ~std::size_t{3}; }

}  // namespace

EncodedPointId EncodePointId(int64_t id) {
  const auto v = static_cast<uint32_t>(id + 1);
  return {static_cast<float>(v >> 16), static_cast<float>(v & 0xFFFFu)};
}

bool DecodePointId(double hi, double lo, int64_t* id) {
  if (!(hi >= 0 && hi <= 0xFFFF && lo >= 0 && lo <= 0xFFFF)) return false;
  if (hi != std::floor(hi) || lo != std::floor(lo)) return false;
  *id = static_cast<int64_t>(hi) * 65536 + static_cast<int64_t>(lo) - 1;
  return *id >= kMinPointId && *id <= kMaxPointId;
}

void ConvertPlyPointIds(const fs::path& ply) {
  const Bytes in = ReadFile(ply);
  static const std::string kEnd = "end_header\n";
  const auto end = std::search(in.begin(), in.end(), kEnd.begin(), kEnd.end());
  if (end == in.end()) Fail(ply, "no end_header");
  const std::size_t body = static_cast<std::size_t>(end - in.begin()) + kEnd.size();

  std::istringstream header(std::string(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(body)));
  std::ostringstream out_header;
  std::string line, element;
  std::size_t vertex_count = 0, record = 0, s_offset = 0;
  bool binary_le = false, has_s = false, has_t = false;
  while (std::getline(header, line)) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "format") {
      std::string fmt;
      words >> fmt;
      binary_le = fmt == "binary_little_endian";
    } else if (key == "element") {
      words >> element;
      if (element == "vertex") words >> vertex_count;
    } else if (key == "property" && element == "vertex") {
      std::string type, name;
      words >> type >> name;
      const std::size_t size = PlyTypeSize(type);
      if (size == 0) Fail(ply, "vertex property \"" + line + "\"");
      if (name == "s" && type == "float") {
        has_s = true;
        s_offset = record;
        out_header << "property int point_id\n";
        record += size;
        continue;
      }
      if (name == "t") {
        if (!has_s || type != "float" || record != s_offset + 4) Fail(ply, "t does not follow s");
        has_t = true;
        record += size;
        continue;
      }
      record += size;
    }
    out_header << line << '\n';
    if (key == "format")
      out_header << "comment point_id: id of the vertex's 3D point, -1 for Steiner points\n";
  }
  if (!binary_le) Fail(ply, "not binary_little_endian");
  if (!has_s || !has_t) Fail(ply, "no s/t vertex properties carrying the point ids");
  if (body + vertex_count * record > in.size()) Fail(ply, "file shorter than its vertices");

  const std::string h = out_header.str();
  const std::size_t new_record = record - 4;
  Bytes out;
  out.reserve(h.size() + in.size() - body - 4 * vertex_count);
  out.insert(out.end(), h.begin(), h.end());
  const std::size_t vertices_at = out.size();
  out.resize(vertices_at + vertex_count * new_record);
  for (std::size_t i = 0; i < vertex_count; ++i) {
    const uint8_t* src = in.data() + body + i * record;
    uint8_t* dst = out.data() + vertices_at + i * new_record;
    int64_t id = 0;
    if (!DecodePointId(Load<float>(src + s_offset), Load<float>(src + s_offset + 4), &id))
      Fail(ply, "vertex " + std::to_string(i) + " does not carry a point id");
    std::memcpy(dst, src, s_offset);
    Store<int32_t>(dst + s_offset, static_cast<int32_t>(id));
    std::memcpy(dst + s_offset + 4, src + s_offset + 8, record - s_offset - 8);
  }
  out.insert(out.end(), in.begin() + static_cast<std::ptrdiff_t>(body + vertex_count * record),
             in.end());
  WriteFile(ply, out);
}

void ConvertGltfPointIds(const fs::path& file, bool binary) {
  using nlohmann::json;
  json doc;
  Bytes buffer;
  fs::path bin_path;
  {
    const Bytes in = ReadFile(file);
    if (binary) {
      // GLB: 12-byte header, then a JSON chunk and a BIN chunk (glTF 2.0 spec, section 4.4).
      if (in.size() < 20 || Load<uint32_t>(in.data()) != kGlbMagic) Fail(file, "not a GLB");
      const auto json_len = Load<uint32_t>(in.data() + 12);
      if (Load<uint32_t>(in.data() + 16) != kChunkJson || 20 + json_len > in.size())
        Fail(file, "first chunk is not JSON");
      doc = json::parse(in.begin() + 20, in.begin() + 20 + json_len);
      const std::size_t bin_at = 20 + json_len;
      if (bin_at + 8 > in.size() || Load<uint32_t>(in.data() + bin_at + 4) != kChunkBin)
        Fail(file, "no BIN chunk");
      const auto bin_len = Load<uint32_t>(in.data() + bin_at);
      if (bin_at + 8 + bin_len > in.size()) Fail(file, "BIN chunk truncated");
      buffer.assign(in.begin() + static_cast<std::ptrdiff_t>(bin_at + 8),
                    in.begin() + static_cast<std::ptrdiff_t>(bin_at + 8 + bin_len));
    } else {
      doc = json::parse(in.begin(), in.end());
    }
  }
  json& buffers = doc["buffers"];
  if (!buffers.is_array() || buffers.size() != 1) Fail(file, "expected exactly one buffer");
  if (!binary) {
    const std::string uri = buffers[0].value("uri", "");
    if (uri.empty() || uri.find(':') != std::string::npos || uri.find('/') != std::string::npos)
      Fail(file, "buffer uri \"" + uri + "\" is not a file beside it");
    bin_path = file.parent_path() / uri;
    buffer = ReadFile(bin_path);
  }
  const auto byte_length = buffers[0].value("byteLength", std::size_t{0});
  if (byte_length > buffer.size()) Fail(file, "buffer shorter than its byteLength");
  buffer.resize(byte_length);  // drop GLB padding; re-added on write

  json& accessors = doc["accessors"];
  json& views = doc["bufferViews"];
  struct Freed {
    std::size_t begin, end;
  };
  std::vector<Freed> freed;
  for (json& mesh : doc["meshes"]) {
    for (json& primitive : mesh["primitives"]) {
      json& attributes = primitive["attributes"];
      if (!attributes.contains("TEXCOORD_0")) Fail(file, "a primitive has no point-id channel");
      const auto a = attributes["TEXCOORD_0"].get<std::size_t>();
      json& accessor = accessors.at(a);
      if (accessor.value("componentType", 0) != kFloat || accessor.value("type", "") != "VEC2")
        Fail(file, "TEXCOORD_0 is not FLOAT VEC2");
      const auto v = accessor.at("bufferView").get<std::size_t>();
      for (std::size_t i = 0; i < accessors.size(); ++i)
        if (i != a && accessors[i].value("bufferView", json(-1)) == json(v))
          Fail(file, "TEXCOORD_0 shares its bufferView");
      json& view = views.at(v);
      const auto count = accessor.at("count").get<std::size_t>();
      const auto stride = view.value("byteStride", std::size_t{8});
      const auto view_at = view.value("byteOffset", std::size_t{0});
      const auto view_len = view.at("byteLength").get<std::size_t>();
      const auto first = view_at + accessor.value("byteOffset", std::size_t{0});
      if (count == 0 || first + (count - 1) * stride + 8 > view_at + view_len ||
          view_at + view_len > buffer.size())
        Fail(file, "TEXCOORD_0 outside its buffer");

      // Decode everything before overwriting: the packed ids overlap the pairs.
      std::vector<float> ids(count);
      float lo_id = std::numeric_limits<float>::max(), hi_id = -lo_id;
      for (std::size_t i = 0; i < count; ++i) {
        const uint8_t* p = buffer.data() + first + i * stride;
        int64_t id = 0;
        // assimp's glTF exporter flips texture v (v' = 1 - v).
        if (!DecodePointId(Load<float>(p), 1.0 - static_cast<double>(Load<float>(p + 4)), &id) ||
            id > kMaxGltfPointId)
          Fail(file, "vertex " + std::to_string(i) + " does not carry a point id");
        ids[i] = static_cast<float>(id);  // exact: |id| <= 2^24
        lo_id = std::min(lo_id, ids[i]);
        hi_id = std::max(hi_id, ids[i]);
      }
      std::memcpy(buffer.data() + view_at, ids.data(), 4 * count);
      freed.push_back({view_at + 4 * count, view_at + view_len});

      view["byteOffset"] = view_at;
      view["byteLength"] = 4 * count;
      view.erase("byteStride");
      accessor["componentType"] = kFloat;
      accessor["type"] = "SCALAR";
      accessor["min"] = json::array({lo_id});
      accessor["max"] = json::array({hi_id});
      accessor.erase("byteOffset");
      accessor.erase("normalized");
      attributes.erase("TEXCOORD_0");
      attributes["_POINT_ID"] = a;
    }
  }

  // Cut the freed bytes out of the buffer, last range first, and move the views behind them.
  std::sort(freed.begin(), freed.end(), [](const Freed& x, const Freed& y) { return x.begin > y.begin; });
  for (const Freed& f : freed) {
    const std::size_t len = f.end - f.begin;  // a multiple of 4: alignment is kept
    buffer.erase(buffer.begin() + static_cast<std::ptrdiff_t>(f.begin),
                 buffer.begin() + static_cast<std::ptrdiff_t>(f.end));
    for (json& view : views) {
      const auto at = view.value("byteOffset", std::size_t{0});
      if (at >= f.end) view["byteOffset"] = at - len;
    }
  }
  buffers[0]["byteLength"] = buffer.size();

  if (!binary) {
    const std::string text = doc.dump(2) + "\n";
    WriteFile(file, Bytes(text.begin(), text.end()));
    WriteFile(bin_path, buffer);
    return;
  }
  std::string text = doc.dump();
  text.resize(Padded4(text.size()), ' ');
  const std::size_t bin_len = Padded4(buffer.size());
  Bytes out(12 + 8 + text.size() + 8 + bin_len, 0);
  Store<uint32_t>(out.data(), kGlbMagic);
  Store<uint32_t>(out.data() + 4, 2);
  Store<uint32_t>(out.data() + 8, static_cast<uint32_t>(out.size()));
  Store<uint32_t>(out.data() + 12, static_cast<uint32_t>(text.size()));
  Store<uint32_t>(out.data() + 16, kChunkJson);
  std::memcpy(out.data() + 20, text.data(), text.size());
  uint8_t* bin = out.data() + 20 + text.size();
  Store<uint32_t>(bin, static_cast<uint32_t>(bin_len));
  Store<uint32_t>(bin + 4, kChunkBin);
  std::memcpy(bin + 8, buffer.data(), buffer.size());
  WriteFile(file, out);
}

}  // namespace imr::exporter_assimp
