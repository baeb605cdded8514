// `import imr`: the engine fed from Python, the readers as keyframe streams, jobs and
// `imr evaluate` (docs/python.md). The work is session.cc's; this file turns Python values into
// updates and options, results into numpy arrays and dicts, C++ errors into Python's, and keeps
// long calls off the GIL and stoppable with Ctrl-C.
#include "host/python/session.h"

#include "host/plugin/host_services.h"
#include "host/pipeline/run.h"
#include "host/util/log.h"
#include "host/util/write_rule.h"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <condition_variable>
#include <csignal>
#include <functional>
#include <mutex>
#include <thread>

namespace py = pybind11;
using nlohmann::json;

namespace imr::python {
namespace {

// --- JSON <-> Python ---

py::object ToPython(const json& j) {
  switch (j.type()) {
    case json::value_t::null: return py::none();
    case json::value_t::boolean: return py::bool_(j.get<bool>());
    case json::value_t::number_integer: return py::int_(j.get<int64_t>());
    case json::value_t::number_unsigned: return py::int_(j.get<uint64_t>());
    case json::value_t::number_float: return py::float_(j.get<double>());
    case json::value_t::string: return py::str(j.get<std::string>());
    case json::value_t::array: {
      py::list l;
      for (const json& x : j) l.append(ToPython(x));
      return l;
    }
    case json::value_t::object: {
      py::dict d;
      for (const auto& [k, v] : j.items()) d[py::str(k)] = ToPython(v);
      return d;
    }
    default: return py::none();
  }
}

// `what` names the value in the error (an option's name).
json ToJson(const py::handle& o, const std::string& what) {
  if (o.is_none()) return nullptr;
  if (py::isinstance<py::bool_>(o)) return o.cast<bool>();
  if (py::isinstance<py::int_>(o)) return o.cast<int64_t>();
  if (py::isinstance<py::float_>(o)) return o.cast<double>();
  if (py::isinstance<py::str>(o)) return o.cast<std::string>();
  if (py::hasattr(o, "dtype") && py::hasattr(o, "item") && py::len(o.attr("shape")) == 0)
    return ToJson(o.attr("item")(), what);  // a numpy scalar
  if (py::isinstance<py::dict>(o)) {
    json j = json::object();
    for (const auto& [k, v] : o.cast<py::dict>()) j[py::str(k).cast<std::string>()] = ToJson(v, what);
    return j;
  }
  if (py::isinstance<py::sequence>(o) || py::isinstance<py::array>(o)) {
    json j = json::array();
    for (const auto& x : o) j.push_back(ToJson(x, what));
    return j;
  }
  throw OptionError(what + ": cannot be given as " + py::str(py::type::of(o)).cast<std::string>());
}

json KwargsToJson(const py::kwargs& kwargs) {
  json j = json::object();
  for (const auto& [k, v] : kwargs) {
    const std::string key = py::str(k).cast<std::string>();
    j[key] = ToJson(v, key);
  }
  return j;
}

// --- Long calls ---

// Runs `work` on a thread of its own with the GIL released; the calling thread checks Python's
// signals every 50 ms (so Ctrl-C in a notebook or a terminal reaches Python's handler), and when
// a handler raises (KeyboardInterrupt) asks the host to cancel (the job runner and the engine
// poll it), waits for `work` to stop and raises that exception. Nothing is left half-written:
// the runner's outputs are staged and removed when it stops.
void Interruptible(const std::function<void()>& work) {
  plugin::ClearCancel();
  std::exception_ptr error;
  std::mutex mutex;
  std::condition_variable cv;
  bool done = false, interrupted = false;
  {
    py::gil_scoped_release release;
    std::thread worker([&] {
      try {
        work();
      } catch (...) {
        error = std::current_exception();
      }
      std::lock_guard lock(mutex);
      done = true;
      cv.notify_all();
    });
    std::unique_lock lock(mutex);
    while (!done) {
      cv.wait_for(lock, std::chrono::milliseconds(50));
      if (done || interrupted) continue;
      lock.unlock();
      {
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {
          interrupted = true;
          plugin::RequestCancel(SIGINT);
        }
      }
      lock.lock();
    }
    lock.unlock();
    worker.join();
  }
  plugin::ClearCancel();
  if (interrupted) throw py::error_already_set();
  if (error) std::rethrow_exception(error);
}

// --- Arrays ---

// An integer id array (any integer dtype, no negative values) of `what`.
std::vector<uint64_t> Ids(const py::handle& o, const char* what) {
  if (o.is_none()) return {};
  py::array a = py::array::ensure(o);
  if (!a) throw OptionError(std::string(what) + ": expected an array of integer ids");
  if (a.size() == 0) return {};
  if (a.ndim() != 1)
    throw OptionError(std::string(what) + ": expected a 1-D array of ids, got " +
                      std::to_string(a.ndim()) + " dimensions");
  const char kind = a.dtype().kind();
  if (kind != 'i' && kind != 'u')
    throw OptionError(std::string(what) + ": expected integer ids, got dtype " +
                      py::str(a.dtype()).cast<std::string>());
  if (kind == 'i') {
    auto s = a.cast<py::array_t<int64_t, py::array::c_style | py::array::forcecast>>();
    std::vector<uint64_t> out(static_cast<std::size_t>(s.size()));
    for (py::ssize_t i = 0; i < s.size(); ++i) {
      if (s.data()[i] < 0)
        throw OptionError(std::string(what) + "[" + std::to_string(i) + "]: expected an id >= 0, got " +
                          std::to_string(s.data()[i]));
      out[static_cast<std::size_t>(i)] = static_cast<uint64_t>(s.data()[i]);
    }
    return out;
  }
  auto s = a.cast<py::array_t<uint64_t, py::array::c_style | py::array::forcecast>>();
  return {s.data(), s.data() + s.size()};
}

// An (n, 3) array of positions of `what`.
std::vector<Vec3> Positions(const py::handle& o, std::size_t n, const char* what, const char* ids) {
  if (o.is_none()) {
    if (n == 0) return {};
    throw OptionError(std::string(what) + ": needed with " + ids + " (" + std::to_string(n) + " ids)");
  }
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a) throw OptionError(std::string(what) + ": expected an (N, 3) array of numbers");
  if (a.size() == 0 && n == 0) return {};
  if (a.ndim() != 2 || a.shape(1) != 3 || static_cast<std::size_t>(a.shape(0)) != n) {
    std::string shape;
    for (py::ssize_t i = 0; i < a.ndim(); ++i) shape += (i ? ", " : "") + std::to_string(a.shape(i));
    throw OptionError(std::string(what) + ": expected shape (" + std::to_string(n) + ", 3) (one row per id of " +
                      ids + "), got (" + shape + ")");
  }
  std::vector<Vec3> out(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) out[i][k] = a.data()[3 * i + k];
  return out;
}

// Which cameras see each of n points: None (the keyframe's one camera), one id for all, an
// (n,) array (one camera each), an (n, k) array, or a list of n lists (any number each).
std::vector<std::vector<uint64_t>> Observers(const py::handle& o, std::size_t n, const char* what,
                                             const std::vector<engine::Camera>& cameras, bool optional) {
  std::vector<std::vector<uint64_t>> out(n);
  if (n == 0) return out;
  if (o.is_none()) {
    if (optional) return out;
    if (cameras.size() != 1)
      throw OptionError(std::string(what) + ": needed when the keyframe has " +
                        std::to_string(cameras.size()) + " cameras (which of them see each point?)");
    for (auto& v : out) v = {cameras[0].id};
    return out;
  }
  if (py::isinstance<py::int_>(o)) {
    for (auto& v : out) v = {o.cast<uint64_t>()};
    return out;
  }
  if (py::isinstance<py::array>(o)) {
    py::array a = o.cast<py::array>();
    if (a.ndim() == 1) {
      const std::vector<uint64_t> ids = Ids(a, what);
      if (ids.size() != n)
        throw OptionError(std::string(what) + ": expected " + std::to_string(n) + " camera ids (one per point), got " +
                          std::to_string(ids.size()));
      for (std::size_t i = 0; i < n; ++i) out[i] = {ids[i]};
      return out;
    }
    if (a.ndim() == 2 && static_cast<std::size_t>(a.shape(0)) == n) {
      const std::vector<uint64_t> ids = Ids(a.attr("reshape")(-1), what);
      const std::size_t k = static_cast<std::size_t>(a.shape(1));
      for (std::size_t i = 0; i < n; ++i) out[i].assign(ids.begin() + i * k, ids.begin() + (i + 1) * k);
      return out;
    }
    throw OptionError(std::string(what) + ": expected " + std::to_string(n) + " rows (one per point)");
  }
  const py::sequence s = py::reinterpret_borrow<py::sequence>(o);
  if (!py::isinstance<py::sequence>(o) || static_cast<std::size_t>(py::len(s)) != n)
    throw OptionError(std::string(what) + ": expected " + std::to_string(n) +
                      " entries (the cameras of each point)");
  for (std::size_t i = 0; i < n; ++i) {
    const py::object e = s[i];
    if (py::isinstance<py::int_>(e))
      out[i] = {e.cast<uint64_t>()};
    else
      out[i] = Ids(e, what);
  }
  return out;
}

std::array<double, 9> Rotation(const py::handle& o) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.size() != 9) throw OptionError("rotation: expected a 3x3 matrix (world -> camera, rows)");
  std::array<double, 9> r;
  std::copy(a.data(), a.data() + 9, r.begin());
  return r;
}

// An (N, 3) array of finite points of `what` ("truth"), for imr.evaluate.
std::vector<imr::Vec3> PointsFromArray(const py::handle& o, const std::string& what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 2 || a.shape(1) != 3) {
    std::string shape;
    if (a)
      for (py::ssize_t i = 0; i < a.ndim(); ++i) shape += (i ? ", " : "") + std::to_string(a.shape(i));
    throw OptionError(what + ": expected an (N, 3) array of numbers" + (a ? ", got shape (" + shape + ")" : ""));
  }
  std::vector<imr::Vec3> out(static_cast<std::size_t>(a.shape(0)));
  for (std::size_t i = 0; i < out.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      out[i][k] = a.data()[3 * i + k];
      if (!std::isfinite(out[i][k]))
        throw OptionError(what + "[" + std::to_string(i) + "]: expected finite numbers, got " +
                          std::to_string(out[i][k]));
    }
  return out;
}

// (vertices (V, 3), faces (F, 3) integer indices below V) as a mesh, for imr.evaluate.
imr::eval::TriangleMesh MeshFromArrays(const py::handle& vertices, const py::handle& faces) {
  imr::eval::TriangleMesh m;
  m.vertices = PointsFromArray(vertices, "mesh: vertices");
  py::array f = py::array::ensure(faces);
  if (!f || f.ndim() != 2 || f.shape(1) != 3 || (f.size() > 0 && f.dtype().kind() != 'i' && f.dtype().kind() != 'u'))
    throw OptionError("mesh: faces: expected integers of shape (F, 3)");
  auto fi = f.cast<py::array_t<int64_t, py::array::c_style | py::array::forcecast>>();
  m.triangles.resize(static_cast<std::size_t>(fi.shape(0)));
  for (std::size_t t = 0; t < m.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int64_t i = fi.data()[3 * t + k];
      if (i < 0 || static_cast<uint64_t>(i) >= m.vertices.size())
        throw OptionError("mesh: faces[" + std::to_string(t) + "]: vertex index " + std::to_string(i) +
                          " is out of range (" + std::to_string(m.vertices.size()) + " vertices)");
      m.triangles[t][k] = static_cast<uint32_t>(i);
    }
  return m;
}

// A mesh's arrays without a copy: the mesh moves into a capsule that both arrays keep alive.
py::tuple MeshArrays(engine::Mesh mesh, bool point_ids) {
  const auto nv = static_cast<py::ssize_t>(mesh.vertices.size() / 3);
  const auto nf = static_cast<py::ssize_t>(mesh.faces.size() / 3);
  auto* owned = new engine::Mesh(std::move(mesh));
  py::capsule owner(owned, [](void* p) { delete static_cast<engine::Mesh*>(p); });
  // Indices are below 2^31 (a mesh has far fewer vertices): the uint32 buffer read as int32.
  py::array_t<double> v({nv, py::ssize_t{3}}, {py::ssize_t{24}, py::ssize_t{8}},
                        nv ? owned->vertices.data() : nullptr, owner);
  py::array_t<int32_t> f({nf, py::ssize_t{3}}, {py::ssize_t{12}, py::ssize_t{4}},
                         nf ? reinterpret_cast<const int32_t*>(owned->faces.data()) : nullptr, owner);
  if (!point_ids) return py::make_tuple(v, f);
  py::array_t<int64_t> ids({nv}, {py::ssize_t{8}}, nv ? owned->point_ids.data() : nullptr, owner);
  return py::make_tuple(v, f, ids);
}

// --- The bound classes ---

// imr.Engine: a Session behind a mutex (its calls release the GIL, so two Python threads could
// otherwise enter it at once).
class PyEngine {
 public:
  PyEngine(const py::object& weight_policy, const py::object& weight_policy_params,
           const py::kwargs& options) {
    const std::string policy = weight_policy.is_none() ? "" : weight_policy.cast<std::string>();
    const json params = weight_policy_params.is_none() ? json::object()
                                                       : ToJson(weight_policy_params, "weight_policy_params");
    session_ = std::make_unique<Session>(KwargsToJson(options).dump(), policy, params.dump());
  }

  void AddKeyframe(Keyframe k) {
    py::gil_scoped_release release;
    std::lock_guard lock(mutex_);
    session_->Add(std::move(k));
  }

  py::tuple MeshNow(bool point_ids) {
    engine::Mesh m;
    {
      py::gil_scoped_release release;
      std::lock_guard lock(mutex_);
      m = session_->Mesh();
    }
    return MeshArrays(std::move(m), point_ids);
  }

  py::object Stats() {
    std::lock_guard lock(mutex_);
    return ToPython(session_->Stats());
  }
  py::object Options() {
    std::lock_guard lock(mutex_);
    return ToPython(session_->Options());
  }
  void Write(const py::object& file) {
    const std::string path = py::module_::import("os").attr("fspath")(file).cast<std::string>();
    py::gil_scoped_release release;
    std::lock_guard lock(mutex_);
    session_->Write(path);
  }
  int keyframes() {
    std::lock_guard lock(mutex_);
    return session_->keyframes();
  }

 private:
  std::mutex mutex_;
  std::unique_ptr<Session> session_;
};

Keyframe BuildKeyframe(const py::object& camera, const py::object& new_ids, const py::object& new_positions,
                       const py::object& new_cameras, const py::object& moved_ids,
                       const py::object& moved_positions, const py::object& moved_cameras,
                       const py::object& removed_ids) {
  Keyframe k;
  engine::KeyframeUpdate& u = k.update;
  if (py::isinstance<engine::Camera>(camera))
    u.cameras.push_back(camera.cast<engine::Camera>());
  else if (!camera.is_none())
    for (const auto& c : camera) u.cameras.push_back(c.cast<engine::Camera>());
  const std::vector<uint64_t> nid = Ids(new_ids, "new_ids");
  const std::vector<Vec3> npos = Positions(new_positions, nid.size(), "new_positions", "new_ids");
  const auto ncam = Observers(new_cameras, nid.size(), "new_cameras", u.cameras, false);
  for (std::size_t i = 0; i < nid.size(); ++i) u.new_points.push_back({nid[i], npos[i], ncam[i]});
  const std::vector<uint64_t> mid = Ids(moved_ids, "moved_ids");
  const std::vector<Vec3> mpos = Positions(moved_positions, mid.size(), "moved_positions", "moved_ids");
  const auto mcam = Observers(moved_cameras, mid.size(), "moved_cameras", u.cameras, true);
  for (std::size_t i = 0; i < mid.size(); ++i) u.moved_points.push_back({mid[i], mpos[i], mcam[i]});
  u.removed_points = Ids(removed_ids, "removed_ids");
  return k;
}

template <typename Points>
py::array_t<uint64_t> PointIds(const Points& points) {
  py::array_t<uint64_t> a(static_cast<py::ssize_t>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i) a.mutable_data()[i] = points[i].id;
  return a;
}
template <typename Points>
py::array_t<double> PointPositions(const Points& points) {
  py::array_t<double> a({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}});
  for (std::size_t i = 0; i < points.size(); ++i)
    for (int k = 0; k < 3; ++k) a.mutable_data()[3 * i + k] = points[i].position[k];
  return a;
}
template <typename Points>
py::list PointCameras(const Points& points) {
  py::list l;
  for (const auto& p : points) l.append(py::cast(p.camera_ids));
  return l;
}

// The reader behind imr.read_colmap, imr.read_slam_json, imr.read(format, ...): an iterator of
// Keyframe objects. Opening reads the whole model (a SLAM JSON stream: one pass), off the GIL.
class PyReader {
 public:
  PyReader(const std::string& format, const std::string& path, const py::dict& options) {
    const std::string o = ToJson(options, "options").dump();
    Interruptible([&] { reader_ = std::make_unique<Reader>(format, path, o); });
  }
  Keyframe Next() {
    std::optional<Keyframe> k;
    {
      py::gil_scoped_release release;
      k = reader_->Next();
    }
    if (!k) throw py::stop_iteration();
    return std::move(*k);
  }
  int Count() const { return reader_->KeyframeCount(); }

 private:
  std::unique_ptr<Reader> reader_;
};


// imr.Error, imr.SequenceError, imr.WriteRefused, and which C++ exception becomes which
// Python one.
void RegisterErrors(py::module_& m) {
  static py::exception<std::runtime_error> error(m, "Error", PyExc_RuntimeError);
  static py::exception<SequenceError> sequence_error(m, "SequenceError", error.ptr());
  // A write the write rule refused (host/util/write_rule.h): a PermissionError, as the OS's own.
  static py::exception<imr::WriteRefused> write_refused(m, "WriteRefused", PyExc_PermissionError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const py::builtin_exception&) {
      throw;  // pybind11's own (StopIteration, ...): its translator
    } catch (const OptionError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const SequenceError& e) {
      py::object ex = py::reinterpret_borrow<py::object>(sequence_error.ptr())(e.what());
      ex.attr("sequence") = e.sequence();
      PyErr_SetObject(sequence_error.ptr(), ex.ptr());
    } catch (const std::invalid_argument& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const imr::WriteRefused& e) {
      write_refused(e.what());
    } catch (const std::runtime_error& e) {
      error(e.what());
    }
  });
}

// imr.Camera.
void BindCamera(py::module_& m) {
  py::class_<engine::Camera>(m, "Camera",
                             "A camera: id, centre (world), rotation (world -> camera, 3x3 rows), "
                             "intrinsics (fx, fy, cx, cy; 0: unknown).")
      .def(py::init([](uint64_t id, const py::object& center, const py::object& rotation,
                       const py::object& intrinsics) {
             engine::Camera c;
             c.id = id;
             auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(center);
             if (!a || a.size() != 3) throw OptionError("center: expected 3 numbers");
             for (int k = 0; k < 3; ++k) c.center[k] = a.data()[k];
             if (!rotation.is_none()) c.rotation = Rotation(rotation);
             if (!intrinsics.is_none()) {
               auto i = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(intrinsics);
               if (!i || i.size() != 4) throw OptionError("intrinsics: expected (fx, fy, cx, cy)");
               std::copy(i.data(), i.data() + 4, c.intrinsics.begin());
             }
             // The readers' checks (a rotation, intrinsics unknown or positive, a centre in
             // bounds), here so that the line that made the camera is the one that fails.
             if (const std::string p = imr::io::CameraProblem(&c); !p.empty()) throw OptionError(p);
             return c;
           }),
           py::arg("id"), py::arg("center"), py::arg("rotation") = py::none(),
           py::arg("intrinsics") = py::none())
      .def_readwrite("id", &engine::Camera::id)
      .def_property_readonly("center", [](const engine::Camera& c) {
        return py::array_t<double>(3, c.center.data());
      })
      .def_property_readonly("rotation", [](const engine::Camera& c) {
        return py::array_t<double>({3, 3}, c.rotation.data());
      })
      .def_property_readonly("intrinsics", [](const engine::Camera& c) {
        return py::array_t<double>(4, c.intrinsics.data());
      })
      .def("__repr__", [](const engine::Camera& c) {
        return "imr.Camera(id=" + std::to_string(c.id) + ", center=(" + std::to_string(c.center[0]) +
               ", " + std::to_string(c.center[1]) + ", " + std::to_string(c.center[2]) + "))";
      });
}

// imr.Keyframe.
void BindKeyframe(py::module_& m) {
  py::class_<Keyframe>(m, "Keyframe",
                       "One engine update: its cameras, new, moved and removed points.")
      .def(py::init(&BuildKeyframe), py::arg("camera") = py::none(), py::arg("new_ids") = py::none(),
           py::arg("new_positions") = py::none(), py::arg("new_cameras") = py::none(),
           py::arg("moved_ids") = py::none(), py::arg("moved_positions") = py::none(),
           py::arg("moved_cameras") = py::none(), py::arg("removed_ids") = py::none())
      .def_property_readonly("index", [](const Keyframe& k) { return k.info.index; })
      .def_property_readonly("frame", [](const Keyframe& k) { return k.info.frame; })
      .def_property_readonly("format", [](const Keyframe& k) { return k.format; })
      .def_property_readonly("cameras", [](const Keyframe& k) { return k.update.cameras; })
      .def_property_readonly("new_ids", [](const Keyframe& k) { return PointIds(k.update.new_points); })
      .def_property_readonly("new_positions", [](const Keyframe& k) { return PointPositions(k.update.new_points); })
      .def_property_readonly("new_cameras", [](const Keyframe& k) { return PointCameras(k.update.new_points); })
      .def_property_readonly("moved_ids", [](const Keyframe& k) { return PointIds(k.update.moved_points); })
      .def_property_readonly("moved_positions", [](const Keyframe& k) { return PointPositions(k.update.moved_points); })
      .def_property_readonly("moved_cameras", [](const Keyframe& k) { return PointCameras(k.update.moved_points); })
      .def_property_readonly("removed_ids", [](const Keyframe& k) {
        return py::array_t<uint64_t>(static_cast<py::ssize_t>(k.update.removed_points.size()),
                                     k.update.removed_points.data());
      })
      .def("__repr__", [](const Keyframe& k) {
        return "imr.Keyframe(index=" + std::to_string(k.info.index) + ", frame=" + std::to_string(k.info.frame) +
               ", cameras=" + std::to_string(k.update.cameras.size()) + ", new=" +
               std::to_string(k.update.new_points.size()) + ", moved=" +
               std::to_string(k.update.moved_points.size()) + ", removed=" +
               std::to_string(k.update.removed_points.size()) + ")";
      });
}

// imr.Engine.
void BindEngine(py::module_& m) {
  py::class_<PyEngine>(m, "Engine",
                       "The engine, fed keyframe by keyframe: Engine(weight_policy=None, "
                       "weight_policy_params=None, **options), options as a job's \"engine\" "
                       "section (imr options --only engine); ValueError names a bad one.")
      .def(py::init<const py::object&, const py::object&, const py::kwargs&>(),
           py::arg("weight_policy") = py::none(), py::arg("weight_policy_params") = py::none())
      .def("add_keyframe", [](PyEngine& e, Keyframe& k) { e.AddKeyframe(k); }, py::arg("keyframe"),
           "one keyframe, as imr run applies it: a Keyframe from a reader, or camera (a Camera or "
           "a list), new_ids (N,), new_positions (N, 3), new_cameras (None: the keyframe's camera; "
           "ids per point), moved_ids, moved_positions, moved_cameras, removed_ids")
      .def("add_keyframe",
           [](PyEngine& e, const py::object& camera, const py::object& new_ids,
              const py::object& new_positions, const py::object& new_cameras,
              const py::object& moved_ids, const py::object& moved_positions,
              const py::object& moved_cameras, const py::object& removed_ids) {
             e.AddKeyframe(BuildKeyframe(camera, new_ids, new_positions, new_cameras, moved_ids,
                                         moved_positions, moved_cameras, removed_ids));
           },
           py::arg("camera") = py::none(), py::arg("new_ids") = py::none(),
           py::arg("new_positions") = py::none(), py::arg("new_cameras") = py::none(),
           py::arg("moved_ids") = py::none(), py::arg("moved_positions") = py::none(),
           py::arg("moved_cameras") = py::none(), py::arg("removed_ids") = py::none())
      .def("mesh", &PyEngine::MeshNow, py::arg("point_ids") = false,
           "(vertices float64 (V, 3), faces int32 (F, 3)[, point ids int64 (V,)]): the exported "
           "surface now, the engine's buffers handed to numpy (no copy)")
      .def("stats", &PyEngine::Stats, "the counters of report.json's \"engine\", with \"scale\"")
      .def("options", &PyEngine::Options, "the engine options in use (after engine.scale)")
      .def("write", &PyEngine::Write, py::arg("path"),
           "writes the mesh as imr run does (org.imr.exporter.assimp): .ply, .obj, .gltf or .glb")
      .def_property_readonly("keyframes", &PyEngine::keyframes);
}

// imr.Reader.
void BindReader(py::module_& m) {
  py::class_<PyReader>(m, "Reader")
      .def(py::init<const std::string&, const std::string&, const py::dict&>(), py::arg("format"),
           py::arg("path"), py::arg("options"))
      .def("__iter__", [](PyReader& r) -> PyReader& { return r; })
      .def("__next__", &PyReader::Next)
      .def("__len__", [](const PyReader& r) {
        if (r.Count() < 0) throw py::type_error("this reader does not know its length");
        return r.Count();
      });
}

// _run and _evaluate (imr.run and imr.evaluate in __init__.py).
void BindRunAndEvaluate(py::module_& m) {
  m.def("_run", [](const std::string& job_file, const py::object& job_text,
                   const std::vector<std::string>& overrides, int threads, const std::string& job_name) {
    json reports;
    const std::optional<std::string> text =
        job_text.is_none() ? std::nullopt : std::optional<std::string>(job_text.cast<std::string>());
    Interruptible([&] { reports = RunJob(job_file, text ? &*text : nullptr, overrides, threads, job_name); });
    return ToPython(reports);
  });
  // mesh: a path, or (vertices, faces) arrays; truth: a path, "" (velodyne_seq) or an (N, 3)
  // array. Arrays are evaluated in memory: no copy of the caller's data is written anywhere.
  m.def("_evaluate", [](const py::object& mesh, const py::object& truth, const py::dict& options) {
    const std::string o = ToJson(options, "options").dump();
    std::optional<imr::eval::TriangleMesh> mesh_data;
    std::optional<std::vector<imr::Vec3>> truth_points;
    std::string mesh_name, truth_name;
    if (py::isinstance<py::str>(mesh)) {
      mesh_name = mesh.cast<std::string>();
    } else {
      mesh_name = "<arrays>";
      const py::sequence vf = mesh.cast<py::sequence>();
      mesh_data = MeshFromArrays(vf[0], vf[1]);
    }
    if (py::isinstance<py::str>(truth)) {
      truth_name = truth.cast<std::string>();
    } else {
      truth_name = "<array>";
      truth_points = PointsFromArray(truth, "truth");
    }
    json report;
    Interruptible([&] {
      report = Evaluate(mesh_name, truth_name, o, mesh_data ? &*mesh_data : nullptr,
                        truth_points ? &*truth_points : nullptr);
    });
    return ToPython(report);
  });
}

// _set_plugin_directory and set_log_level.
void BindSettings(py::module_& m) {
  m.def("_set_plugin_directory", [](const std::string& d) { SetPluginDirectory(d); });
  m.def("set_log_level", [](const std::string& level) {
    using imr::LogLevel;
    const std::pair<const char*, LogLevel> levels[] = {{"debug", LogLevel::kDebug}, {"info", LogLevel::kInfo},
                                                       {"warning", LogLevel::kWarning}, {"error", LogLevel::kError},
                                                       {"quiet", LogLevel::kQuiet}};
    for (const auto& [name, l] : levels)
      if (level == name) return imr::SetLogLevel(l);
    throw OptionError("set_log_level: expected debug, info, warning, error or quiet, got '" + level + "'");
  }, py::arg("level"), "What imr logs to stderr: debug, info (default), warning, error or quiet.");
}

}  // namespace
}  // namespace imr::python

PYBIND11_MODULE(_imr, m) {
  using namespace imr::python;
  m.doc() = "imr: incremental manifold reconstruction with moving points (docs/python.md)";
  RegisterErrors(m);
  BindCamera(m);
  BindKeyframe(m);
  BindEngine(m);
  BindReader(m);
  BindRunAndEvaluate(m);
  BindSettings(m);
  m.attr("__version__") = imr::pipeline::Version();
}
