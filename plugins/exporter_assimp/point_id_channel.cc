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

EncodedVertexKey EncodeVertexKey(int64_t key) {
  const auto v = static_cast<uint64_t>(key);
  return {static_cast<float>(v >> 24), static_cast<float>(v & 0xFFFFFFu)};
}

namespace {

// A PLY as assimp writes it: where the body starts, the vertex record as the header declares it
// (colours are "uchar" whatever their size), the header lines around the vertex properties.
struct AssimpPly {
  struct Property {
    std::string type, name;
    std::size_t size = 0;  // bytes as declared
    bool color = false;    // red, green, blue, alpha
  };
  std::size_t body = 0;
  std::vector<Property> properties;
  std::vector<std::string> before, after;
  std::size_t vertex_count = 0, face_count = 0;
};

AssimpPly ReadAssimpPlyHeader(const Bytes& in, const fs::path& ply) {
  static const std::string kEnd = "end_header\n";
  const auto end = std::search(in.begin(), in.end(), kEnd.begin(), kEnd.end());
  if (end == in.end()) Fail(ply, "no end_header");
  AssimpPly a;
  a.body = static_cast<std::size_t>(end - in.begin()) + kEnd.size();
  std::istringstream header(std::string(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(a.body)));
  std::string line, element;
  bool binary_le = false;
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
      if (element == "vertex") words >> a.vertex_count;
      if (element == "face") words >> a.face_count;
    } else if (key == "property" && element == "vertex") {
      AssimpPly::Property p;
      words >> p.type >> p.name;
      p.size = PlyTypeSize(p.type);
      if (p.size == 0) Fail(ply, "vertex property \"" + line + "\"");
      p.color = p.type == "uchar" && (p.name == "red" || p.name == "green" || p.name == "blue" ||
                                      p.name == "alpha");
      a.properties.push_back(p);
      continue;
    }
    (a.properties.empty() ? a.before : a.after).push_back(line);
  }
  if (!binary_le) Fail(ply, "not binary_little_endian");
  return a;
}

// assimp 5.2's binary writer declares colours "uchar" but writes four floats in [0, 1]: tell
// which from the file's size (faces: a uchar count and three ints each).
bool FloatColors(const AssimpPly& a, std::size_t file_size, const fs::path& ply) {
  std::size_t declared = 0, colors = 0;
  for (const AssimpPly::Property& p : a.properties) {
    declared += p.size;
    colors += p.color;
  }
  const std::size_t faces_bytes = a.face_count * 13;
  const std::size_t float_record = declared + 3 * colors;
  if (file_size == a.body + a.vertex_count * declared + faces_bytes) return false;
  if (colors > 0 && file_size == a.body + a.vertex_count * float_record + faces_bytes) return true;
  Fail(ply, "its size fits no vertex layout (" + std::to_string(file_size) + " bytes)");
}

// The output's vertex record: its header, and what goes where from the input's record.
struct VertexRewrite {
  struct Copy {
    std::size_t from, size, to;
    bool float_to_byte;
  };
  std::string header;
  std::vector<Copy> copies;
  std::size_t record = 0, out_record = 0, s_offset = 0;
};

// Output: the same properties, s t -> int point_id (when asked), colours -> uchar red green blue
// (alpha dropped).
VertexRewrite PlanRewrite(const AssimpPly& a, bool float_colors, bool point_ids, const fs::path& ply) {
  VertexRewrite w;
  std::ostringstream out_header;
  for (const std::string& l : a.before) {
    out_header << l << '\n';
    if (l.rfind("format", 0) == 0 && point_ids)
      out_header << "comment point_id: id of the vertex's 3D point, -1 for Steiner points\n";
  }
  bool has_s = false, has_t = false;
  for (const AssimpPly::Property& p : a.properties) {
    const std::size_t in_size = p.color && float_colors ? 4 : p.size;
    if (point_ids && p.name == "s" && p.type == "float" && !has_s) {
      has_s = true;
      w.s_offset = w.record;
      out_header << "property int point_id\n";
      w.copies.push_back({w.record, 8, w.out_record, false});  // decoded in CopyVertices
      w.out_record += 4;
    } else if (point_ids && p.name == "t" && has_s && !has_t) {
      if (p.type != "float" || w.record != w.s_offset + 4) Fail(ply, "t does not follow s");
      has_t = true;
    } else if (p.color && p.name == "alpha") {
      // dropped
    } else {
      out_header << "property " << p.type << " " << p.name << '\n';
      w.copies.push_back({w.record, in_size, w.out_record, p.color && float_colors});
      w.out_record += p.size;
    }
    w.record += in_size;
  }
  if (point_ids && (!has_s || !has_t)) Fail(ply, "no s/t vertex properties carrying the point ids");
  for (const std::string& l : a.after) out_header << l << '\n';
  w.header = out_header.str();
  return w;
}

// Vertex i's record rewritten from `src` into `dst`.
void RewriteVertex(const VertexRewrite& w, bool point_ids, std::size_t i, const uint8_t* src,
                   uint8_t* dst, const fs::path& ply) {
  for (const VertexRewrite::Copy& c : w.copies) {
    if (point_ids && c.from == w.s_offset && c.size == 8) {
      int64_t id = 0;
      if (!DecodePointId(Load<float>(src + w.s_offset), Load<float>(src + w.s_offset + 4), &id))
        Fail(ply, "vertex " + std::to_string(i) + " does not carry a point id");
      Store<int32_t>(dst + c.to, static_cast<int32_t>(id));
    } else if (c.float_to_byte) {
      // The writer multiplies by 255 and truncates; the exporter stores (b + 0.5) / 255.
      const float v = Load<float>(src + c.from);
      dst[c.to] = static_cast<uint8_t>(std::clamp(std::floor(v * 255.0f), 0.0f, 255.0f));
    } else {
      std::memcpy(dst + c.to, src + c.from, c.size);
    }
  }
}

}  // namespace

void RewritePly(const fs::path& ply, bool point_ids) {
  const Bytes in = ReadFile(ply);
  const AssimpPly a = ReadAssimpPlyHeader(in, ply);
  const VertexRewrite w = PlanRewrite(a, FloatColors(a, in.size(), ply), point_ids, ply);
  Bytes out;
  out.reserve(w.header.size() + a.vertex_count * w.out_record + a.face_count * 13);
  out.insert(out.end(), w.header.begin(), w.header.end());
  const std::size_t vertices_at = out.size();
  out.resize(vertices_at + a.vertex_count * w.out_record);
  for (std::size_t i = 0; i < a.vertex_count; ++i)
    RewriteVertex(w, point_ids, i, in.data() + a.body + i * w.record,
                  out.data() + vertices_at + i * w.out_record, ply);
  out.insert(out.end(), in.begin() + static_cast<std::ptrdiff_t>(a.body + a.vertex_count * w.record),
             in.end());
  WriteFile(ply, out);
}

void EditGltf(const fs::path& file, bool binary, const std::function<void(GltfDocument&)>& edit) {
  using nlohmann::json;
  GltfDocument g;
  g.file = file;
  g.binary = binary;
  {
    const Bytes in = ReadFile(file);
    if (binary) {
      // GLB: 12-byte header, then a JSON chunk and a BIN chunk (glTF 2.0 spec, section 4.4).
      if (in.size() < 20 || Load<uint32_t>(in.data()) != kGlbMagic) Fail(file, "not a GLB");
      const auto json_len = Load<uint32_t>(in.data() + 12);
      if (Load<uint32_t>(in.data() + 16) != kChunkJson || 20 + json_len > in.size())
        Fail(file, "first chunk is not JSON");
      g.doc = json::parse(in.begin() + 20, in.begin() + 20 + json_len);
      const std::size_t bin_at = 20 + json_len;
      if (bin_at + 8 > in.size() || Load<uint32_t>(in.data() + bin_at + 4) != kChunkBin)
        Fail(file, "no BIN chunk");
      const auto bin_len = Load<uint32_t>(in.data() + bin_at);
      if (bin_at + 8 + bin_len > in.size()) Fail(file, "BIN chunk truncated");
      g.buffer.assign(in.begin() + static_cast<std::ptrdiff_t>(bin_at + 8),
                      in.begin() + static_cast<std::ptrdiff_t>(bin_at + 8 + bin_len));
    } else {
      g.doc = json::parse(in.begin(), in.end());
    }
  }
  json& buffers = g.doc["buffers"];
  if (!buffers.is_array() || buffers.size() != 1) Fail(file, "expected exactly one buffer");
  if (!binary) {
    const std::string uri = buffers[0].value("uri", "");
    if (uri.empty() || uri.find(':') != std::string::npos || uri.find('/') != std::string::npos)
      Fail(file, "buffer uri \"" + uri + "\" is not a file beside it");
    g.buffer_file = file.parent_path() / uri;
    g.buffer = ReadFile(g.buffer_file);
  }
  const auto byte_length = buffers[0].value("byteLength", std::size_t{0});
  if (byte_length > g.buffer.size()) Fail(file, "buffer shorter than its byteLength");
  g.buffer.resize(byte_length);  // drop GLB padding; re-added on write

  edit(g);
  g.doc["buffers"][0]["byteLength"] = g.buffer.size();

  if (!binary) {
    const std::string text = g.doc.dump(2) + "\n";
    WriteFile(file, Bytes(text.begin(), text.end()));
    WriteFile(g.buffer_file, g.buffer);
    return;
  }
  std::string text = g.doc.dump();
  text.resize(Padded4(text.size()), ' ');
  const std::size_t bin_len = Padded4(g.buffer.size());
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
  std::memcpy(bin + 8, g.buffer.data(), g.buffer.size());
  WriteFile(file, out);
}

void ConvertGltfPointIds(GltfDocument& g) {
  using nlohmann::json;
  const fs::path& file = g.file;
  Bytes& buffer = g.buffer;
  json& accessors = g.doc["accessors"];
  json& views = g.doc["bufferViews"];
  struct Freed {
    std::size_t begin, end;
  };
  std::vector<Freed> freed;
  for (json& mesh : g.doc["meshes"]) {
    for (json& primitive : mesh["primitives"]) {
      json& attributes = primitive["attributes"];
      // The ids ride in the last texture channel: TEXCOORD_1 behind an atlas, else TEXCOORD_0.
      const std::string channel = attributes.contains("TEXCOORD_1") ? "TEXCOORD_1" : "TEXCOORD_0";
      if (!attributes.contains(channel)) Fail(file, "a primitive has no point-id channel");
      const auto a = attributes[channel].get<std::size_t>();
      json& accessor = accessors.at(a);
      if (accessor.value("componentType", 0) != kFloat || accessor.value("type", "") != "VEC2")
        Fail(file, channel + " is not FLOAT VEC2");
      const auto v = accessor.at("bufferView").get<std::size_t>();
      for (std::size_t i = 0; i < accessors.size(); ++i)
        if (i != a && accessors[i].value("bufferView", json(-1)) == json(v))
          Fail(file, channel + " shares its bufferView");
      json& view = views.at(v);
      const auto count = accessor.at("count").get<std::size_t>();
      const auto stride = view.value("byteStride", std::size_t{8});
      const auto view_at = view.value("byteOffset", std::size_t{0});
      const auto view_len = view.at("byteLength").get<std::size_t>();
      const auto first = view_at + accessor.value("byteOffset", std::size_t{0});
      if (count == 0 || first + (count - 1) * stride + 8 > view_at + view_len ||
          view_at + view_len > buffer.size())
        Fail(file, channel + " outside its buffer");

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
      attributes.erase(channel);
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
}

void ConvertGltfVertexKeys(GltfDocument& g) {
  using nlohmann::json;
  const fs::path& file = g.file;
  json& accessors = g.doc["accessors"];
  json& views = g.doc["bufferViews"];
  for (json& mesh : g.doc["meshes"]) {
    for (json& primitive : mesh["primitives"]) {
      json& attributes = primitive["attributes"];
      std::string channel;  // the highest-numbered TEXCOORD_n
      for (int n = 7; n >= 0 && channel.empty(); --n)
        if (attributes.contains("TEXCOORD_" + std::to_string(n))) channel = "TEXCOORD_" + std::to_string(n);
      if (channel.empty()) Fail(file, "a primitive has no vertex-key channel");
      const auto a = attributes[channel].get<std::size_t>();
      json& accessor = accessors.at(a);
      if (accessor.value("componentType", 0) != kFloat || accessor.value("type", "") != "VEC2")
        Fail(file, channel + " is not FLOAT VEC2");
      const json& view = views.at(accessor.at("bufferView").get<std::size_t>());
      const auto count = accessor.at("count").get<std::size_t>();
      const auto stride = view.value("byteStride", std::size_t{8});
      const auto view_at = view.value("byteOffset", std::size_t{0});
      const auto first = view_at + accessor.value("byteOffset", std::size_t{0});
      if (count == 0 || first + (count - 1) * stride + 8 > view_at + view.at("byteLength").get<std::size_t>() ||
          view_at + view.at("byteLength").get<std::size_t>() > g.buffer.size())
        Fail(file, channel + " outside its buffer");
      float lo[2] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
      float hi[2] = {-lo[0], -lo[0]};
      for (std::size_t i = 0; i < count; ++i) {
        uint8_t* p = g.buffer.data() + first + i * stride;
        // assimp's glTF exporter flips texture v (v' = 1 - v); exact for |v| <= 2^24.
        const double y = 1.0 - static_cast<double>(Load<float>(p + 4));
        const double x = Load<float>(p);
        if (!(x >= 0 && x < 16777216.0 && y >= 0 && y < 16777216.0) || x != std::floor(x) || y != std::floor(y))
          Fail(file, "vertex " + std::to_string(i) + " does not carry a vertex key");
        const float xy[2] = {static_cast<float>(x), static_cast<float>(y)};
        Store<float>(p + 4, xy[1]);
        for (int k = 0; k < 2; ++k) {
          lo[k] = std::min(lo[k], xy[k]);
          hi[k] = std::max(hi[k], xy[k]);
        }
      }
      accessor["min"] = json::array({lo[0], lo[1]});
      accessor["max"] = json::array({hi[0], hi[1]});
      attributes.erase(channel);
      attributes["_VERTEX_KEY"] = a;
    }
  }
}

void SetUprightNode(GltfDocument& g, const double rotation[9], const double view_from[3],
                    const double view_to[3], const std::string& about) {
  using nlohmann::json;
  json& doc = g.doc;
  const auto scene = doc.value("scene", std::size_t{0});
  if (!doc.contains("scenes") || scene >= doc["scenes"].size()) Fail(g.file, "no scene");
  json& roots = doc["scenes"][scene]["nodes"];
  json matrix = json::array();  // column-major; + 0.0 turns -0 into 0
  for (int col = 0; col < 4; ++col)
    for (int row = 0; row < 4; ++row)
      matrix.push_back(row < 3 && col < 3 ? rotation[3 * row + col] + 0.0 : (row == col ? 1.0 : 0.0));
  auto rotated = [&](const double* x) {
    json p = json::array();
    for (int row = 0; row < 3; ++row)
      p.push_back(rotation[3 * row] * x[0] + rotation[3 * row + 1] * x[1] + rotation[3 * row + 2] * x[2] + 0.0);
    return p;
  };
  json node = {
      {"name", "imr_upright"},
      {"children", roots},
      {"matrix", matrix},
      {"extras", {{"imr_upright", {{"about", about}}}}}};
  if (view_from != nullptr && view_to != nullptr) {
    node["extras"]["imr_upright"]["view_from"] = rotated(view_from);
    node["extras"]["imr_upright"]["view_to"] = rotated(view_to);
  }
  doc["nodes"].push_back(node);
  roots = json::array({doc["nodes"].size() - 1});
}

std::array<double, 3> ExportOrigin(const double* vertices, std::size_t vertex_count) {
  std::array<double, 3> lo{}, hi{}, origin{};
  bool small = true;
  for (std::size_t i = 0; i < vertex_count; ++i)
    for (int k = 0; k < 3; ++k) {
      const double x = vertices[3 * i + k];
      small = small && std::fabs(x) <= kOriginFreeRange;
      lo[k] = i == 0 ? x : std::min(lo[k], x);
      hi[k] = i == 0 ? x : std::max(hi[k], x);
    }
  if (small) return origin;
  for (int k = 0; k < 3; ++k) origin[k] = std::round((lo[k] + hi[k]) / 2.0 / 1000.0) * 1000.0;
  return origin;
}

void AddPlyOrigin(const fs::path& ply, const std::array<double, 3>& origin) {
  Bytes bytes = ReadFile(ply);
  static const std::string kFormat = "format ";
  const auto format = std::search(bytes.begin(), bytes.end(), kFormat.begin(), kFormat.end());
  const auto eol = std::find(format, bytes.end(), '\n');
  if (format == bytes.end() || eol == bytes.end()) Fail(ply, "no format line");
  std::ostringstream line;
  line.precision(17);
  line << "comment imr_origin " << origin[0] << ' ' << origin[1] << ' ' << origin[2]
       << " (add it to every vertex for the sequence's coordinates)\n";
  const std::string text = line.str();
  bytes.insert(eol + 1, text.begin(), text.end());
  WriteFile(ply, bytes);
}

void SetGltfOrigin(GltfDocument& g, const std::array<double, 3>& origin) {
  nlohmann::json& doc = g.doc;
  const auto scene = doc.value("scene", std::size_t{0});
  if (!doc.contains("scenes") || scene >= doc["scenes"].size()) Fail(g.file, "no scene");
  for (const nlohmann::json& root : doc["scenes"][scene]["nodes"]) {
    nlohmann::json& node = doc["nodes"].at(root.get<std::size_t>());
    if (node.contains("matrix") || node.contains("translation"))
      Fail(g.file, "a root node already has a transform");
    node["translation"] = {origin[0], origin[1], origin[2]};
  }
}

}  // namespace imr::exporter_assimp
