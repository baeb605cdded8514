#include "host/eval/mesh_io.h"

#include "host/util/input_file.h"
#include "host/util/text_codec.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string_view>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;

// What a mesh reader expects, in the open rule's refusals.
constexpr std::string_view kMeshWhat = "a mesh or point file (.ply, .obj, .off, .gltf, .glb, .xyz)";
using nlohmann::json;

[[noreturn]] void Fail(const fs::path& path, const std::string& what) {
  throw std::runtime_error(path.string() + ": " + what);
}

// Through the open rule (host/util/input_file.h): a FIFO or a device named as a mesh is refused
// by name rather than waited on.
std::string ReadBytes(const fs::path& path, std::string_view what = kMeshWhat) {
  return ReadInputFile(path, what);
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Parses a whole token as a finite double; false otherwise (from_chars takes no leading '+').
bool ParseDouble(std::string_view s, double* out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(*out);
}

bool ParseInt(std::string_view s, int64_t* out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// Splits a line into tokens separated by blanks (and commas when `commas`).
void Tokenize(std::string_view line, bool commas, std::vector<std::string_view>* out) {
  out->clear();
  std::size_t i = 0;
  auto sep = [&](char c) { return c == ' ' || c == '\t' || c == '\r' || (commas && c == ','); };
  while (i < line.size()) {
    while (i < line.size() && sep(line[i])) ++i;
    const std::size_t b = i;
    while (i < line.size() && !sep(line[i])) ++i;
    if (i > b) out->push_back(line.substr(b, i - b));
  }
}

// Calls fn(line_number from 1, line) for every line of `text`.
template <typename Fn>
void ForEachLine(std::string_view text, Fn&& fn) {
  std::size_t pos = 0, number = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    fn(++number, text.substr(pos, end - pos));
    pos = end + 1;
  }
}

void CheckIndices(const TriangleMesh& m, const fs::path& path) {
  for (std::size_t f = 0; f < m.triangles.size(); ++f)
    for (uint32_t i : m.triangles[f])
      if (i >= m.vertices.size())
        Fail(path, "triangle " + std::to_string(f) + " has vertex index " + std::to_string(i) +
                       " but there are " + std::to_string(m.vertices.size()) + " vertices");
}

// Fan-triangulates polygon `poly` (vertex indices) into m.
void AddPolygon(const std::vector<int64_t>& poly, TriangleMesh* m) {
  for (std::size_t k = 1; k + 1 < poly.size(); ++k)
    m->triangles.push_back({static_cast<uint32_t>(poly[0]), static_cast<uint32_t>(poly[k]),
                            static_cast<uint32_t>(poly[k + 1])});
}

// ---------------------------------------------------------------------------------------- OBJ

TriangleMesh ParseObj(std::string_view text, const fs::path& path) {
  TriangleMesh m;
  std::vector<std::string_view> tok;
  std::vector<int64_t> poly;
  ForEachLine(text, [&](std::size_t n, std::string_view line) {
    Tokenize(line, false, &tok);
    if (tok.empty() || tok[0][0] == '#') return;
    const auto where = [&] { return "line " + std::to_string(n) + ": "; };
    if (tok[0] == "v") {
      Vec3 v;
      if (tok.size() < 4) Fail(path, where() + "a vertex needs x y z");
      for (int k = 0; k < 3; ++k)
        if (!ParseDouble(tok[1 + k], &v[k]))
          Fail(path, where() + "bad vertex coordinate '" + std::string(tok[1 + k]) + "'");
      m.vertices.push_back(v);
    } else if (tok[0] == "f") {
      if (tok.size() < 4) Fail(path, where() + "a face needs at least 3 vertices");
      poly.clear();
      for (std::size_t k = 1; k < tok.size(); ++k) {
        const std::string_view t = tok[k].substr(0, tok[k].find('/'));
        int64_t i = 0;
        if (!ParseInt(t, &i) || i == 0)
          Fail(path, where() + "bad face vertex '" + std::string(tok[k]) + "'");
        const int64_t nv = static_cast<int64_t>(m.vertices.size());
        i = i < 0 ? nv + i : i - 1;  // negative: relative to the vertices read so far
        if (i < 0 || i > std::numeric_limits<uint32_t>::max())
          Fail(path, where() + "face vertex '" + std::string(tok[k]) + "' is out of range");
        poly.push_back(i);
      }
      AddPolygon(poly, &m);
    }
  });
  CheckIndices(m, path);
  return m;
}

// ---------------------------------------------------------------------------------------- PLY

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool PlyTypeFromName(const std::string& s, PlyType* t) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kInt8},     {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},   {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16}, {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},   {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32}, {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& [name, type] : kNames)
    if (s == name) {
      *t = type;
      return true;
    }
  return false;
}

std::size_t PlySize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8: return 1;
    case PlyType::kInt16:
    case PlyType::kUint16: return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
  }
  return 0;
}

bool PlyIsInteger(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { kAscii, kBinaryLE, kBinaryBE };

// Reads PLY values one at a time from the body, in either encoding, with bounds checks.
class PlyReader {
 public:
  PlyReader(std::string_view body, PlyFormat format, const fs::path& path)
      : body_(body), format_(format), path_(path) {}

  // `element` and `item` name the value for errors ("face 12 of 40").
  double Read(PlyType t, const PlyElement& element, uint64_t item) {
    if (format_ == PlyFormat::kAscii) return ReadAscii(t, element, item);
    const std::size_t n = PlySize(t);
    if (pos_ + n > body_.size())
      Fail(path_, "truncated: " + What(element, item) + " ends past the end of the file");
    unsigned char b[8];
    std::memcpy(b, body_.data() + pos_, n);
    pos_ += n;
    const bool swap = (format_ == PlyFormat::kBinaryBE) == (std::endian::native == std::endian::little);
    if (swap) std::reverse(b, b + n);
    switch (t) {
      case PlyType::kInt8: return static_cast<int8_t>(b[0]);
      case PlyType::kUint8: return b[0];
      case PlyType::kInt16: return Load<int16_t>(b);
      case PlyType::kUint16: return Load<uint16_t>(b);
      case PlyType::kInt32: return Load<int32_t>(b);
      case PlyType::kUint32: return Load<uint32_t>(b);
      case PlyType::kFloat32: return Load<float>(b);
      case PlyType::kFloat64: return Load<double>(b);
    }
    return 0.0;
  }

  std::size_t remaining() const { return body_.size() - pos_; }

 private:
  template <typename T>
  static double Load(const unsigned char* b) {
    T v;
    std::memcpy(&v, b, sizeof(T));
    return static_cast<double>(v);
  }

  static std::string What(const PlyElement& e, uint64_t item) {
    return e.name + " " + std::to_string(item) + " of " + std::to_string(e.count);
  }

  double ReadAscii(PlyType t, const PlyElement& element, uint64_t item) {
    while (pos_ < body_.size() && std::isspace(static_cast<unsigned char>(body_[pos_]))) ++pos_;
    const std::size_t b = pos_;
    while (pos_ < body_.size() && !std::isspace(static_cast<unsigned char>(body_[pos_]))) ++pos_;
    if (pos_ == b)
      Fail(path_, "truncated: " + What(element, item) + " ends past the end of the file");
    const std::string_view tok = body_.substr(b, pos_ - b);
    double v = 0.0;
    if (!ParseDouble(tok, &v) || (PlyIsInteger(t) && v != std::floor(v)))
      Fail(path_, What(element, item) + ": bad value '" + std::string(tok) + "'");
    return v;
  }

  std::string_view body_;
  PlyFormat format_;
  const fs::path& path_;
  std::size_t pos_ = 0;
};

// A PLY header: the body's format, its elements, imr's origin, where the body starts.
struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  Vec3 origin = {0.0, 0.0, 0.0};
  std::size_t body = 0;
};

// One "property <type> <name>" or "property list <t> <t> <name>" line, tokenised.
PlyProperty ParsePlyProperty(const std::vector<std::string_view>& tok, const fs::path& path,
                             const std::string& where) {
  PlyProperty p;
  if (tok.size() == 5 && tok[1] == "list") {
    p.is_list = true;
    if (!PlyTypeFromName(std::string(tok[2]), &p.count_type) || !PlyIsInteger(p.count_type) ||
        !PlyTypeFromName(std::string(tok[3]), &p.type))
      Fail(path, where + "bad list property types");
    p.name = tok[4];
  } else if (tok.size() == 3) {
    if (!PlyTypeFromName(std::string(tok[1]), &p.type))
      Fail(path, where + "unknown property type '" + std::string(tok[1]) + "'");
    p.name = tok[2];
  } else {
    Fail(path, where + "expected 'property <type> <name>' or 'property list <t> <t> <name>'");
  }
  return p;
}

// Header: text lines up to "end_header".
PlyHeader ParsePlyHeader(std::string_view data, const fs::path& path) {
  std::size_t pos = 0;
  auto next_line = [&](std::string_view* line) {
    if (pos >= data.size()) return false;
    std::size_t end = data.find('\n', pos);
    if (end == std::string_view::npos) end = data.size();
    *line = data.substr(pos, end - pos);
    if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
    pos = std::min(data.size(), end + 1);
    return true;
  };
  std::string_view line;
  if (!next_line(&line) || line != "ply") Fail(path, "not a PLY file (no 'ply' first line)");
  PlyHeader h;
  bool have_format = false, ended = false;
  std::vector<std::string_view> tok;
  int header_line = 1;
  while (next_line(&line)) {
    ++header_line;
    Tokenize(line, false, &tok);
    const auto where = [&] { return "header line " + std::to_string(header_line) + ": "; };
    // imr's exporter writes vertices relative to "comment imr_origin X Y Z" (far from 0).
    if (tok.size() >= 5 && tok[0] == "comment" && tok[1] == "imr_origin") {
      for (int k = 0; k < 3; ++k)
        if (!ParseDouble(tok[2 + k], &h.origin[k])) Fail(path, where() + "bad imr_origin");
      continue;
    }
    if (tok.empty() || tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "end_header") {
      ended = true;
      break;
    }
    if (tok[0] == "format") {
      if (tok.size() < 2) Fail(path, where() + "format needs a name");
      if (tok[1] == "ascii") h.format = PlyFormat::kAscii;
      else if (tok[1] == "binary_little_endian") h.format = PlyFormat::kBinaryLE;
      else if (tok[1] == "binary_big_endian") h.format = PlyFormat::kBinaryBE;
      else Fail(path, where() + "unknown format '" + std::string(tok[1]) + "'");
      have_format = true;
    } else if (tok[0] == "element") {
      int64_t count = -1;
      if (tok.size() != 3 || !ParseInt(tok[2], &count) || count < 0)
        Fail(path, where() + "expected 'element <name> <count>'");
      h.elements.push_back({std::string(tok[1]), static_cast<uint64_t>(count), {}});
    } else if (tok[0] == "property") {
      if (h.elements.empty()) Fail(path, where() + "property before any element");
      h.elements.back().properties.push_back(ParsePlyProperty(tok, path, where()));
    } else {
      Fail(path, where() + "unexpected '" + std::string(tok[0]) + "'");
    }
  }
  if (!ended) Fail(path, "PLY header has no end_header");
  if (!have_format) Fail(path, "PLY header has no format line");
  h.body = pos;
  return h;
}

// The columns of an element the mesh takes: x, y, z of "vertex", the index list of "face".
struct PlyColumns {
  int ix = -1, iy = -1, iz = -1, iface = -1;
};

PlyColumns FindPlyColumns(const PlyElement& e, const fs::path& path) {
  PlyColumns c;
  const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
  for (std::size_t k = 0; k < e.properties.size(); ++k) {
    const PlyProperty& p = e.properties[k];
    const int ik = static_cast<int>(k);
    if (is_vertex && !p.is_list) {
      if (p.name == "x") c.ix = ik;
      if (p.name == "y") c.iy = ik;
      if (p.name == "z") c.iz = ik;
    }
    if (is_face && p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index"))
      c.iface = ik;
  }
  if (is_vertex && (c.ix < 0 || c.iy < 0 || c.iz < 0))
    Fail(path, "element vertex has no x, y and z properties");
  if (is_face && c.iface < 0 && e.count > 0)
    Fail(path, "element face has no list property vertex_indices (or vertex_index)");
  return c;
}

// Element e's items from the body: vertices and faces into `m`, anything else read past.
void ReadPlyElement(PlyReader& r, const PlyElement& e, const Vec3& origin, const fs::path& path,
                    TriangleMesh* m) {
  const PlyColumns c = FindPlyColumns(e, path);
  const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
  // Reserve no more than the body could hold (a corrupt count must not exhaust memory).
  if (is_vertex) m->vertices.reserve(std::min<uint64_t>(e.count, r.remaining() / 3 + 1));
  if (is_face) m->triangles.reserve(std::min<uint64_t>(e.count, r.remaining() / 4 + 1));
  std::vector<double> values;
  std::vector<int64_t> poly;
  for (uint64_t i = 0; i < e.count; ++i) {
    const auto what = [&] { return e.name + " " + std::to_string(i) + " of " + std::to_string(e.count); };
    values.assign(e.properties.size(), 0.0);
    for (std::size_t k = 0; k < e.properties.size(); ++k) {
      const PlyProperty& p = e.properties[k];
      if (!p.is_list) {
        values[k] = r.Read(p.type, e, i);
        continue;
      }
      const double count = r.Read(p.count_type, e, i);
      if (count < 0) Fail(path, what() + ": negative list length");
      const bool keep = is_face && static_cast<int>(k) == c.iface;
      if (keep) {
        if (count < 3) Fail(path, what() + ": a face needs at least 3 vertices, has " +
                                      std::to_string(static_cast<int64_t>(count)));
        if (!PlyIsInteger(p.type)) Fail(path, "face vertex indices must be integers");
        poly.clear();
      }
      for (int64_t j = 0; j < static_cast<int64_t>(count); ++j) {
        const double v = r.Read(p.type, e, i);
        if (keep) {
          if (v < 0 || v > std::numeric_limits<uint32_t>::max())
            Fail(path, what() + ": vertex index " + std::to_string(static_cast<int64_t>(v)) +
                           " is out of range");
          poly.push_back(static_cast<int64_t>(v));
        }
      }
      if (keep) AddPolygon(poly, m);
    }
    if (is_vertex) {
      const Vec3 v = {values[c.ix] + origin[0], values[c.iy] + origin[1], values[c.iz] + origin[2]};
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
        Fail(path, what() + ": coordinate is not finite");
      m->vertices.push_back(v);
    }
  }
}

TriangleMesh ParsePly(std::string_view data, const fs::path& path) {
  const PlyHeader h = ParsePlyHeader(data, path);
  TriangleMesh m;
  PlyReader r(data.substr(h.body), h.format, path);
  bool have_vertex = false;
  for (const PlyElement& e : h.elements) {
    have_vertex = have_vertex || e.name == "vertex";
    ReadPlyElement(r, e, h.origin, path, &m);
  }
  if (!have_vertex) Fail(path, "PLY has no vertex element");
  CheckIndices(m, path);
  return m;
}

// ---------------------------------------------------------------------------------------- XYZ

TriangleMesh ParseXyz(std::string_view text, const fs::path& path) {
  TriangleMesh m;
  std::vector<std::string_view> tok;
  ForEachLine(text, [&](std::size_t n, std::string_view line) {
    Tokenize(line, true, &tok);
    if (tok.empty() || tok[0][0] == '#' || tok[0].substr(0, 2) == "//") return;
    Vec3 v;
    if (tok.size() < 3) Fail(path, "line " + std::to_string(n) + ": expected x y z");
    for (int k = 0; k < 3; ++k)
      if (!ParseDouble(tok[k], &v[k]))
        Fail(path, "line " + std::to_string(n) + ": bad coordinate '" + std::string(tok[k]) + "'");
    m.vertices.push_back(v);
  });
  return m;
}

// ---------------------------------------------------------------------------------------- OFF

// Object File Format (Geomview): a header keyword, a counts line "vertices faces [edges]", the
// vertex lines "x y z ...", then the face lines "n i_1 ... i_n ..." (0-based indices; what follows
// the indices, a colour, is ignored). One record per line (the counts may also follow the keyword
// on its line); '#' starts a comment anywhere; blank lines are skipped. The C / N / ST prefixes
// (colours, normals, texture coordinates after x y z) read like plain OFF; 4OFF, nOFF and the
// binary form are refused.
TriangleMesh ParseOff(std::string_view text, const fs::path& path) {
  enum class Part { kHeader, kCounts, kVertices, kFaces, kDone } part = Part::kHeader;
  int64_t nv = 0, nf = 0;
  std::size_t last_line = 0;
  TriangleMesh m;
  std::vector<std::string_view> tok;
  std::vector<int64_t> poly;
  int64_t faces_read = 0;
  ForEachLine(text, [&](std::size_t n, std::string_view line) {
    last_line = n;
    line = line.substr(0, line.find('#'));
    Tokenize(line, false, &tok);
    if (tok.empty()) return;
    const auto where = [&] { return "line " + std::to_string(n) + ": "; };
    switch (part) {
      case Part::kHeader: {
        // [ST][C][N]OFF: texture coordinates, colours, normals follow x y z (ignored here).
        std::string_view k = tok[0], prefix = k.substr(0, k.size() >= 3 ? k.size() - 3 : 0);
        if (k.size() < 3 || k.substr(k.size() - 3) != "OFF")
          Fail(path, where() + "not an OFF file (expected the keyword 'OFF', found '" +
                         std::string(k) + "')");
        for (std::string_view p : {"ST", "C", "N"})
          if (prefix.substr(0, p.size()) == p) prefix.remove_prefix(p.size());
        if (!prefix.empty())
          Fail(path, where() + "'" + std::string(k) +
                         "' is not supported (only 3D OFF: OFF, COFF, NOFF, STOFF and the like)");
        if (tok.size() > 1 && tok[1] == "BINARY")
          Fail(path, where() + "binary OFF is not supported (only ASCII)");
        part = Part::kCounts;
        if (tok.size() == 1) return;
        tok.erase(tok.begin());  // the counts on the keyword's line, as some writers do
        [[fallthrough]];
      }
      case Part::kCounts: {
        int64_t ne = 0;
        if (tok.size() < 2 || tok.size() > 3 || !ParseInt(tok[0], &nv) || !ParseInt(tok[1], &nf) ||
            (tok.size() == 3 && !ParseInt(tok[2], &ne)))
          Fail(path, where() + "expected the counts 'vertices faces [edges]', found '" +
                         std::string(line) + "'");
        if (nv < 0 || nf < 0 || ne < 0)
          Fail(path, where() + "negative count in '" + std::string(line) + "'");
        if (nv > std::numeric_limits<uint32_t>::max())
          Fail(path, where() + std::to_string(nv) + " vertices: more than 2^32 - 1");
        // Reserve no more than the text could hold (a corrupt count must not exhaust memory).
        m.vertices.reserve(std::min<uint64_t>(nv, text.size() / 6 + 1));
        m.triangles.reserve(std::min<uint64_t>(nf, text.size() / 8 + 1));
        part = nv > 0 ? Part::kVertices : nf > 0 ? Part::kFaces : Part::kDone;
        return;
      }
      case Part::kVertices: {
        Vec3 v;
        if (tok.size() < 3)
          Fail(path, where() + "vertex " + std::to_string(m.vertices.size()) + " of " +
                         std::to_string(nv) + " needs x y z");
        for (int k = 0; k < 3; ++k)
          if (!ParseDouble(tok[k], &v[k]))
            Fail(path, where() + "bad vertex coordinate '" + std::string(tok[k]) + "'");
        m.vertices.push_back(v);
        if (static_cast<int64_t>(m.vertices.size()) == nv)
          part = nf > 0 ? Part::kFaces : Part::kDone;
        return;
      }
      case Part::kFaces: {
        const std::string face = "face " + std::to_string(faces_read) + " of " + std::to_string(nf);
        int64_t size = 0;
        if (!ParseInt(tok[0], &size))
          Fail(path, where() + face + ": bad vertex count '" + std::string(tok[0]) + "'");
        if (size < 3)
          Fail(path, where() + face + ": a face needs at least 3 vertices, has " +
                         std::to_string(size));
        if (static_cast<int64_t>(tok.size()) - 1 < size)
          Fail(path, where() + face + ": says " + std::to_string(size) + " vertices, lists " +
                         std::to_string(tok.size() - 1));
        poly.clear();
        for (int64_t j = 1; j <= size; ++j) {
          int64_t i = 0;
          if (!ParseInt(tok[j], &i))
            Fail(path, where() + face + ": bad vertex index '" + std::string(tok[j]) + "'");
          if (i < 0 || i >= nv)
            Fail(path, where() + face + ": vertex index " + std::to_string(i) +
                           " is out of range (" + std::to_string(nv) + " vertices)");
          poly.push_back(i);
        }
        AddPolygon(poly, &m);
        if (++faces_read == nf) part = Part::kDone;
        return;
      }
      case Part::kDone:
        Fail(path, where() + "more lines than the counts say (" + std::to_string(nv) +
                       " vertices, " + std::to_string(nf) + " faces)");
    }
  });
  const std::string end = " (the file ends at line " + std::to_string(last_line) + ")";
  if (part == Part::kHeader) Fail(path, "empty: no 'OFF' header");
  if (part == Part::kCounts) Fail(path, "truncated: no counts line after 'OFF'" + end);
  if (part == Part::kVertices)
    Fail(path, "truncated: " + std::to_string(m.vertices.size()) + " of " + std::to_string(nv) +
                   " vertices" + end);
  if (part == Part::kFaces)
    Fail(path, "truncated: " + std::to_string(faces_read) + " of " + std::to_string(nf) +
                   " faces" + end);
  return m;
}

// --------------------------------------------------------------------------------------- glTF

using Mat4 = std::array<double, 16>;  // column-major, as glTF

Mat4 Identity4() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

Mat4 Mul4(const Mat4& a, const Mat4& b) {
  Mat4 c{};
  for (int col = 0; col < 4; ++col)
    for (int row = 0; row < 4; ++row) {
      double s = 0.0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[col * 4 + k];
      c[col * 4 + row] = s;
    }
  return c;
}

Vec3 Transform(const Mat4& m, const Vec3& p) {
  return {m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12],
          m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13],
          m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14]};
}

class GltfReader {
 public:
  GltfReader(const json& doc, const fs::path& path, std::string_view glb_bin, bool is_glb)
      : doc_(doc), path_(path), glb_bin_(glb_bin), is_glb_(is_glb) {}

  // Per-vertex attributes to read beside POSITION (ReadGltfWithAttributes).
  void WantAttributes(const std::vector<std::string>& names) {
    names_ = names;
    values_.assign(names.size(), {});
    components_.assign(names.size(), 0);
  }
  std::vector<std::vector<double>> values_;
  std::vector<int> components_;

  TriangleMesh Read() {
    const std::string version = Get(doc_, "asset", "the document").value("version", "");
    if (version.empty() || version[0] != '2')
      Fail(path_, "glTF version '" + version + "' is not supported (expected 2.x)");
    LoadBuffers();
    TriangleMesh m;
    const json& meshes = doc_.contains("meshes") ? doc_["meshes"] : json::array();
    if (doc_.contains("scenes") && doc_["scenes"].is_array() && !doc_["scenes"].empty()) {
      const std::size_t s = doc_.value("scene", 0);
      const json& scenes = doc_["scenes"];
      if (s >= scenes.size()) Fail(path_, "scene " + std::to_string(s) + " does not exist");
      for (const json& n : scenes[s].value("nodes", json::array()))
        AddNode(Index(n, "a scene's node"), Identity4(), 0, &m);
    } else {
      // No scene: every mesh once, untransformed (the spec leaves it to the application).
      for (std::size_t i = 0; i < meshes.size(); ++i) AddMesh(i, Identity4(), &m);
    }
    return m;
  }

 private:
  const json& Get(const json& j, const char* key, const std::string& owner) const {
    if (!j.is_object() || !j.contains(key)) Fail(path_, owner + " has no \"" + key + "\"");
    return j[key];
  }
  std::size_t Index(const json& j, const std::string& what) const {
    if (!j.is_number_unsigned()) Fail(path_, what + " is not an index");
    return j.get<std::size_t>();
  }
  const json& Item(const char* array, std::size_t i) const {
    if (!doc_.contains(array) || !doc_[array].is_array() || i >= doc_[array].size())
      Fail(path_, std::string(array) + "[" + std::to_string(i) + "] does not exist");
    return doc_[array][i];
  }

  void LoadBuffers() {
    if (!doc_.contains("buffers")) return;
    const json& buffers = doc_["buffers"];
    for (std::size_t i = 0; i < buffers.size(); ++i) {
      const json& b = buffers[i];
      const std::string name = "buffers[" + std::to_string(i) + "]";
      std::string data;
      if (!b.contains("uri")) {
        if (!is_glb_ || i != 0) Fail(path_, name + " has no uri");
        data.assign(glb_bin_);
      } else {
        const std::string uri = b["uri"].get<std::string>();
        if (uri.rfind("data:", 0) == 0) {
          const std::size_t comma = uri.find(',');
          if (comma == std::string::npos || uri.substr(0, comma).find(";base64") == std::string::npos)
            Fail(path_, name + ": only base64 data URIs are supported");
          if (!Base64Decode(std::string_view(uri).substr(comma + 1), &data))
            Fail(path_, "bad character in a base64 data URI");
        } else {
          const fs::path file = path_.parent_path() / PercentDecode(uri);
          try {
            data = ReadBytes(file, "a glTF buffer");
          } catch (const std::exception& e) {
            Fail(path_, name + " (\"" + uri + "\"): " + e.what());
          }
        }
      }
      const uint64_t length = b.value("byteLength", uint64_t{0});
      if (data.size() < length)
        Fail(path_, name + " holds " + std::to_string(data.size()) + " bytes, byteLength says " +
                        std::to_string(length));
      buffers_.push_back(std::move(data));
    }
  }

  // Components per element of accessor `a` (SCALAR 1, VEC2 2, ...; 0: unknown type).
  int Components(std::size_t a) const {
    static const std::pair<const char*, int> kTypes[] = {{"SCALAR", 1}, {"VEC2", 2}, {"VEC3", 3},
                                                          {"VEC4", 4}, {"MAT4", 16}};
    const std::string type = Item("accessors", a).value("type", "");
    for (const auto& [t, c] : kTypes)
      if (type == t) return c;
    return 0;
  }

  // Values of accessor `a` as doubles, `components` per element; normalised integers map to
  // [0, 1] / [-1, 1] as the spec says.
  std::vector<double> ReadAccessor(std::size_t a, int components, const std::string& use) {
    const json& acc = Item("accessors", a);
    const std::string name = "accessors[" + std::to_string(a) + "] (" + use + ")";
    const std::string type = acc.value("type", "");
    const int n = Components(a);
    if (n != components)
      Fail(path_, name + " has type '" + type + "', expected " +
                      (components == 1 ? "SCALAR" : "VEC3"));
    if (acc.contains("sparse")) Fail(path_, name + ": sparse accessors are not supported");
    const int ct = acc.value("componentType", 0);
    std::size_t csize = 0;
    switch (ct) {
      case 5120: case 5121: csize = 1; break;
      case 5122: case 5123: csize = 2; break;
      case 5125: case 5126: csize = 4; break;
      default: Fail(path_, name + ": unknown componentType " + std::to_string(ct));
    }
    const uint64_t count = acc.value("count", uint64_t{0});
    const bool normalized = acc.value("normalized", false);
    std::vector<double> out;
    if (!acc.contains("bufferView")) {  // all zeros (spec)
      out.assign(count * n, 0.0);
      return out;
    }
    const json& view = Item("bufferViews", Index(acc["bufferView"], name + ".bufferView"));
    const std::size_t buffer = Index(Get(view, "buffer", "a bufferView"), "bufferView.buffer");
    if (buffer >= buffers_.size())
      Fail(path_, name + ": buffer " + std::to_string(buffer) + " does not exist");
    const std::string& data = buffers_[buffer];
    const uint64_t view_offset = view.value("byteOffset", uint64_t{0});
    const uint64_t view_length = view.value("byteLength", uint64_t{0});
    const uint64_t offset = acc.value("byteOffset", uint64_t{0});
    const uint64_t elem = csize * n;
    uint64_t stride = view.value("byteStride", uint64_t{0});
    if (stride == 0) stride = elem;
    if (stride < elem)
      Fail(path_, name + ": byteStride " + std::to_string(stride) + " is less than an element");
    if (view_offset + view_length > data.size())
      Fail(path_, name + ": its bufferView ends past the end of buffer " + std::to_string(buffer));
    if (count > 0 && offset + (count - 1) * stride + elem > view_length)
      Fail(path_, name + ": " + std::to_string(count) + " elements end past the end of its bufferView");
    out.resize(count * n);
    const char* base = data.data() + view_offset + offset;
    for (uint64_t i = 0; i < count; ++i)
      for (int k = 0; k < n; ++k) {
        const char* p = base + i * stride + k * csize;
        double v = 0.0;
        switch (ct) {
          case 5120: v = Norm<int8_t>(p, normalized, 127.0); break;
          case 5121: v = Norm<uint8_t>(p, normalized, 255.0); break;
          case 5122: v = Norm<int16_t>(p, normalized, 32767.0); break;
          case 5123: v = Norm<uint16_t>(p, normalized, 65535.0); break;
          case 5125: v = Norm<uint32_t>(p, false, 1.0); break;
          case 5126: v = Norm<float>(p, false, 1.0); break;
        }
        out[i * n + k] = v;
      }
    return out;
  }

  template <typename T>
  static double Norm(const char* p, bool normalized, double scale) {
    T v;
    std::memcpy(&v, p, sizeof(T));  // glTF is little-endian, as this host
    const double d = static_cast<double>(v);
    return normalized ? std::max(d / scale, -1.0) : d;
  }

  static Mat4 LocalTransform(const json& node) {
    if (node.contains("matrix")) {
      Mat4 m{};
      for (int i = 0; i < 16; ++i) m[i] = node["matrix"].at(i).get<double>();
      return m;
    }
    std::array<double, 3> t = {0, 0, 0}, s = {1, 1, 1};
    std::array<double, 4> q = {0, 0, 0, 1};  // x y z w
    if (node.contains("translation"))
      for (int i = 0; i < 3; ++i) t[i] = node["translation"].at(i).get<double>();
    if (node.contains("scale"))
      for (int i = 0; i < 3; ++i) s[i] = node["scale"].at(i).get<double>();
    if (node.contains("rotation"))
      for (int i = 0; i < 4; ++i) q[i] = node["rotation"].at(i).get<double>();
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                            {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                            {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    Mat4 m = Identity4();  // T * R * S
    for (int col = 0; col < 3; ++col)
      for (int row = 0; row < 3; ++row) m[col * 4 + row] = r[row][col] * s[col];
    for (int row = 0; row < 3; ++row) m[12 + row] = t[row];
    return m;
  }

  void AddNode(std::size_t n, const Mat4& parent, int depth, TriangleMesh* m) {
    if (depth > 64) Fail(path_, "node hierarchy deeper than 64 (a cycle?)");
    const json& node = Item("nodes", n);
    Mat4 world;
    try {
      // imr's display rotation (the exporter's "imr_upright" root): skipped, so that an imr
      // glTF reads back in its sequence's frame like its OBJ and PLY.
      const bool imr_upright = node.contains("extras") && node["extras"].is_object() &&
                               node["extras"].contains("imr_upright");
      world = imr_upright ? parent : Mul4(parent, LocalTransform(node));
    } catch (const json::exception& e) {
      Fail(path_, "nodes[" + std::to_string(n) + "]: bad transform (" + e.what() + ")");
    }
    if (node.contains("mesh")) AddMesh(Index(node["mesh"], "a node's mesh"), world, m);
    for (const json& c : node.value("children", json::array()))
      AddNode(Index(c, "a node's child"), world, depth + 1, m);
  }

  void AddMesh(std::size_t mesh, const Mat4& world, TriangleMesh* m) {
    const json& prims = Get(Item("meshes", mesh), "primitives", "meshes[" + std::to_string(mesh) + "]");
    for (std::size_t p = 0; p < prims.size(); ++p) {
      const std::string name = "meshes[" + std::to_string(mesh) + "].primitives[" + std::to_string(p) + "]";
      const json& prim = prims[p];
      const int mode = prim.value("mode", 4);
      if (mode < 4 || mode > 6) continue;  // points and lines have no area
      const json& attrs = Get(prim, "attributes", name);
      const std::vector<double> pos =
          ReadAccessor(Index(Get(attrs, "POSITION", name + ".attributes"), name + ".POSITION"), 3,
                       name + " POSITION");
      const std::size_t nv = pos.size() / 3;
      std::vector<uint64_t> idx;
      if (prim.contains("indices")) {
        for (double v : ReadAccessor(Index(prim["indices"], name + ".indices"), 1, name + " indices")) {
          // Any component type reads as a double here: a signed, fractional or huge value is no
          // index (and would be undefined as an integer).
          char text[32];
          std::snprintf(text, sizeof(text), "%.17g", v);
          if (!(v >= 0.0) || v != std::floor(v))
            Fail(path_, name + ": index " + text + " is not a vertex index (glTF indices are "
                            "unsigned integers)");
          if (v >= static_cast<double>(nv))
            Fail(path_, name + ": index " + text + " but POSITION has " + std::to_string(nv) +
                            " vertices");
          idx.push_back(static_cast<uint64_t>(v));
        }
      } else {
        for (std::size_t i = 0; i < nv; ++i) idx.push_back(i);
      }
      const uint64_t base = m->vertices.size();
      if (base + nv > std::numeric_limits<uint32_t>::max())
        Fail(path_, "more than 2^32 - 1 vertices");
      for (std::size_t i = 0; i < nv; ++i)
        m->vertices.push_back(Transform(world, {pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]}));
      for (std::size_t k = 0; k < names_.size(); ++k) {
        if (!attrs.contains(names_[k])) Fail(path_, name + " has no attribute " + names_[k]);
        const std::size_t a = Index(attrs[names_[k]], name + "." + names_[k]);
        const int c = Components(a);
        if (components_[k] != 0 && c != components_[k])
          Fail(path_, name + "." + names_[k] + " has " + std::to_string(c) +
                          " components, an earlier primitive's " + std::to_string(components_[k]));
        components_[k] = c;
        const std::vector<double> v = ReadAccessor(a, c, name + " " + names_[k]);
        if (v.size() != nv * static_cast<std::size_t>(c))
          Fail(path_, name + "." + names_[k] + " has " + std::to_string(v.size() / std::max(c, 1)) +
                          " values, POSITION " + std::to_string(nv));
        values_[k].insert(values_[k].end(), v.begin(), v.end());
      }
      auto add = [&](uint64_t a, uint64_t b, uint64_t c) {
        m->triangles.push_back({static_cast<uint32_t>(base + a), static_cast<uint32_t>(base + b),
                                static_cast<uint32_t>(base + c)});
      };
      if (mode == 4) {
        if (idx.size() % 3 != 0)
          Fail(path_, name + ": " + std::to_string(idx.size()) + " indices, not a multiple of 3");
        for (std::size_t i = 0; i + 2 < idx.size(); i += 3) add(idx[i], idx[i + 1], idx[i + 2]);
      } else if (mode == 5) {  // strip: keep the winding of even triangles
        for (std::size_t i = 0; i + 2 < idx.size(); ++i)
          i % 2 == 0 ? add(idx[i], idx[i + 1], idx[i + 2]) : add(idx[i + 1], idx[i], idx[i + 2]);
      } else {  // fan
        for (std::size_t i = 1; i + 1 < idx.size(); ++i) add(idx[0], idx[i], idx[i + 1]);
      }
    }
  }

  const json& doc_;
  const fs::path& path_;
  std::string_view glb_bin_;
  bool is_glb_;
  std::vector<std::string> buffers_;
  std::vector<std::string> names_;
};

json ParseJson(std::string_view text, const fs::path& path) {
  try {
    return json::parse(text.begin(), text.end());
  } catch (const json::parse_error& e) {
    Fail(path, std::string("not valid JSON: ") + e.what());
  }
}

struct GltfAttributes {
  const std::vector<std::string>* names = nullptr;
  std::vector<std::vector<double>>* values = nullptr;
  std::vector<int>* components = nullptr;
};

TriangleMesh RunGltf(const json& doc, const fs::path& path, std::string_view bin, bool glb,
                     const GltfAttributes& attributes = {}) {
  try {
    GltfReader reader(doc, path, bin, glb);
    if (attributes.names != nullptr) reader.WantAttributes(*attributes.names);
    TriangleMesh m = reader.Read();
    if (attributes.names != nullptr) {
      *attributes.values = std::move(reader.values_);
      *attributes.components = std::move(reader.components_);
    }
    return m;
  } catch (const json::exception& e) {  // a field of the wrong type
    Fail(path, std::string("malformed glTF: ") + e.what());
  }
}

TriangleMesh ParseGlb(std::string_view data, const fs::path& path, const GltfAttributes& attributes = {}) {
  auto u32 = [&](std::size_t at) {
    uint32_t v;
    std::memcpy(&v, data.data() + at, 4);
    return v;
  };
  if (data.size() < 20 || u32(0) != 0x46546C67u) Fail(path, "not a GLB file (no 'glTF' magic)");
  if (u32(4) != 2) Fail(path, "GLB version " + std::to_string(u32(4)) + " is not supported (expected 2)");
  const uint64_t total = u32(8);
  if (total > data.size())
    Fail(path, "truncated: the header says " + std::to_string(total) + " bytes, the file has " +
                   std::to_string(data.size()));
  std::string_view json_chunk, bin_chunk;
  for (uint64_t at = 12; at + 8 <= total;) {
    const uint64_t len = u32(at), type = u32(at + 4);
    if (at + 8 + len > total) Fail(path, "truncated: a chunk ends past the end of the file");
    const std::string_view chunk = data.substr(at + 8, len);
    if (type == 0x4E4F534Au && json_chunk.empty()) json_chunk = chunk;
    else if (type == 0x004E4942u && bin_chunk.empty()) bin_chunk = chunk;
    at += 8 + len;
  }
  if (json_chunk.empty()) Fail(path, "GLB has no JSON chunk");
  return RunGltf(ParseJson(json_chunk, path), path, bin_chunk, true, attributes);
}

}  // namespace

std::string GeometryFormat(const fs::path& path) {
  const std::string ext = Lower(path.extension().string());
  if (ext == ".obj") return "obj";
  if (ext == ".ply") return "ply";
  if (ext == ".gltf") return "gltf";
  if (ext == ".glb") return "glb";
  if (ext == ".off") return "off";
  if (ext == ".xyz" || ext == ".txt" || ext == ".asc") return "xyz";
  return "";
}

namespace {

// The first bytes of a file say what it is: checked before the whole file is read (a 2 GB file
// of zeros named .ply used to be read whole, 12 s, before "not a PLY file").
void CheckHead(const fs::path& path, const std::string& format) {
  const std::string head = InputFile::Open(path, kMeshWhat).ReadUpTo(4096);
  if (format == "ply") {
    if (head.rfind("ply\n", 0) != 0 && head.rfind("ply\r\n", 0) != 0)
      Fail(path, "not a PLY file (no 'ply' first line)");
  } else if (format == "glb") {
    if (head.rfind("glTF", 0) != 0) Fail(path, "not a GLB file (no 'glTF' magic)");
  } else if (const std::size_t nul = head.find('\0'); nul != std::string::npos) {
    // The text formats (OBJ, OFF, glTF's JSON, point lists) hold no NUL byte.
    Fail(path, "not a " + format + " file: a NUL byte at offset " + std::to_string(nul) +
                   " (a binary file?)");
  }
}

}  // namespace

TriangleMesh ReadGeometry(const fs::path& path) {
  const std::string format = GeometryFormat(path);
  if (format.empty())
    Fail(path, "unknown extension '" + path.extension().string() +
                   "' (expected .obj, .ply, .gltf, .glb, .off, or .xyz/.txt/.asc for points)");
  CheckHead(path, format);
  const std::string data = ReadBytes(path);
  if (format == "obj") return ParseObj(data, path);
  if (format == "ply") return ParsePly(data, path);
  if (format == "glb") return ParseGlb(data, path);
  if (format == "off") return ParseOff(data, path);
  if (format == "gltf") return RunGltf(ParseJson(data, path), path, {}, false);
  return ParseXyz(data, path);
}

TriangleMesh ReadMesh(const fs::path& path) {
  if (GeometryFormat(path) == "xyz") Fail(path, "a point file, not a mesh");
  TriangleMesh m = ReadGeometry(path);
  if (m.triangles.empty())
    Fail(path, "no triangles (" + std::to_string(m.vertices.size()) + " vertices)");
  return m;
}

TriangleMesh ReadGltfWithAttributes(const fs::path& path, const std::vector<std::string>& names,
                                    std::vector<std::vector<double>>* values,
                                    std::vector<int>* components) {
  const std::string format = GeometryFormat(path);
  if (format != "glb" && format != "gltf") Fail(path, "not a .gltf or .glb file");
  const std::string data = ReadBytes(path);
  const GltfAttributes a{&names, values, components};
  TriangleMesh m = format == "glb" ? ParseGlb(data, path, a)
                                   : RunGltf(ParseJson(data, path), path, {}, false, a);
  if (m.triangles.empty()) Fail(path, "no triangles (" + std::to_string(m.vertices.size()) + " vertices)");
  return m;
}

double MeshArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (const auto& t : mesh.triangles) {
    const Vec3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    const Vec3 u = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const Vec3 n = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    area += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  }
  return area;
}

}  // namespace imr::eval
