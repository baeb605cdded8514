#include "host/io/slam_json.h"

#include "host/io/json_fields.h"
#include "host/io/json_stream.h"
#include "host/io/openmvg_reader.h"
#include "host/io/update_check.h"
#include "host/io/schema.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>

namespace imr::io {
using nlohmann::json;

SlamJsonOptions SlamJsonOptionsFromJson(const json& o) {
  SlamJsonOptions s;
  s.min_views = o.at("min_views");
  s.min_move = o.at("min_move");
  s.views_per_keyframe = o.at("views_per_keyframe");
  return s;
}

json SlamJsonOptionsSchema() {
  const SlamJsonOptions d;
  return {
      {"min_views", {{"type", "integer"}, {"default", d.min_views}, {"minimum", 0},
                     {"description", "a point enters once this many views have seen it; 0: 2, "
                                     "or what an imr-exported stream says (1)"}}},
      {"min_move", {{"type", "number"}, {"default", d.min_move}, {"minimum", 0.0},
                    {"description", "a later X closer than this (scene units) to the point's "
                                    "estimate is not a move"}}},
      {"views_per_keyframe", {{"type", "integer"}, {"default", d.views_per_keyframe},
                              {"minimum", 1},
                              {"description", "views per keyframe when the views carry no "
                                              "\"keyframe\" numbers"}}}};
}

namespace {

constexpr int64_t kNone = std::numeric_limits<int64_t>::min();

// Frees a container's memory: `v = {}` picks the initializer_list assignment, which empties a
// vector but keeps its capacity.
template <class T>
void Release(T* v) {
  T().swap(*v);
}

std::string Coordinates(const Vec3& x) {
  char b[96];
  std::snprintf(b, sizeof(b), "%.9g, %.9g, %.9g", x[0], x[1], x[2]);
  return b;
}

// Reads the file in passes, so that what it holds does not follow the file's size (issue 46):
//  1. a SAX pass (json_stream.h) reads and checks the views one at a time and keeps, per view,
//     its camera and where its text lies in the file, and per point only the last keyframe that
//     names it (then, per keyframe, the points last used there: 8 bytes a point);
//  2. at open still, a dry run builds every update from the views read again one at a time and
//     drops it, so that bad input fails before the run (removed points, observations after a
//     removal, keyframes out of order); a point's state lives from its first observation to its
//     last use;
//  3. the live run builds each update the same way when it is asked for.
// What a pass holds at a time: the observations of one keyframe's views, those an imr stream
// delivers later than their view's keyframe until then, and the points being tracked.
class SlamJsonSource : public KeyframeSource {
 public:
  SlamJsonSource(const std::filesystem::path& file, const SlamJsonOptions& o)
      : file_(file), f_(file.string()), opt_(o) {
    const std::set<std::string> keys = StreamJsonFile(
        file, {"views", "intrinsics"},
        [&](const std::string& key, json&& v) { Member(key, v); },
        [&](const std::string& key, std::size_t i, json&& e, int64_t begin, int64_t end) {
          if (key == "views") View(i, e, begin, end);
          else Intrinsic(i, e);
        });
    if (!keys.count("views")) f_.Fail("(top level)", "missing field \"views\"");
    if (!keys.count("slam_data_version")) f_.Fail("(top level)", "missing field \"slam_data_version\"");
    Build();
  }

  bool Next(engine::KeyframeUpdate* u, KeyframeInfo* info) override {
    if (next_ >= list_.numbers.size()) return false;
    *u = engine::KeyframeUpdate{};
    DeliverKeyframe(next_, &live_, u);
    Release(&erase_at_[next_]);
    Release(&list_.removed[next_]);
    *info = {static_cast<int>(next_), list_.frames[next_]};
    ++next_;
    u->last = next_ == list_.numbers.size();
    if (u->last) live_ = Delivery{};  // the file closed, nothing pending
    return true;
  }
  int KeyframeCount() const override { return static_cast<int>(list_.numbers.size()); }

  // What the reader still holds for the keyframes not handed out yet: the observations read
  // ahead of their keyframe (an imr stream's later ones), the points' states, their release
  // schedule and the keyframes' removals (not the views' cameras, kept for Camera()). At open:
  // the schedule and the removals, 8 bytes a point and a removal, none per observation.
  int64_t PendingBytes() const override {
    int64_t b = 0;
    for (const auto& [k, obs] : live_.ahead) b += static_cast<int64_t>(obs.capacity() * sizeof(Obs));
    for (const auto& [id, p] : live_.points)
      b += static_cast<int64_t>(sizeof(id) + sizeof(p) + p.cameras.capacity() * sizeof(uint64_t));
    for (std::size_t k = 0; k < erase_at_.size(); ++k)
      b += static_cast<int64_t>((erase_at_[k].capacity() + list_.removed[k].capacity()) * sizeof(uint64_t));
    return b;
  }

  const CameraGeometry* Camera(uint64_t id) const override {
    auto it = view_by_id_.find(id);
    return it == view_by_id_.end() ? nullptr : &views_[it->second].geometry;
  }
  json Summary() const override { return summary_; }

 private:
  struct ViewRec {
    CameraGeometry geometry;
    int64_t keyframe = kNone;
    uint64_t intrinsic = 0;
    bool has_intrinsic = false;
    int width = 0, height = 0;  // the view's own image size (imr's writer and others put it here)
    int64_t begin = 0, end = 0;  // its text in the file
  };
  struct Obs {
    uint64_t point;
    Vec3 x;
    int64_t keyframe;  // delivery keyframe, kNone: the view's
    uint32_t view;
    uint32_t index;  // within the view, for messages
  };

  // A view's path in the file, for messages.
  static std::string ViewPath(std::size_t i) { return "views[" + std::to_string(i) + "]"; }

  void Member(const std::string& key, const json& v) {
    if (key == "slam_data_version") {
      const std::string ver = f_.String(v, key);
      if (ver != "0.3" && ver != "0.2")
        f_.Fail(key, "expected \"0.3\" (or \"0.2\"), got " + Describe(v));
    } else if (key == "imr_stream") {
      imr_stream_ = v;
    } else if (key == "views" || key == "intrinsics") {
      f_.Fail(key, "expected an array, got " + Describe(v));
    }
  }

  void Intrinsic(std::size_t i, const json& e) {
    const std::string path = "intrinsics[" + std::to_string(i) + "]";
    uint64_t id = i;
    if (const json* k = f_.Optional(e, "intrinsicId", path)) id = f_.Id(*k, path + ".intrinsicId");
    else if (const json* k2 = f_.Optional(e, "key", path)) id = f_.Id(*k2, path + ".key");
    const json& value = f_.Member(e, "value", path);
    std::string name = "pinhole";
    if (const json* n = f_.Optional(value, "polymorphic_name", path + ".value"))
      name = f_.String(*n, path + ".value.polymorphic_name");
    const json& w = f_.Member(value, "ptr_wrapper", path + ".value");
    const json& d = f_.Member(w, "data", path + ".value.ptr_wrapper");
    if (!intrinsics_.emplace(id, OpenMvgIntrinsicFromData(f_, name, d, path + ".value.ptr_wrapper.data")).second)
      f_.Fail(path, "intrinsic " + std::to_string(id) + " is listed twice");
  }

  // Pass 1: the view's camera and place, its observations checked, each point's last keyframe.
  void View(std::size_t i, const json& v, int64_t begin, int64_t end) {
    const std::string path = ViewPath(i);
    ViewRec r;
    r.begin = begin, r.end = end;
    CameraGeometry& g = r.geometry;
    g.id = f_.Id(f_.Member(v, "viewId", path), path + ".viewId");
    if (!view_by_id_.emplace(g.id, views_.size()).second)
      f_.Fail(path + ".viewId", "view " + std::to_string(g.id) +
                                    " is listed twice (viewIds must be unique)");
    if (const json* n = f_.Optional(v, "filename", path)) g.name = f_.String(*n, path + ".filename");
    if (const json* k = f_.Optional(v, "id_intrinsic", path)) {
      r.intrinsic = f_.Id(*k, path + ".id_intrinsic");
      r.has_intrinsic = true;
    }
    if (const json* w = f_.Optional(v, "width", path))
      r.width = static_cast<int>(std::clamp<int64_t>(f_.Integer(*w, path + ".width"), 0, 1 << 20));
    if (const json* h = f_.Optional(v, "height", path))
      r.height = static_cast<int>(std::clamp<int64_t>(f_.Integer(*h, path + ".height"), 0, 1 << 20));
    if (const json* k = f_.Optional(v, "keyframe", path)) {
      r.keyframe = f_.Integer(*k, path + ".keyframe");
      if (r.keyframe < 0) f_.Fail(path + ".keyframe", "expected an integer >= 0");
    }
    const json& ex = f_.Member(v, "extrinsic", path);
    const Mat3 rot = f_.Rotation(f_.Member(ex, "rotation", path + ".extrinsic"), path + ".extrinsic.rotation");
    SetFromCenter(rot, f_.Vector3(f_.Member(ex, "center", path + ".extrinsic"), path + ".extrinsic.center"), &g);
    const int64_t vk = r.keyframe != kNone ? r.keyframe : static_cast<int64_t>(i) / std::max(1, opt_.views_per_keyframe);
    views_.push_back(std::move(r));
    Observations(views_.size() - 1, v, [&](const Obs& o) {
      const int64_t at = o.keyframe != kNone ? o.keyframe : vk;
      auto [it, first] = last_number_.try_emplace(o.point, at);
      if (!first) it->second = std::max(it->second, at);
    });
  }

  // The observations of view `vi` (its JSON `v`), checked, each handed to `fn` in file order with
  // its delivery keyframe (kNone: the view's).
  // A view sees a point once at a keyframe (imr's streams list it again at a later keyframe with
  // the later estimate): the same pointId twice at one keyframe with two positions is a
  // contradiction (the same position twice is read as once).
  template <class Fn>
  void Observations(std::size_t vi, const json& v, Fn&& fn) const {
    const std::string path = ViewPath(vi);
    const json& obs = f_.Member(v, "observations", path);
    if (!obs.is_array()) f_.Fail(path + ".observations", "expected an array, got " + Describe(obs));
    std::map<std::pair<uint64_t, int64_t>, std::pair<Vec3, uint32_t>> seen;
    for (std::size_t j = 0; j < obs.size(); ++j) {
      const std::string op = path + ".observations[" + std::to_string(j) + "]";
      Obs o;
      o.point = f_.Id(f_.Member(obs[j], "pointId", op), op + ".pointId");
      o.x = f_.Vector3(f_.Member(obs[j], "X", op), op + ".X");
      o.keyframe = kNone;
      if (const json* k = f_.Optional(obs[j], "keyframe", op)) o.keyframe = f_.Integer(*k, op + ".keyframe");
      o.view = static_cast<uint32_t>(vi);
      o.index = static_cast<uint32_t>(j);
      const auto [it, first] = seen.try_emplace({o.point, o.keyframe}, o.x, o.index);
      if (!first) {
        const Vec3& before = it->second.first;
        if (before != o.x)
          f_.Fail(op + ".pointId",
                  "point " + std::to_string(o.point) + " is listed twice in view " +
                      std::to_string(views_[vi].geometry.id) + " with two positions (observations[" +
                      std::to_string(it->second.second) + "].X [" + Coordinates(before) +
                      "], here [" + Coordinates(o.x) +
                      "]): a view sees a point once (at a keyframe)");
        continue;
      }
      fn(o);
    }
  }

  std::string ObsPath(const Obs& o) const {
    return ViewPath(o.view) + ".observations[" + std::to_string(o.index) + "]";
  }

  void Build() {
    ResolveIntrinsics();
    NumberViewKeyframes();
    list_ = ListKeyframes();
    const bool has_imr_stream = !imr_stream_.is_null();
    imr_stream_ = nullptr;  // its keyframes are in list_ now
    for (std::size_t i = 0; i < list_.numbers.size(); ++i) slot_[list_.numbers[i]] = i;
    for (std::size_t i = 0; i < views_.size(); ++i)
      if (!slot_.count(views_[i].keyframe))
        f_.Fail(ViewPath(i) + ".keyframe", "keyframe " + std::to_string(views_[i].keyframe) +
                                               " is not in imr_stream.keyframes");
    // Each point leaves the reader's memory after the last keyframe that observes or removes it.
    for (std::size_t k = 0; k < list_.numbers.size(); ++k)
      for (uint64_t id : list_.removed[k]) {
        auto [it, first] = last_number_.try_emplace(id, list_.numbers[k]);
        if (!first) it->second = std::max(it->second, list_.numbers[k]);
      }
    const std::size_t points = last_number_.size();
    erase_at_.assign(list_.numbers.size(), {});
    for (const auto& [id, number] : last_number_) {
      // A keyframe no list names fails in the dry run (a late observation's): keep it to the end.
      auto s = slot_.upper_bound(number);
      erase_at_[s == slot_.begin() ? 0 : std::prev(s)->second].push_back(id);
    }
    Release(&last_number_);
    for (auto& ids : erase_at_) ids.shrink_to_fit();
    // The dry run: every update built and dropped, so that bad input fails here.
    Delivery d;
    engine::KeyframeUpdate scratch;
    for (std::size_t k = 0; k < list_.numbers.size(); ++k) {
      scratch = engine::KeyframeUpdate{};
      DeliverKeyframe(k, &d, &scratch);
    }
    summary_ = {{"file", f_.file()},
                {"views", views_.size()},
                {"observations", d.observations},
                {"points", points},
                {"points_never_entered", d.never_entered},
                {"moves", d.moves},
                {"min_views", list_.min_views},
                {"keyframes", list_.numbers.size()},
                {"imr_stream", has_imr_stream}};
  }

  // The keyframes: numbers, the frame each ends at, the points each removes.
  struct KeyframeList {
    std::vector<int64_t> numbers;
    std::vector<int> frames;
    std::vector<std::vector<uint64_t>> removed;
    int min_views = 0;
  };

  // A point as the stream has delivered it so far.
  struct PointState {
    bool entered = false, removed = false;
    Vec3 position{};
    std::vector<uint64_t> cameras;
  };

  // Where a pass over the keyframes stands: the next view, the observations read ahead of their
  // keyframe (by keyframe number, in file order), the points between their first observation and
  // their last use, the counts.
  struct Delivery {
    std::size_t vi = 0;
    std::map<int64_t, std::vector<Obs>> ahead;
    std::unordered_map<uint64_t, PointState> points;
    std::unique_ptr<InputStream> in;  // the file, opened at the first view read
    std::string text;                 // a view's text
    int64_t moves = 0, observations = 0, never_entered = 0;
  };

  // Intrinsics of the views.
  void ResolveIntrinsics() {
    for (std::size_t i = 0; i < views_.size(); ++i) {
      ViewRec& v = views_[i];
      if (!v.has_intrinsic) continue;
      auto it = intrinsics_.find(v.intrinsic);
      if (it == intrinsics_.end())
        f_.Fail(ViewPath(i) + ".id_intrinsic", "view " + std::to_string(v.geometry.id) + " uses intrinsic " +
                                                   std::to_string(v.intrinsic) + ", which intrinsics does not list");
      v.geometry.intrinsics = it->second;
      v.geometry.has_intrinsics = true;
      // An intrinsic without an image size takes the view's (SLAM JSON puts it in either place).
      if (v.geometry.intrinsics.width <= 0 && v.width > 0) v.geometry.intrinsics.width = v.width;
      if (v.geometry.intrinsics.height <= 0 && v.height > 0) v.geometry.intrinsics.height = v.height;
    }
  }

  // Keyframe of each view: its own number, or views_per_keyframe consecutive views.
  void NumberViewKeyframes() {
    const bool numbered = !views_.empty() && views_[0].keyframe != kNone;
    for (std::size_t i = 0; i < views_.size(); ++i) {
      ViewRec& v = views_[i];
      if ((v.keyframe != kNone) != numbered)
        f_.Fail(ViewPath(i), numbered ? "missing field \"keyframe\" (the first view has one: all need one)"
                                      : "has a \"keyframe\" but the first view has none (all or none)");
      if (!numbered) v.keyframe = static_cast<int64_t>(i) / opt_.views_per_keyframe;
      if (i > 0 && v.keyframe < views_[i - 1].keyframe)
        f_.Fail(ViewPath(i) + ".keyframe", "keyframe " + std::to_string(v.keyframe) +
                                               " comes after keyframe " + std::to_string(views_[i - 1].keyframe) +
                                               " (views must be in keyframe order)");
    }
  }

  // The keyframes: imr_stream's list (every update, removals), else those of the views.
  KeyframeList ListKeyframes() {
    KeyframeList list;
    list.min_views = opt_.min_views;
    if (!imr_stream_.is_null()) {
      const json* mv = f_.Optional(imr_stream_, "min_views", "imr_stream");
      if (mv != nullptr && list.min_views == 0) list.min_views = static_cast<int>(f_.Integer(*mv, "imr_stream.min_views"));
      const json& ks = f_.Member(imr_stream_, "keyframes", "imr_stream");
      if (!ks.is_array()) f_.Fail("imr_stream.keyframes", "expected an array");
      for (std::size_t i = 0; i < ks.size(); ++i) {
        const std::string p = "imr_stream.keyframes[" + std::to_string(i) + "]";
        list.numbers.push_back(f_.Integer(f_.Member(ks[i], "keyframe", p), p + ".keyframe"));
        if (i > 0 && list.numbers[i] <= list.numbers[i - 1]) f_.Fail(p + ".keyframe", "keyframes must increase");
        list.frames.push_back(static_cast<int>(f_.Integer(f_.Member(ks[i], "frame", p), p + ".frame")));
        list.removed.emplace_back();
        if (const json* r = f_.Optional(ks[i], "removed_points", p)) {
          if (!r->is_array()) f_.Fail(p + ".removed_points", "expected an array of point ids");
          for (std::size_t j = 0; j < r->size(); ++j)
            list.removed.back().push_back(f_.Id((*r)[j], p + ".removed_points[" + std::to_string(j) + "]"));
        }
      }
    } else {
      for (std::size_t i = 0; i < views_.size(); ++i) {
        if (list.numbers.empty() || list.numbers.back() != views_[i].keyframe) {
          list.numbers.push_back(views_[i].keyframe);
          list.frames.push_back(0);
          list.removed.emplace_back();
        }
        list.frames.back() = static_cast<int>(i);
      }
    }
    if (list.min_views <= 0) list.min_views = 2;
    return list;
  }


  // The text of view `vi`, read again (pass 1 checked it: a difference now means the file
  // changed while it was read).
  json ReadView(std::size_t vi, Delivery* d) const {
    const ViewRec& v = views_[vi];
    if (!d->in) d->in = std::make_unique<InputStream>(file_, "a JSON file");
    d->text.resize(static_cast<std::size_t>(v.end - v.begin));
    d->in->seekg(v.begin);
    d->in->read(d->text.data(), static_cast<std::streamsize>(d->text.size()));
    json j = json::parse(d->text, nullptr, /*allow_exceptions=*/false);
    if (!d->in->good() || v.begin < 0 || !j.is_object())
      f_.Fail(ViewPath(vi), "changed while it was read (read again at its keyframe, it is no longer "
                            "the view read at open): do not write the file while imr reads it");
    return j;
  }

  // Keyframe k's update: its cameras, its removals, and its observations as new points (seen by
  // min_views cameras) and moved ones. Its observations in the file's order: the later ones of
  // earlier views first (their views come before this keyframe's), then those of its own views.
  void DeliverKeyframe(std::size_t k, Delivery* d, engine::KeyframeUpdate* out) {
    const KeyframeList& list = list_;
    std::unordered_map<uint64_t, PointState>& points = d->points;
    engine::KeyframeUpdate& u = *out;
    const int64_t number = list.numbers[k];
    std::vector<Obs> now;
    if (auto it = d->ahead.find(number); it != d->ahead.end()) {
      now = std::move(it->second);
      d->ahead.erase(it);
    }
    for (; d->vi < views_.size() && views_[d->vi].keyframe == number; ++d->vi) {
      const std::size_t vi = d->vi;
      u.cameras.push_back({views_[vi].geometry.id, views_[vi].geometry.center});
      const json v = ReadView(vi, d);
      Observations(vi, v, [&](Obs o) {
        if (o.keyframe == kNone || o.keyframe == number) {
          o.keyframe = kNone;
          now.push_back(o);
          return;
        }
        if (o.keyframe < number)
          f_.Fail(ObsPath(o) + ".keyframe", "keyframe " + std::to_string(o.keyframe) +
                                                " is before its view's keyframe " + std::to_string(number));
        if (!slot_.count(o.keyframe))
          f_.Fail(ObsPath(o) + ".keyframe", "keyframe " + std::to_string(o.keyframe) +
                                                " is not in imr_stream.keyframes");
        d->ahead[o.keyframe].push_back(o);
      });
    }
    for (uint64_t id : list.removed[k]) {
      auto it = points.find(id);
      if (it == points.end() || !it->second.entered || it->second.removed)
        f_.Fail("imr_stream.keyframes[" + std::to_string(k) + "].removed_points",
                PointNotInStream(id, number));
      it->second.removed = true;
    }
    u.removed_points = list.removed[k];
    std::vector<uint64_t> touched;
    struct Move {
      engine::MovedPoint m;
      Vec3 before;  // the estimate the engine has
    };
    std::unordered_map<uint64_t, Move> moved;
    for (const Obs& o : now) {
      ++d->observations;
      PointState& s = points[o.point];
      if (s.removed)
        f_.Fail(ObsPath(o), ObservedAfterRemoval(o.point));
      const uint64_t cam = views_[o.view].geometry.id;
      const bool new_cam = std::find(s.cameras.begin(), s.cameras.end(), cam) == s.cameras.end();
      if (new_cam) s.cameras.push_back(cam);
      if (!s.entered) {
        s.position = o.x;
        touched.push_back(o.point);
        continue;
      }
      auto [it, first] = moved.try_emplace(o.point, Move{{o.point, s.position, {}}, s.position});
      if (first) touched.push_back(o.point);
      if (new_cam) it->second.m.camera_ids.push_back(cam);
      const double dist = std::hypot(o.x[0] - s.position[0], o.x[1] - s.position[1], o.x[2] - s.position[2]);
      if (o.x != s.position && dist > opt_.min_move) {
        s.position = o.x;
        it->second.m.position = o.x;
      }
    }
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    for (uint64_t id : touched) {
      PointState& s = points[id];
      auto m = moved.find(id);
      if (m != moved.end()) {
        const bool move = m->second.m.position != m->second.before;
        if (move) ++d->moves;
        if (move || !m->second.m.camera_ids.empty()) u.moved_points.push_back(std::move(m->second.m));
      } else if (!s.entered && static_cast<int>(s.cameras.size()) >= list.min_views) {
        s.entered = true;
        u.new_points.push_back({id, s.position, s.cameras});
      }
    }
    // The points whose last use this was.
    for (uint64_t id : erase_at_[k]) {
      auto it = points.find(id);
      if (it == points.end()) continue;
      d->never_entered += it->second.entered ? 0 : 1;
      points.erase(it);
    }
  }

  std::filesystem::path file_;
  JsonFields f_;
  SlamJsonOptions opt_;

  json imr_stream_;
  std::map<uint64_t, Intrinsics> intrinsics_;
  std::vector<ViewRec> views_;
  std::unordered_map<uint64_t, std::size_t> view_by_id_;
  std::unordered_map<uint64_t, int64_t> last_number_;  // pass 1: point -> last keyframe number
  KeyframeList list_;
  std::map<int64_t, std::size_t> slot_;           // keyframe number -> index
  std::vector<std::vector<uint64_t>> erase_at_;   // per keyframe: points last used there
  Delivery live_;
  std::size_t next_ = 0;
  json summary_;
};

}  // namespace

std::unique_ptr<KeyframeSource> OpenSlamJson(const std::filesystem::path& file, const SlamJsonOptions& options) {
  return std::make_unique<SlamJsonSource>(file, options);
}

// -----------------------------------------------------------------------------------------------

uint64_t CanonicalOrder::Rank(uint64_t id) const {
  auto next = runs_.upper_bound(id);
  if (next == runs_.begin()) return UINT64_MAX;
  const auto& [first, run] = *std::prev(next);
  return id <= run.last_id ? run.first_rank + (id - first) : UINT64_MAX;
}

void CanonicalOrder::Arrive(uint64_t id) {
  if (Rank(id) != UINT64_MAX) return;  // its first arrival counts
  const uint64_t rank = arrived_++;
  auto next = runs_.upper_bound(id);
  if (next != runs_.begin()) {
    auto& [first, run] = *std::prev(next);
    if (run.last_id + 1 == id && run.first_rank + (id - first) == rank) {  // the next in order
      run.last_id = id;
      return;
    }
  }
  runs_.emplace(id, Run{id, rank});
}

void CanonicalOrder::Apply(engine::KeyframeUpdate* u) {
  for (const engine::Camera& c : u->cameras) Arrive(c.id);
  auto order = [&](std::vector<uint64_t>* ids) {
    std::vector<uint64_t> out;
    for (uint64_t id : *ids)
      if (std::find(out.begin(), out.end(), id) == out.end()) out.push_back(id);
    std::stable_sort(out.begin(), out.end(),
                     [&](uint64_t a, uint64_t b) { return Rank(a) < Rank(b); });
    *ids = std::move(out);
  };
  for (auto& p : u->new_points) order(&p.camera_ids);
  for (auto& p : u->moved_points) order(&p.camera_ids);
  auto by_id = [](const auto& a, const auto& b) { return a.id < b.id; };
  std::stable_sort(u->new_points.begin(), u->new_points.end(), by_id);
  std::stable_sort(u->moved_points.begin(), u->moved_points.end(), by_id);
  std::sort(u->removed_points.begin(), u->removed_points.end());
}

}  // namespace imr::io
