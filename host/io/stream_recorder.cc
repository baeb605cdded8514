#include "host/io/stream_recorder.h"

#include "host/io/openmvg_reader.h"
#include "host/util/json_text.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <unordered_set>

namespace imr::io {
using nlohmann::json;
namespace fs = std::filesystem;

std::string StreamRecorderOptions::Check() const {
  if (spool.empty()) return "spool: a folder for the spool files is required";
  std::error_code ec;
  if (!fs::is_directory(spool, ec)) return "spool: " + spool.string() + " is not a folder";
  if (sort_run_records < 1) return "sort_run_records: at least 1";
  if (evict_after_keyframes < 1) return "evict_after_keyframes: at least 1";
  return "";
}

// One observation as it reached the engine: the view it belongs to (arrival index), the point,
// its estimate then, and the keyframe (later than the view's for a late observation).
struct StreamRecorder::ObservationRecord {
  uint64_t view;
  uint64_t point;
  Vec3 x;
  int64_t keyframe;
};

bool StreamRecorder::ObservationLess::operator()(const ObservationRecord& a,
                                                 const ObservationRecord& b) const {
  return a.view < b.view;  // stable: a view's observations stay in the order they came
}

// A view as spooled: fixed fields, then the name's bytes.
struct ViewFixed {
  uint64_t id;
  int64_t keyframe;
  Vec3 center;
  Mat3 rotation;  // the source's, else the identity
  uint64_t full;  // index of its intrinsics in full_
  uint64_t name_bytes;
};
struct StreamRecorder::ViewHead {
  ViewFixed f;
  std::string name;  // the source's image name, else view_<id>
};

namespace {

// A point's state as spooled when it leaves memory: a head (sub 0: estimate, flags, the last
// keyframe that named it) and one record per camera (sub 1 + j), all with the eviction's number.
struct PointRecord {
  uint64_t id;
  uint64_t seq;   // the eviction: the latest wins
  uint32_t sub;   // 0: the head; 1 + j: camera j
  uint32_t flags;  // head: 1 removed
  uint64_t value;  // head: the keyframe that last named it; camera: its id
  Vec3 position;   // head only
};
struct PointLess {
  bool operator()(const PointRecord& a, const PointRecord& b) const {
    if (a.id != b.id) return a.id < b.id;
    if (a.seq != b.seq) return a.seq < b.seq;
    return a.sub < b.sub;
  }
};

// A COLMAP track entry on its way to images.txt: view, point, its place among the point's
// cameras, and the point's final estimate.
struct EntryRecord {
  uint64_t view;
  uint64_t point;
  uint64_t j;
  Vec3 position;
};
struct EntryLess {
  bool operator()(const EntryRecord& a, const EntryRecord& b) const {
    return a.view != b.view ? a.view < b.view : a.point < b.point;
  }
};

// The same entry on its way to points3D.txt: its image and 2D point, its reprojection error.
struct TrackRecord {
  uint64_t point;
  uint64_t j;
  uint32_t image_id;
  uint32_t point2d_idx;
  uint64_t has_error;
  double error;
  Vec3 position;
};
struct TrackLess {
  bool operator()(const TrackRecord& a, const TrackRecord& b) const {
    return a.point != b.point ? a.point < b.point : a.j < b.j;
  }
};

std::string Vec(const Vec3& v) {
  return "[" + ExactNumber(v[0]) + ", " + ExactNumber(v[1]) + ", " + ExactNumber(v[2]) + "]";
}

// A placeholder for cameras whose intrinsics the source does not know (said in the file).
Intrinsics PlaceholderIntrinsics() {
  Intrinsics k;
  k.source_model = "pinhole";
  k.width = 1000, k.height = 1000;
  k.fx = k.fy = 500.0, k.cx = k.cy = 500.0;
  k.projectable = true;
  return k;
}

// What the files list of a camera: one entry per class of these.
bool SameIntrinsics(const Intrinsics& a, const Intrinsics& b) {
  return a.source_model == b.source_model && a.source_params == b.source_params &&
         a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.k1 == b.k1 && a.k2 == b.k2 && a.k3 == b.k3 &&
         a.p1 == b.p1 && a.p2 == b.p2;
}

// Every field: the projection of the COLMAP export's 2D points uses the view's own.
bool FullySame(const Intrinsics& a, const Intrinsics& b) {
  return SameIntrinsics(a, b) && a.lens == b.lens && a.k4 == b.k4 && a.q1 == b.q1 &&
         a.q2 == b.q2 && a.q3 == b.q3 && a.s1 == b.s1 && a.s2 == b.s2 && a.omega == b.omega &&
         a.projectable == b.projectable;
}

std::size_t IndexOf(std::vector<Intrinsics>* list, const Intrinsics& k,
                    bool (*same)(const Intrinsics&, const Intrinsics&)) {
  std::size_t j = 0;
  while (j < list->size() && !same((*list)[j], k)) ++j;
  if (j == list->size()) list->push_back(k);
  return j;
}

// Copies a text spool into `out`.
void CopyInto(const fs::path& from, SpoolWriter* out) {
  SpoolReader in(from);
  char chunk[4096];
  std::size_t n;
  while ((n = in.ReadUpTo(chunk, sizeof chunk)) > 0) out->Write(chunk, n);
}

}  // namespace

int64_t StreamRecorder::ViewIndex::Find(uint64_t id) const {
  auto it = runs_.upper_bound(id);
  if (it == runs_.begin()) return -1;
  --it;
  if (id - it->first >= it->second.count) return -1;
  return static_cast<int64_t>(it->second.first_index + (id - it->first));
}

void StreamRecorder::ViewIndex::Add(uint64_t id, uint64_t index) {
  if (!runs_.empty()) {
    auto last = std::prev(runs_.end());
    if (id == last->first + last->second.count && index == last->second.first_index + last->second.count) {
      ++last->second.count;
      return;
    }
  }
  runs_.emplace(id, Run{1, index});
}

StreamRecorder::StreamRecorder(const KeyframeSource* source, std::string written_by,
                               StreamRecorderOptions options)
    : source_(source), written_by_(std::move(written_by)), options_(std::move(options)) {
  if (const std::string why = options_.Check(); !why.empty())
    throw std::invalid_argument("stream recorder: " + why);
  evict_after_ = options_.evict_after_keyframes;
  const fs::path& d = options_.spool;
  views_out_ = std::make_unique<SpoolWriter>(d / "views.bin");
  keyframes_out_ = std::make_unique<SpoolWriter>(d / "keyframes.txt");
  points_out_ = std::make_unique<SpoolWriter>(d / "points.bin");
  observations_ = std::make_unique<ExternalSort<ObservationRecord, ObservationLess>>(
      d, "observations", options_.sort_run_records);
}

StreamRecorder::~StreamRecorder() = default;

void StreamRecorder::AddView(const engine::Camera& c, int64_t keyframe) {
  const CameraGeometry* g = source_ ? source_->Camera(c.id) : nullptr;
  const Intrinsics k = g && g->has_intrinsics ? g->intrinsics : PlaceholderIntrinsics();
  placeholder_ |= !(g && g->has_intrinsics);
  const std::size_t full = IndexOf(&full_, k, FullySame);
  if (full == slam_of_full_.size()) {  // a new camera model: its classes in first-use order
    slam_of_full_.push_back(IndexOf(&slam_intrinsics_, k, SameIntrinsics));
    // COLMAP puts the top-left pixel's centre at (0.5, 0.5), every other reader of imr at (0, 0).
    Intrinsics shifted = k;
    if (ColmapModelId(k.source_model) < 0) shifted.cx += 0.5, shifted.cy += 0.5;
    const std::size_t j = IndexOf(&colmap_intrinsics_, shifted, SameIntrinsics);
    if (j == colmap_cameras_.size()) {
      ColmapModel::Camera cam;
      cam.id = static_cast<uint32_t>(j + 1);
      if (!IntrinsicsToColmap(shifted, &cam.model, &cam.params)) {
        cam.model = "PINHOLE";  // e.g. an OpenMVG fisheye: its pinhole part
        cam.params = {shifted.fx, shifted.fy, shifted.cx, shifted.cy};
      }
      cam.width = static_cast<uint64_t>(std::max(shifted.width, 0));
      cam.height = static_cast<uint64_t>(std::max(shifted.height, 0));
      colmap_cameras_.push_back(std::move(cam));
    }
    colmap_of_full_.push_back(j);
  }
  const std::string name = g && !g->name.empty() ? g->name : "view_" + std::to_string(c.id);
  ViewFixed f{c.id, keyframe, c.center, g ? g->rotation : Identity3(), full, name.size()};
  views_out_->Put(f);
  views_out_->Write(name);
  ids_fit_ &= c.id < 0xFFFFFFFFu;
  view_index_.Add(c.id, static_cast<uint64_t>(views_));
  ++views_;
}

void StreamRecorder::Record(const engine::KeyframeUpdate& u, const KeyframeInfo& info) {
  const int64_t k = keyframes_;
  for (const engine::Camera& c : u.cameras) {
    if (view_index_.Find(c.id) >= 0) continue;  // the engine keeps a camera's first centre
    AddView(c, k);
  }
  Recover(u);
  for (uint64_t id : u.removed_points) {
    auto it = points_.find(id);
    if (it == points_.end()) continue;
    it->second.removed = true;
    it->second.named = k;
  }
  auto observe = [&](uint64_t cam, uint64_t point, const Vec3& x) {
    const int64_t view = view_index_.Find(cam);
    if (view < 0) return;
    observations_->Add({static_cast<uint64_t>(view), point, x, k});
    ++stats_.observations;
  };
  for (const engine::MovedPoint& m : u.moved_points) {
    auto it = points_.find(m.id);
    if (it == points_.end()) continue;
    PointState& s = it->second;
    s.named = k;
    std::vector<uint64_t> added;
    for (uint64_t c : m.camera_ids)
      if (std::find(s.cameras.begin(), s.cameras.end(), c) == s.cameras.end() &&
          std::find(added.begin(), added.end(), c) == added.end())
        added.push_back(c);
    if (added.empty() && m.position == s.position) continue;  // nothing reaches the engine
    if (added.empty()) {
      if (s.cameras.empty()) ++unrepresentable_;
      else observe(s.cameras.back(), m.id, m.position);  // a move seen by no new camera
    }
    for (uint64_t c : added) {
      observe(c, m.id, m.position);
      s.cameras.push_back(c);
    }
    s.position = m.position;
  }
  for (const engine::NewPoint& p : u.new_points) {
    PointState s;
    s.position = p.position;
    s.named = k;
    for (uint64_t c : p.camera_ids)
      if (std::find(s.cameras.begin(), s.cameras.end(), c) == s.cameras.end()) {
        s.cameras.push_back(c);
        observe(c, p.id, p.position);
      }
    if (s.cameras.empty()) ++unrepresentable_;
    points_[p.id] = std::move(s);
  }
  std::vector<uint64_t> removed = u.removed_points;
  std::sort(removed.begin(), removed.end());
  std::string line = k ? ",\n" : "";
  line += "  {\"keyframe\": " + std::to_string(k) + ", \"frame\": " + std::to_string(info.frame) +
          ", \"removed_points\": [";
  for (std::size_t i = 0; i < removed.size(); ++i) line += (i ? ", " : "") + std::to_string(removed[i]);
  line += "]}";
  keyframes_out_->Write(line);
  ++keyframes_;
  Evict(k);  // a pass over the points in memory: small beside the engine's keyframe
}

void StreamRecorder::Evict(int64_t k) {
  const uint64_t seq = static_cast<uint64_t>(evictions_++);
  for (auto it = points_.begin(); it != points_.end();) {
    const PointState& s = it->second;
    if (k - s.named < evict_after_) {
      ++it;
      continue;
    }
    PointRecord head{it->first, seq, 0, s.removed ? 1u : 0u, static_cast<uint64_t>(s.named), s.position};
    points_out_->Put(head);
    for (std::size_t j = 0; j < s.cameras.size(); ++j)
      points_out_->Put(PointRecord{it->first, seq, static_cast<uint32_t>(1 + j), 0, s.cameras[j], Vec3{}});
    ++stats_.points_spooled;
    it = points_.erase(it);
  }
  // A map keeps its buckets when emptied: a new one holds what is left.
  if (points_.bucket_count() > 4 * (points_.size() + 16)) {
    std::unordered_map<uint64_t, PointState> kept(points_.begin(), points_.end());
    points_.swap(kept);
  }
}

void StreamRecorder::Recover(const engine::KeyframeUpdate& u) {
  if (stats_.points_spooled == 0) return;
  std::unordered_set<uint64_t> wanted;
  for (const engine::MovedPoint& m : u.moved_points)
    if (!points_.count(m.id)) wanted.insert(m.id);
  for (uint64_t id : u.removed_points)
    if (!points_.count(id)) wanted.insert(id);
  if (wanted.empty()) return;
  // One read of the spool for all of them: each point's latest eviction.
  points_out_->Flush();
  ++stats_.spool_scans;
  std::unordered_map<uint64_t, std::pair<uint64_t, PointState>> found;
  SpoolReader in(points_out_->path());
  PointRecord r;
  while (in.Get(&r)) {
    if (!wanted.count(r.id)) continue;
    if (r.sub == 0) {
      auto& [seq, s] = found[r.id];
      seq = r.seq;
      s = PointState{};
      s.position = r.position;
      s.removed = r.flags & 1u;
      s.named = static_cast<int64_t>(r.value);
    } else {
      auto it = found.find(r.id);
      if (it != found.end() && it->second.first == r.seq) it->second.second.cameras.push_back(r.value);
    }
  }
  for (auto& [id, entry] : found) {
    PointState& s = entry.second;
    // Named again this long after: keep points in memory for twice that from now on.
    const int64_t gap = keyframes_ - s.named;
    if (gap < (1 << 20)) evict_after_ = std::max<int>(evict_after_, static_cast<int>(2 * gap));
    s.named = keyframes_;
    points_.emplace(id, std::move(s));
    ++stats_.points_recovered;
  }
}

bool StreamRecorder::ReadViewHead(SpoolReader* in, ViewHead* v) const {
  if (!in->Get(&v->f)) return false;
  v->name.resize(v->f.name_bytes);
  if (v->f.name_bytes > 0 && !in->Read(v->name.data(), v->name.size()))
    throw std::runtime_error(views_out_->path().string() + ": ends within a view's name: the spool is damaged");
  return true;
}

void StreamRecorder::WriteSlamJson(const fs::path& file) {
  views_out_->Flush();
  keyframes_out_->Flush();
  SpoolWriter out(file, /*sync=*/true);
  out.Write("{\n\"slam_data_version\": \"0.3\",\n\"root_path\": \"\",\n");
  json note = {{"written_by", written_by_},
               {"what", "the per-keyframe updates (cameras, new points, moves, removals) that "
                        "reached imr's engine; replaying this file with imr's slam_json format "
                        "reproduces the run"},
               {"min_views", 1}};
  if (placeholder_) note["placeholder_intrinsics"] = "some cameras' intrinsics were unknown: pinhole f=500, 1000x1000";
  std::string head = DumpJson(note);  // written_by holds the sequence's name: bytes
  head.pop_back();  // reopen the object to append the keyframes
  out.Write("\"imr_stream\": " + head + ", \"keyframes\": [\n");
  CopyInto(keyframes_out_->path(), &out);
  if (keyframes_ > 0) out.Write("\n");
  out.Write("]},\n\"intrinsics\": [\n");
  for (std::size_t j = 0; j < slam_intrinsics_.size(); ++j) {
    std::string name;
    json data;
    OpenMvgIntrinsicToData(slam_intrinsics_[j], &name, &data);
    const json e = {{"intrinsicId", j},
                    {"value", {{"polymorphic_id", 2147483649u}, {"polymorphic_name", name},
                               {"ptr_wrapper", {{"id", 2147483649u + j}, {"data", data}}}}}};
    out.Write("  " + DumpJson(e) + (j + 1 < slam_intrinsics_.size() ? ",\n" : "\n"));
  }
  out.Write("],\n\"views\": [\n");
  SpoolReader views(views_out_->path());
  auto observations = observations_->Read();
  ObservationRecord o{};
  bool have = observations->Next(&o);
  ViewHead v;
  std::string s;
  for (int64_t i = 0; ReadViewHead(&views, &v); ++i) {
    const std::size_t intr = slam_of_full_[v.f.full];
    const Mat3& r = v.f.rotation;
    s = "  {\"viewId\": " + std::to_string(v.f.id) + ", \"keyframe\": " + std::to_string(v.f.keyframe) +
        ", \"local_path\": \"\", \"filename\": " + DumpJson(json(v.name)) +  // image names are bytes
        ", \"width\": " + std::to_string(slam_intrinsics_[intr].width) +
        ", \"height\": " + std::to_string(slam_intrinsics_[intr].height) +
        ", \"id_intrinsic\": " + std::to_string(intr) + ",\n   \"extrinsic\": {\"rotation\": [" +
        Vec(r[0]) + ", " + Vec(r[1]) + ", " + Vec(r[2]) + "], \"center\": " + Vec(v.f.center) +
        "},\n   \"observations\": [";
    for (bool first = true; have && o.view == static_cast<uint64_t>(i); have = observations->Next(&o)) {
      s += first ? "\n    " : ",\n    ";
      first = false;
      s += "{\"pointId\": " + std::to_string(o.point) + ", \"X\": " + Vec(o.x);
      if (o.keyframe != v.f.keyframe) s += ", \"keyframe\": " + std::to_string(o.keyframe);
      s += "}";
      if (s.size() >= SpoolWriter::kBufferBytes) out.Write(s), s.clear();
    }
    s += i + 1 < views_ ? "]},\n" : "]}\n";
    out.Write(s);
  }
  out.Write("]\n}\n");
  out.Close();
}

template <class F>
void StreamRecorder::ForEachPoint(F f) {
  points_out_->Flush();
  ExternalSort<PointRecord, PointLess> sorted(options_.spool, "points-sorted", options_.sort_run_records);
  {
    SpoolReader in(points_out_->path());
    PointRecord r;
    while (in.Get(&r)) sorted.Add(r);
  }
  auto reader = sorted.Read();
  PointRecord r{};
  bool have = reader->Next(&r);
  // The next point of the spool at its latest eviction.
  auto next_spooled = [&](uint64_t* id, PointState* s) {
    if (!have) return false;
    *id = r.id;
    uint64_t seq = 0;
    for (; have && r.id == *id; have = reader->Next(&r)) {
      if (r.sub == 0) {
        seq = r.seq;
        *s = PointState{};
        s->position = r.position;
        s->removed = r.flags & 1u;
      } else if (r.seq == seq) {
        s->cameras.push_back(r.value);
      }
    }
    return true;
  };
  std::vector<uint64_t> in_memory;
  in_memory.reserve(points_.size());
  for (const auto& [id, s] : points_) in_memory.push_back(id);
  std::sort(in_memory.begin(), in_memory.end());
  uint64_t id = 0;
  PointState s;
  bool spooled = next_spooled(&id, &s);
  std::size_t m = 0;
  while (spooled || m < in_memory.size()) {
    if (spooled && (m == in_memory.size() || id < in_memory[m])) {
      f(id, s);
      spooled = next_spooled(&id, &s);
    } else {
      if (spooled && id == in_memory[m]) spooled = next_spooled(&id, &s);  // memory is newer
      f(in_memory[m], points_.at(in_memory[m]));
      ++m;
    }
  }
}

void StreamRecorder::WriteColmap(const fs::path& dir) {
  views_out_->Flush();
  // Every track entry, by view and point: the order of images.txt's 2D points.
  ExternalSort<EntryRecord, EntryLess> entries(options_.spool, "entries", options_.sort_run_records);
  std::size_t points = 0;
  ForEachPoint([&](uint64_t id, const PointState& s) {
    if (s.removed || s.cameras.empty()) return;
    ++points;
    for (std::size_t j = 0; j < s.cameras.size(); ++j) {
      const int64_t view = view_index_.Find(s.cameras[j]);
      if (view < 0)
        throw std::runtime_error("COLMAP export: point " + std::to_string(id) + "'s camera " +
                                 std::to_string(s.cameras[j]) + " is no camera of the run");
      entries.Add({static_cast<uint64_t>(view), id, j, s.position});
    }
  });
  {
    SpoolWriter cameras(dir / "cameras.txt", /*sync=*/true);
    cameras.Write(ColmapCamerasText(colmap_cameras_));
    cameras.Close();
  }

  ExternalSort<TrackRecord, TrackLess> tracks(options_.spool, "tracks", options_.sort_run_records);
  {
    SpoolWriter out(dir / "images.txt", /*sync=*/true);
    out.Write(ColmapImagesHeader(static_cast<std::size_t>(views_), entries.size()));
    SpoolReader views(views_out_->path());
    auto observations = observations_->Read();
    ObservationRecord o{};
    bool have_o = observations->Next(&o);
    auto track_entries = entries.Read();
    EntryRecord e{};
    bool have_e = track_entries->Next(&e);
    ViewHead v;
    std::unordered_map<uint64_t, Vec3> seen;
    std::string s;
    for (int64_t i = 0; ReadViewHead(&views, &v); ++i) {
      const uint64_t view = static_cast<uint64_t>(i);
      const Intrinsics& k = full_[v.f.full];
      ColmapModel::Image im;
      im.id = ids_fit_ ? static_cast<uint32_t>(v.f.id) : static_cast<uint32_t>(i + 1);
      im.qvec = RotationToQuaternion(v.f.rotation);
      const Vec3 rc = Mul(v.f.rotation, v.f.center);
      im.tvec = {-rc[0], -rc[1], -rc[2]};
      im.camera_id = static_cast<uint32_t>(colmap_of_full_[v.f.full] + 1);
      im.name = v.name;
      // Its camera, to project the points, and the shift from its pixels to COLMAP's.
      CameraGeometry g;
      g.intrinsics = k, g.has_intrinsics = true;
      SetFromCenter(v.f.rotation, v.f.center, &g);
      const double shift = ColmapModelId(k.source_model) < 0 ? 0.5 : 0.0;
      // The estimate of each point when the view first observed it.
      seen.clear();
      for (; have_o && o.view == view; have_o = observations->Next(&o)) seen.emplace(o.point, o.x);
      s.clear();
      AppendColmapImageHead(im, &s);
      uint32_t idx = 0;
      for (; have_e && e.view == view; have_e = track_entries->Next(&e), ++idx) {
        // The 2D point: the input's keypoint, else where the estimate this view saw projects.
        std::array<double, 2> xy{};
        bool measured = source_ && source_->Keypoint(v.f.id, e.point, &xy);
        if (!measured) {
          auto it = seen.find(e.point);
          measured = it != seen.end() && Project(g, it->second, &xy[0], &xy[1]);
        }
        double u = 0.0, w = 0.0;
        const bool projects = Project(g, e.position, &u, &w);
        TrackRecord t{e.point, e.j, im.id, idx, 0, 0.0, e.position};
        if (measured && projects) {
          t.has_error = 1;
          t.error = std::hypot(xy[0] - u, xy[1] - w);
        } else if (!measured) {
          xy = projects ? std::array<double, 2>{u, w} : std::array<double, 2>{-shift, -shift};
        }
        AppendColmapPoint2D({xy[0] + shift, xy[1] + shift, static_cast<int64_t>(e.point)}, idx == 0, &s);
        tracks.Add(t);
        if (s.size() >= SpoolWriter::kBufferBytes) out.Write(s), s.clear();
      }
      s += "\n";
      out.Write(s);
    }
    out.Close();
  }
  entries.Release();

  SpoolWriter out(dir / "points3D.txt", /*sync=*/true);
  out.Write(ColmapPointsHeader(points, tracks.size()));
  auto reader = tracks.Read();
  TrackRecord t{};
  bool have = reader->Next(&t);
  std::string s;
  while (have) {
    ColmapModel::Point3D p;
    p.id = t.point;
    p.xyz = t.position;
    // COLMAP's mean reprojection error of the point, summed in its cameras' order; -1
    // (COLMAP's "not computed") when no track entry has both a 2D point and a projection.
    double error_sum = 0.0;
    int errors = 0;
    for (; have && t.point == p.id; have = reader->Next(&t)) {
      if (t.has_error) error_sum += t.error, ++errors;
      p.track.push_back({t.image_id, t.point2d_idx});
    }
    p.error = errors > 0 ? error_sum / errors : -1.0;
    s.clear();
    AppendColmapPoint3D(p, &s);
    out.Write(s);
  }
  out.Close();
}

int64_t StreamRecorder::HeldBytes() const {
  // A hash node: the value, the next pointer and the cached hash.
  const std::size_t node = sizeof(std::pair<const uint64_t, PointState>) + 2 * sizeof(void*);
  std::size_t bytes = points_.bucket_count() * sizeof(void*) + points_.size() * node;
  for (const auto& [id, s] : points_) bytes += s.cameras.capacity() * sizeof(uint64_t);
  bytes += observations_->HeldBytes() + 3 * SpoolWriter::kBufferBytes;
  bytes += view_index_.runs() * 64;
  for (const auto* list : {&full_, &slam_intrinsics_, &colmap_intrinsics_})
    for (const Intrinsics& k : *list)
      bytes += sizeof(Intrinsics) + k.source_params.capacity() * sizeof(double) + k.source_model.capacity();
  bytes += colmap_cameras_.size() * (sizeof(ColmapModel::Camera) + 16 * sizeof(double));
  return static_cast<int64_t>(bytes);
}

StreamRecorder::Stats StreamRecorder::stats() const {
  Stats s = stats_;
  s.views = views_;
  s.evict_after_keyframes = evict_after_;
  return s;
}

}  // namespace imr::io
