#include "host/io/openmvg_reader.h"

#include "host/io/json_fields.h"
#include "host/io/json_stream.h"
#include "host/io/schema.h"
#include "host/util/input_file.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <fstream>
#include <map>
#include <unordered_map>

namespace imr::io {
namespace {
using nlohmann::json;

constexpr uint64_t kUndefinedIndex = 4294967295u;  // OpenMVG's UndefinedIndexT
constexpr uint64_t kCerealNewBit = 0x80000000u;     // cereal: first occurrence of an id

struct ViewData {
  uint64_t id_view = 0, id_intrinsic = kUndefinedIndex, id_pose = kUndefinedIndex;
  std::string filename;
  std::string path;  // for messages
};

struct Reader {
  explicit Reader(const std::filesystem::path& file) : f(file.string()) {}

  // cereal's ptr_wrapper: the first occurrence of a pointer carries "data" and an id with the
  // high bit set; later occurrences carry only the id.
  const json& PtrData(const json& value, const std::string& path,
                      std::unordered_map<uint64_t, json>* seen) {
    const json& w = f.Member(value, "ptr_wrapper", path);
    const uint64_t id = f.Id(f.Member(w, "id", path + ".ptr_wrapper"), path + ".ptr_wrapper.id");
    const json* data = f.Optional(w, "data", path + ".ptr_wrapper");
    if (data != nullptr) return (*seen)[id & ~kCerealNewBit] = *data;
    auto it = seen->find(id & ~kCerealNewBit);
    if (it == seen->end())
      f.Fail(path + ".ptr_wrapper", "refers to pointer id " + std::to_string(id) +
                                        " which no earlier ptr_wrapper defined (no \"data\")");
    return it->second;
  }

  void View(std::size_t i, const json& e) {
    const std::string path = "views[" + std::to_string(i) + "]";
    const json& value = f.Member(e, "value", path);
    const json& d = PtrData(value, path + ".value", &view_ptrs);
    const std::string dp = path + ".value.ptr_wrapper.data";
    ViewData v;
    v.path = path;
    v.id_view = f.Id(f.Member(d, "id_view", dp), dp + ".id_view");
    if (const json* x = f.Optional(d, "id_intrinsic", dp)) v.id_intrinsic = f.Id(*x, dp + ".id_intrinsic");
    if (const json* x = f.Optional(d, "id_pose", dp)) v.id_pose = f.Id(*x, dp + ".id_pose");
    if (const json* x = f.Optional(d, "filename", dp)) v.filename = f.String(*x, dp + ".filename");
    if (!views.emplace(v.id_view, v).second)
      f.Fail(dp + ".id_view", "view " + std::to_string(v.id_view) + " is listed twice");
  }

  void Intrinsic(std::size_t i, const json& e) {
    const std::string path = "intrinsics[" + std::to_string(i) + "]";
    const uint64_t key = f.Id(f.Member(e, "key", path), path + ".key");
    const json& value = f.Member(e, "value", path);
    const std::string vp = path + ".value";
    // cereal's polymorphic types: the name is written with the first id that has the high bit.
    std::string name;
    const json* pid = f.Optional(value, "polymorphic_id", vp);
    if (const json* n = f.Optional(value, "polymorphic_name", vp)) {
      name = f.String(*n, vp + ".polymorphic_name");
      if (pid != nullptr) type_names[f.Id(*pid, vp + ".polymorphic_id") & ~kCerealNewBit] = name;
    } else if (pid != nullptr) {
      auto it = type_names.find(f.Id(*pid, vp + ".polymorphic_id") & ~kCerealNewBit);
      if (it == type_names.end())
        f.Fail(vp + ".polymorphic_id", "names no intrinsic type seen before (no polymorphic_name)");
      name = it->second;
    } else {
      f.Fail(vp, "missing field \"polymorphic_name\"");
    }
    const json& d = PtrData(value, vp, &intrinsic_ptrs);
    const Intrinsics k = OpenMvgIntrinsicFromData(f, name, d, vp + ".ptr_wrapper.data");
    if (!intrinsics.emplace(key, k).second)
      f.Fail(path + ".key", "intrinsic " + std::to_string(key) + " is listed twice");
  }

  void Extrinsic(std::size_t i, const json& e) {
    const std::string path = "extrinsics[" + std::to_string(i) + "]";
    const uint64_t key = f.Id(f.Member(e, "key", path), path + ".key");
    const json& value = f.Member(e, "value", path);
    const std::string vp = path + ".value";
    CameraGeometry g;
    const Mat3 r = f.Rotation(f.Member(value, "rotation", vp), vp + ".rotation");
    SetFromCenter(r, f.Vector3(f.Member(value, "center", vp), vp + ".center"), &g);
    if (!poses.emplace(key, g).second)
      f.Fail(path + ".key", "pose " + std::to_string(key) + " is listed twice");
  }

  void Landmark(std::size_t i, const json& e) {
    const std::string path = "structure[" + std::to_string(i) + "]";
    SfmPoint p;
    p.id = f.Id(f.Member(e, "key", path), path + ".key");
    const json& value = f.Member(e, "value", path);
    const std::string vp = path + ".value";
    p.position = f.Vector3(f.Member(value, "X", vp), vp + ".X");
    const json& obs = f.Member(value, "observations", vp);
    if (!obs.is_array()) f.Fail(vp + ".observations", "expected an array, got " + Describe(obs));
    for (std::size_t j = 0; j < obs.size(); ++j) {
      const std::string op = vp + ".observations[" + std::to_string(j) + "]";
      SfmObservation o;
      o.view_id = f.Id(f.Member(obs[j], "key", op), op + ".key");
      const json& ov = f.Member(obs[j], "value", op);
      const std::vector<double> x = f.Numbers(f.Member(ov, "x", op + ".value"), op + ".value.x");
      if (x.size() != 2) f.Fail(op + ".value.x", "expected 2 numbers");
      o.x = x[0], o.y = x[1];
      p.observations.push_back(o);
    }
    landmark_paths.push_back(path);
    points.push_back(std::move(p));
  }

  SfmModel Finish() {
    SfmModel m;
    m.file = f.file();
    // SfMInit_ImageListing writes views and intrinsics only (older OpenMVG: empty extrinsics
    // and structure); a third-party writer may leave out the points.
    const std::string run_sfm = "run the SfM (openMVG_main_SfM) or, with known poses, "
                                "openMVG_main_ComputeStructureFromKnownPoses, and give imr the "
                                "sfm_data.json it writes (convert an sfm_data.bin with "
                                "openMVG_main_ConvertSfM_DataFormat)";
    const std::string listing = " (openMVG_main_SfMInit_ImageListing writes views and intrinsics only); ";
    for (const char* k : {"views", "intrinsics"})
      if (!seen_members.count(k)) f.Fail("(top level)", std::string("missing field \"") + k + "\"");
    if (!seen_members.count("extrinsics"))
      f.Fail("(top level)", "missing field \"extrinsics\": the file has no camera poses" + listing + run_sfm);
    if (!seen_members.count("structure"))
      f.Fail("(top level)", "missing field \"structure\": the file has no 3D points" + listing + run_sfm);
    m.points_file = f.file() + ": structure";
    m.views_file = f.file() + ": extrinsics";
    m.no_points_hint = " (the array is empty); " + run_sfm;
    std::unordered_map<uint64_t, bool> posed;  // view id -> has a pose
    for (const auto& [id, v] : views) {
      const std::string dp = v.path + ".value.ptr_wrapper.data";
      const bool has_intrinsic = v.id_intrinsic != kUndefinedIndex;
      if (has_intrinsic && !intrinsics.count(v.id_intrinsic))
        f.Fail(dp + ".id_intrinsic", "view " + std::to_string(id) + " uses intrinsic " +
                                         std::to_string(v.id_intrinsic) + ", which intrinsics does not list");
      auto pose = poses.find(v.id_pose);
      posed[id] = pose != poses.end();
      if (pose == poses.end()) {
        ++m.views_without_pose;
        continue;
      }
      CameraGeometry g = pose->second;
      g.id = id;
      g.name = v.filename;
      g.has_intrinsics = has_intrinsic;
      if (has_intrinsic) g.intrinsics = intrinsics.at(v.id_intrinsic);
      m.views.push_back(std::move(g));
    }
    std::sort(m.views.begin(), m.views.end(),
              [](const CameraGeometry& a, const CameraGeometry& b) { return a.id < b.id; });
    for (std::size_t i = 0; i < points.size(); ++i) {
      SfmPoint& p = points[i];
      std::vector<SfmObservation> kept;
      for (std::size_t j = 0; j < p.observations.size(); ++j) {
        const SfmObservation& o = p.observations[j];
        auto it = posed.find(o.view_id);
        if (it == posed.end())
          f.Fail(landmark_paths[i] + ".value.observations[" + std::to_string(j) + "].key",
                 "landmark " + std::to_string(p.id) + " is observed in view " +
                     std::to_string(o.view_id) + ", which views does not list");
        if (it->second)
          kept.push_back(o);
        else
          ++m.observations_skipped;
      }
      p.observations = std::move(kept);
    }
    std::vector<std::size_t> order(points.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return points[a].id < points[b].id; });
    for (std::size_t i = 0; i < order.size(); ++i) {
      if (i > 0 && points[order[i]].id == points[order[i - 1]].id)
        f.Fail(landmark_paths[order[i]] + ".key",
               "landmark " + std::to_string(points[order[i]].id) + " is listed twice");
      m.points.push_back(std::move(points[order[i]]));
    }
    return m;
  }

  JsonFields f;
  std::unordered_map<uint64_t, json> view_ptrs, intrinsic_ptrs;
  std::map<uint64_t, std::string> type_names;
  std::map<uint64_t, ViewData> views;
  std::map<uint64_t, Intrinsics> intrinsics;
  std::map<uint64_t, CameraGeometry> poses;
  std::vector<SfmPoint> points;
  std::vector<std::string> landmark_paths;
  std::set<std::string> seen_members;
};

}  // namespace

Intrinsics OpenMvgIntrinsicFromData(const JsonFields& f, const std::string& name, const json& d,
                                    const std::string& dp) {
  Intrinsics k;
  k.source_model = name;
  if (const json* w = f.Optional(d, "width", dp)) k.width = static_cast<int>(f.Integer(*w, dp + ".width"));
  if (const json* h = f.Optional(d, "height", dp)) k.height = static_cast<int>(f.Integer(*h, dp + ".height"));
  if (f.Optional(d, "focal_length", dp) == nullptr && f.Optional(d, "prior_focal_length", dp) != nullptr)
    f.Fail(dp, "missing field \"focal_length\"; the file has \"prior_focal_length\" only, a guess "
               "before the SfM refined it: not a reconstruction's intrinsics");
  k.fx = k.fy = f.Number(f.Member(d, "focal_length", dp), dp + ".focal_length");
  const std::vector<double> pp = f.Numbers(f.Member(d, "principal_point", dp), dp + ".principal_point");
  if (pp.size() != 2) f.Fail(dp + ".principal_point", "expected 2 numbers");
  k.cx = pp[0], k.cy = pp[1];
  if (const std::string p = IntrinsicsProblem(k.fx, k.fy, k.cx, k.cy); !p.empty())
    f.Fail(dp + ".focal_length", p);
  k.source_params = {k.fx, k.cx, k.cy};
  auto disto = [&](const char* field, std::size_t n) {
    const std::vector<double> p = f.Numbers(f.Member(d, field, dp), dp + "." + field);
    if (p.size() != n)
      f.Fail(dp + "." + field, "the " + name + " model has " + std::to_string(n) +
                                   " distortion values, got " + std::to_string(p.size()));
    k.source_params.insert(k.source_params.end(), p.begin(), p.end());
    return p;
  };
  k.projectable = true;
  if (name == "pinhole") {
  } else if (name == "pinhole_radial_k1") {
    k.k1 = disto("disto_k1", 1)[0];
  } else if (name == "pinhole_radial_k3") {
    const auto p = disto("disto_k3", 3);
    k.k1 = p[0], k.k2 = p[1], k.k3 = p[2];
  } else if (name == "pinhole_brown_t2") {
    const auto p = disto("disto_t2", 5);
    k.k1 = p[0], k.k2 = p[1], k.k3 = p[2], k.p1 = p[3], k.p2 = p[4];
  } else if (name == "fisheye") {  // OpenCV's equidistant model, as COLMAP's OPENCV_FISHEYE
    const auto p = disto("disto_fisheye", 4);
    k.lens = Lens::kFisheye;
    k.k1 = p[0], k.k2 = p[1], k.k3 = p[2], k.k4 = p[3];
  } else {
    k.projectable = false;  // spherical, ...: kept, not projected
  }
  // imr's own stream export keeps a COLMAP camera as COLMAP wrote it (OpenMVG has no name for
  // FOV, thin prism, ...): that wins over the OpenMVG fields, which other readers use.
  if (const json* model = f.Optional(d, "colmap_model", dp)) {
    const std::string name_c = f.String(*model, dp + ".colmap_model");
    const std::vector<double> params = f.Numbers(f.Member(d, "colmap_params", dp), dp + ".colmap_params");
    Intrinsics c;
    std::string error;
    if (!IntrinsicsFromColmap(name_c, params, k.width, k.height, &c, &error))
      f.Fail(dp + ".colmap_params", error);
    return c;
  }
  return k;
}

void OpenMvgIntrinsicToData(const Intrinsics& k, std::string* name, json* data) {
  *data = {{"width", k.width}, {"height", k.height}, {"focal_length", k.fx},
           {"principal_point", {k.cx, k.cy}}};
  if (ColmapModelId(k.source_model) >= 0) {  // read back exactly (OpenMvgIntrinsicFromData)
    (*data)["colmap_model"] = k.source_model;
    (*data)["colmap_params"] = k.source_params;
  }
  if (k.lens == Lens::kFisheye) {
    *name = "fisheye";  // what OpenMVG cannot hold (thin prism, tangential) is dropped
    (*data)["disto_fisheye"] = {k.k1, k.k2, k.k3, k.k4};
  } else if (k.p1 != 0.0 || k.p2 != 0.0) {
    *name = "pinhole_brown_t2";
    (*data)["disto_t2"] = {k.k1, k.k2, k.k3, k.p1, k.p2};
  } else if (k.k2 != 0.0 || k.k3 != 0.0) {
    *name = "pinhole_radial_k3";
    (*data)["disto_k3"] = {k.k1, k.k2, k.k3};
  } else if (k.k1 != 0.0) {
    *name = "pinhole_radial_k1";
    (*data)["disto_k1"] = {k.k1};
  } else {
    *name = "pinhole";
  }
}

namespace {

// OpenMVG's binary sfm_data (a cereal portable binary archive; what openMVG_main_SfM writes as
// sfm_data.bin): refused before parsing, with the command that converts it.
void RefuseBinary(const std::filesystem::path& file) {
  // The open rule: a FIFO or a device named as the model is refused by name, not read.
  const std::string bytes = InputFile::Open(file, "an OpenMVG sfm_data JSON file").ReadUpTo(64);
  const char* head = bytes.data();
  const std::size_t n = bytes.size();
  std::size_t i = 0;
  while (i < n && std::isspace(static_cast<unsigned char>(head[i]))) ++i;
  const bool has_nul = std::memchr(head, '\0', n) != nullptr;
  if (has_nul || (file.extension() == ".bin" && i < n && head[i] != '{'))
    throw std::runtime_error(
        file.string() + ": an OpenMVG binary sfm_data (cereal archive); imr reads the JSON form: "
        "convert it with openMVG_main_ConvertSfM_DataFormat -i " + file.string() + " -o " +
        (file.parent_path() / (file.stem().string() + ".json")).string());
}

}  // namespace

SfmModel ReadOpenMvg(const std::filesystem::path& file) {
  RefuseBinary(file);
  Reader r(file);
  r.seen_members = StreamJsonFile(
      file, {"views", "intrinsics", "extrinsics", "structure"},
      [&](const std::string& key, json&& value) {
        if (key == "sfm_data_version" && !value.is_string())
          r.f.Fail("sfm_data_version", "expected a string, got " + Describe(value));
        if (key == "views" || key == "intrinsics" || key == "extrinsics" || key == "structure")
          r.f.Fail(key, "expected an array, got " + Describe(value));
      },
      [&](const std::string& key, std::size_t i, json&& e) {
        if (key == "views") r.View(i, e);
        else if (key == "intrinsics") r.Intrinsic(i, e);
        else if (key == "extrinsics") r.Extrinsic(i, e);
        else r.Landmark(i, e);
      });
  return r.Finish();
}

}  // namespace imr::io
