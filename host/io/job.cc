#include "host/io/job.h"

#include "host/util/input_file.h"

#include "host/io/json_stream.h"

#include <cctype>
#include <cstdint>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace imr::io {
namespace fs = std::filesystem;
namespace {

using json = nlohmann::json;

std::string TypeName(const json& v) {
  if (v.is_null()) return "null";
  if (v.is_boolean()) return "boolean";
  if (v.is_number_integer()) return "integer";
  if (v.is_number()) return "number";
  if (v.is_string()) return "string";
  if (v.is_array()) return "array";
  return "object";
}

// Walks one JSON object, recording problems; each Take* marks the key as known.
class ObjectReader {
 public:
  ObjectReader(const json& obj, std::string path, std::vector<Problem>* problems)
      : obj_(obj), path_(std::move(path)), problems_(problems) {}

  const json* Get(const std::string& key, bool required) {
    known_.insert(key);
    auto it = obj_.find(key);
    if (it == obj_.end()) {
      if (required) problems_->push_back({Path(key), "required key is missing"});
      return nullptr;
    }
    return &*it;
  }

  std::optional<std::string> String(const std::string& key, bool required) {
    const json* v = Get(key, required);
    if (v == nullptr) return std::nullopt;
    if (!v->is_string()) {
      Wrong(key, "string", *v);
      return std::nullopt;
    }
    return v->get<std::string>();
  }

  std::optional<std::vector<std::string>> Strings(const std::string& key, bool required,
                                                  bool non_empty) {
    const json* v = Get(key, required);
    if (v == nullptr) return std::nullopt;
    if (!v->is_array()) {
      Wrong(key, "array of strings", *v);
      return std::nullopt;
    }
    std::vector<std::string> out;
    bool ok = true;
    for (std::size_t i = 0; i < v->size(); ++i) {
      const json& e = (*v)[i];
      if (!e.is_string() || e.get<std::string>().empty()) {
        problems_->push_back({Path(key) + "[" + std::to_string(i) + "]",
                              "expected a non-empty string, got " + Describe(e)});
        ok = false;
      } else {
        out.push_back(e.get<std::string>());
      }
    }
    if (ok && non_empty && out.empty())
      problems_->push_back({Path(key), "expected at least one entry, got []"});
    if (!ok) return std::nullopt;
    return out;
  }

  std::optional<int64_t> Integer(const std::string& key, bool required, int64_t minimum) {
    const json* v = Get(key, required);
    if (v == nullptr) return std::nullopt;
    if (!v->is_number_integer()) {
      Wrong(key, "integer", *v);
      return std::nullopt;
    }
    // The values are ints: a larger one would wrap silently (2^32 + 1 -> 1).
    const int64_t i = v->is_number_unsigned() && v->get<uint64_t>() > INT64_MAX
                          ? INT64_MAX
                          : v->get<int64_t>();
    if (i < minimum || i > INT32_MAX) {
      problems_->push_back({Path(key), "expected an integer in [" + std::to_string(minimum) +
                                           ", " + std::to_string(INT32_MAX) + "], got " +
                                           Describe(*v)});
      return std::nullopt;
    }
    return i;
  }

  const json* Object(const std::string& key, bool required) {
    const json* v = Get(key, required);
    if (v != nullptr && !v->is_object()) {
      Wrong(key, "object", *v);
      return nullptr;
    }
    return v;
  }

  // Unknown keys are errors: a typo must never be silently ignored.
  void RejectUnknown() {
    std::vector<std::string> known(known_.begin(), known_.end());
    for (const auto& [k, _] : obj_.items())
      if (!known_.count(k))
        problems_->push_back({Path(k), "unknown key (expected " + JoinAlternatives(known) + ")"});
  }

  std::string Path(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

 private:
  void Wrong(const std::string& key, const std::string& expected, const json& got) {
    // "got string \"ply\"", "got number 3"; null is its own type and value ("got null").
    problems_->push_back({Path(key), "expected " + expected + ", got " +
                                         (got.is_null() ? std::string("null")
                                                        : TypeName(got) + " " + Describe(got))});
  }
  const json& obj_;
  std::string path_;
  std::vector<Problem>* problems_;
  std::set<std::string> known_;
};

// nlohmann reports a byte offset; people want line and column.
std::string LineColumn(const std::string& text, std::size_t byte) {
  std::size_t line = 1, col = 1;
  for (std::size_t i = 0; i < byte && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(col);
}

// The byte where arrays and objects first nest deeper than `max_depth`, or npos. A scan of the
// text, before parsing: nlohmann parses any depth, but copying or printing the value recurses.
std::size_t TooDeepAt(const std::string& text, std::size_t max_depth) {
  std::size_t depth = 0;
  bool in_string = false, escaped = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return i;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return std::string::npos;
}

// Keys that appear twice in one object: nlohmann keeps the last silently, and a typo must never
// be silently ignored. A scan of the text (already parsed, so well formed) that follows the
// nesting to name each with its JSON path and both places.
std::vector<Problem> DuplicateKeys(const std::string& text) {
  struct Frame {
    bool object = false;
    std::size_t index = 0;                       // arrays: the element being read
    std::string path;                            // this container's JSON path
    std::map<std::string, std::size_t> keys;     // objects: key -> byte of its first quote
    std::string key;                             // objects: the key of the value being read
  };
  std::vector<Problem> problems;
  std::vector<Frame> stack;
  auto child_path = [&stack]() -> std::string {
    if (stack.empty()) return "";
    const Frame& f = stack.back();
    if (!f.object) return f.path + "[" + std::to_string(f.index) + "]";
    return f.path.empty() ? f.key : f.path + "." + f.key;
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '{' || c == '[') {
      Frame f;
      f.object = c == '{';
      f.path = child_path();
      stack.push_back(std::move(f));
    } else if (c == '}' || c == ']') {
      if (!stack.empty()) stack.pop_back();
    } else if (c == ',') {
      if (!stack.empty() && !stack.back().object) ++stack.back().index;
    } else if (c == '"') {
      std::size_t end = i + 1;
      while (end < text.size() && text[end] != '"') end += text[end] == '\\' ? 2 : 1;
      std::size_t next = end + 1;
      while (next < text.size() && std::isspace(static_cast<unsigned char>(text[next]))) ++next;
      if (!stack.empty() && stack.back().object && next < text.size() && text[next] == ':') {
        Frame& f = stack.back();
        std::string key;
        try {
          key = json::parse(text.substr(i, end + 1 - i)).get<std::string>();
        } catch (const json::exception&) {
          key = text.substr(i + 1, end - i - 1);
        }
        f.key = key;
        const auto [it, first] = f.keys.emplace(key, i);
        if (!first)
          problems.push_back({f.path.empty() ? key : f.path + "." + key,
                              "the key appears twice (" + LineColumn(text, it->second) + " and " +
                                  LineColumn(text, i) +
                                  "); JSON would keep the last one silently: remove one"});
      }
      i = end;
    }
  }
  return problems;
}

void ParseStage(const json& v, std::size_t index, JobSpec* job, std::vector<Problem>* problems) {
  const std::string path = "pipeline[" + std::to_string(index) + "]";
  if (!v.is_object()) {
    problems->push_back({path, "expected an object {\"kind\", \"plugin\", \"params\"}, got " +
                                   Describe(v)});
    return;
  }
  ObjectReader r(v, path, problems);
  StageSpec stage;
  stage.json_path = path;
  if (auto kind = r.String("kind", true)) {
    stage.kind = *kind;
    bool known = false;
    for (const auto& k : StageKinds()) known |= k == *kind;
    if (!known)
      problems->push_back({r.Path("kind"), "expected " + JoinAlternatives(StageKinds()) +
                                               ", got " + Describe(*kind)});
  }
  if (auto plugin = r.String("plugin", true)) stage.plugin = *plugin;
  if (const json* params = r.Object("params", false)) stage.params = *params;
  r.String("description", false);
  if (const json* t = r.Get("timeout_seconds", false)) {
    // Finite, or the deadline would overflow; a year at most catches minutes/ms mix-ups.
    if (t->is_number() && t->get<double>() > 0.0 && t->get<double>() <= kMaxStageTimeoutSeconds)
      stage.timeout_seconds = t->get<double>();
    else
      problems->push_back({r.Path("timeout_seconds"),
                           "expected a number of seconds > 0 and at most " +
                               std::to_string(static_cast<long>(kMaxStageTimeoutSeconds)) +
                               " (a year), got " + Describe(*t)});
  }
  // A mesh refiner's schedule is the host's, not the plugin's: refine every this many keyframes.
  if (const json* e = r.Get("every_keyframes", false)) {
    if (stage.kind != "mesh_refiner")
      problems->push_back({r.Path("every_keyframes"), "only a mesh_refiner stage has a schedule"});
    else if (e->is_number_integer() && e->get<int64_t>() >= 0 && e->get<int64_t>() <= 1000000)
      stage.every_keyframes = e->get<int>();
    else
      problems->push_back({r.Path("every_keyframes"),
                           "expected an integer from 0 (only at the end) to 1000000, got " +
                               Describe(*e)});
  }
  r.RejectUnknown();
  job->pipeline.push_back(std::move(stage));
}

}  // namespace

const std::vector<std::string>& StageKinds() {
  static const std::vector<std::string> kinds = {"features", "refiner", "dense", "weight_policy",
                                                 "mesh_refiner", "exporter"};
  return kinds;
}

fs::path JobSpec::Resolve(const std::string& p) const {
  fs::path path(p);
  return path.is_absolute() ? path : (base_dir / path).lexically_normal();
}

std::string ExpandTemplate(const std::string& tmpl,
                           const std::vector<std::pair<std::string, std::string>>& values) {
  std::string out;
  for (std::size_t pos = 0; pos < tmpl.size();) {
    bool replaced = false;
    for (const auto& [key, value] : values)
      if (tmpl.compare(pos, key.size(), key) == 0) {
        out += value;
        pos += key.size();
        replaced = true;
        break;
      }
    if (!replaced) out += tmpl[pos++];
  }
  return out;
}

fs::path JobSpec::OutputDirectory(const std::string& sequence_name) const {
  return Resolve(ExpandTemplate(output.directory, {{"{sequence}", sequence_name}, {"{job}", Name()}}));
}

fs::path JobSpec::BatchDirectory() const {
  fs::path prefix;
  bool has_sequence = false;
  for (const fs::path& c : fs::path(output.directory)) {
    if (c.string().find("{sequence}") != std::string::npos) {
      has_sequence = true;
      break;
    }
    prefix /= c;
  }
  fs::path dir = OutputDirectory("");  // no {sequence}: the one output folder
  if (has_sequence) {
    const std::string s = ExpandTemplate(prefix.string(), {{"{job}", Name()}});
    dir = Resolve(s.empty() ? "." : s);
  }
  dir = dir.lexically_normal();
  if (dir.has_relative_path() && dir.filename().empty()) dir = dir.parent_path();
  return fs::absolute(dir);
}

std::vector<Problem> CheckOutputTemplate(const std::string& tmpl, const std::string& path) {
  std::vector<Problem> problems;
  for (std::size_t open = tmpl.find('{'); open != std::string::npos;
       open = tmpl.find('{', open + 1)) {
    const std::size_t close = tmpl.find('}', open);
    if (close == std::string::npos) {
      problems.push_back({path, "unclosed '{' in " + Describe(tmpl)});
      break;
    }
    const std::string key = tmpl.substr(open, close - open + 1);
    if (key != "{sequence}" && key != "{job}")
      problems.push_back({path, "unknown placeholder " + key + " (expected {sequence} or {job})"});
  }
  return problems;
}

void ApplyJobOverrides(const std::vector<std::string>& overrides, json* job,
                       std::vector<Problem>* problems) {
  for (const std::string& o : overrides) {
    const std::string where = "--set " + o;
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0) {
      problems->push_back({where, "expected KEY=VALUE, e.g. engine.steiner_spacing=2"});
      continue;
    }
    // "a.b[2].c" -> a, b, 2, c; an empty key ("a..b", ".a", "a[]") is an error.
    std::vector<std::string> keys;
    std::string key;
    bool ok = true;
    char previous = '.';
    for (char c : o.substr(0, eq)) {
      if (c == '.' || c == '[' || c == ']') {
        if (key.empty() && !(previous == ']' && c != ']')) ok = false;
        if (!key.empty()) keys.push_back(key);
        key.clear();
      } else {
        key += c;
      }
      previous = c;
    }
    if (!key.empty()) keys.push_back(key);
    else if (previous != ']') ok = false;
    if (!ok || keys.empty()) {
      problems->push_back({where, "expected a key path like engine.steiner_spacing or "
                                  "pipeline[1].params.max_distance"});
      continue;
    }
    const std::string text = o.substr(eq + 1);
    if (TooDeepAt(text, kMaxJsonDepth) != std::string::npos) {
      problems->push_back({where, "arrays and objects nested deeper than " +
                                      std::to_string(kMaxJsonDepth) + " levels"});
      continue;
    }
    json value = text;  // what is not JSON is a string
    try {
      json parsed = json::parse(text, nullptr, /*allow_exceptions=*/false);
      if (!parsed.is_discarded()) value = std::move(parsed);
    } catch (const json::exception&) {  // e.g. 1e999, too large for a double: a string
    }
    json* at = job;
    std::string path;
    for (std::size_t i = 0; i < keys.size() && at != nullptr; ++i) {
      const std::string& k = keys[i];
      const bool last = i + 1 == keys.size();
      if (at->is_array()) {
        std::size_t index = 0;
        if (k.find_first_not_of("0123456789") != std::string::npos || k.size() > 9 ||
            (index = std::stoul(k)) >= at->size()) {
          problems->push_back({where, (path.empty() ? "the job" : path) + " has " +
                                          std::to_string(at->size()) + " entries, no [" + k + "]"});
          at = nullptr;
          break;
        }
        path += "[" + k + "]";
        at = &(*at)[index];
      } else if (at->is_object() || at->is_null()) {
        path += (path.empty() ? "" : ".") + k;
        at = &(*at)[k];
      } else {
        problems->push_back({where, path + " is " + Describe(*at) + ", not an object or array"});
        at = nullptr;
        break;
      }
      if (last) *at = value;
    }
  }
}

// The job file's JSON object; nullopt (with the problem) when it is too deep, malformed or not
// an object. Never throws.
std::optional<json> ParseJobRoot(const std::string& text, const fs::path& file,
                                 std::vector<Problem>* problems) {
  if (const std::size_t at = TooDeepAt(text, kMaxJsonDepth); at != std::string::npos) {
    problems->push_back({"", file.string() + ": " + LineColumn(text, at) +
                                 ": arrays and objects nested deeper than " +
                                 std::to_string(kMaxJsonDepth) + " levels"});
    return std::nullopt;
  }
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    std::string what = e.what();
    // Keep nlohmann's explanation, drop its "[json.exception.parse_error.101] parse error at
    // line x, column y:" prefix in favour of ours.
    const auto colon = what.find(": ", what.find("parse error"));
    if (colon != std::string::npos) what = what.substr(colon + 2);
    problems->push_back({"", file.string() + ": malformed JSON at " + LineColumn(text, e.byte == 0 ? 0 : e.byte - 1) +
                                 ": " + what});
    return std::nullopt;
  } catch (const json::exception& e) {
    // Not a parse_error: e.g. out_of_range.406, a number too large for a double ("1e999"). Found
    // by tests/fuzz/job_fuzz; ParseJobText must never throw. nlohmann names the number, not
    // where it is: find it.
    const std::string what = e.what();
    std::string where;
    const auto open = what.find('\''), close = what.rfind('\'');
    if (open != std::string::npos && close > open + 1)
      if (const auto at = text.find(what.substr(open + 1, close - open - 1)); at != std::string::npos)
        where = " at " + LineColumn(text, at);
    problems->push_back({"", file.string() + ": malformed JSON" + where + ": " + what});
    return std::nullopt;
  }
  if (!root.is_object()) {
    problems->push_back({"", file.string() + ": expected a JSON object at the top level, got " +
                                 TypeName(root)});
    return std::nullopt;
  }
  return root;
}

// The job's "output": folder template, stem, tiles, formats, snapshots.
void ParseOutput(const json& output, JobSpec* job, std::vector<Problem>* problems) {
  ObjectReader orr(output, "output", problems);
  if (auto d = orr.String("directory", true)) {
    job->output.directory = *d;
    auto p = CheckOutputTemplate(*d, "output.directory");
    problems->insert(problems->end(), p.begin(), p.end());
    if (d->find("{sequence}") == std::string::npos && job->sequences.size() > 1)
      problems->push_back({"output.directory", "several sequences would share one folder: "
                                               "put {sequence} in the template"});
  }
  if (auto s = orr.String("stem", false)) {
    // Plain names only: the stem also names companion files referenced from inside outputs
    // (a glTF's .bin), where spaces or slashes would need escaping.
    const bool plain = !s->empty() && (*s)[0] != '.' &&
                       s->find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                            "0123456789._-") == std::string::npos;
    if (!plain)
      problems->push_back({"output.stem", "expected a file name of letters, digits, '.', '_' "
                                          "and '-' (not starting with '.'), got " + Describe(*s)});
    else
      job->output.stem = *s;
  }
  if (const json* t = orr.Get("tiles", false)) {
    if (t->is_object() || t->is_boolean())
      job->output.tiles = *t;
    else
      problems->push_back({"output.tiles", "expected an object of tile options (or true), got " +
                                               Describe(*t)});
  }
  const bool tiles = job->output.tiles.is_object() || job->output.tiles == json(true);
  if (auto f = orr.Strings("formats", false, false)) {
    job->output.formats = *f;
    if (f->empty() && !tiles)
      problems->push_back({"output.formats", "expected at least one entry, got [] (formats [] "
                                             "with output.tiles writes tiles only)"});
  }
  if (auto n = orr.Integer("snapshot_every", false, 0)) job->output.snapshot_every = static_cast<int>(*n);
  orr.RejectUnknown();
}

JobParseResult ParseJobText(const std::string& text, const fs::path& file,
                            const std::vector<std::string>& overrides) {
  JobParseResult result;
  JobSpec& job = result.job;
  job.file = file;
  // Absolute, so that sources and output folders do not depend on the reader's current folder:
  // the batch's children get the job's absolute path, and with a relative one their manifests
  // never matched the batch's (re-runs redid everything, the summary called them failed).
  std::error_code ec;
  job.base_dir = fs::absolute(file.has_parent_path() ? file.parent_path() : fs::path("."), ec)
                     .lexically_normal();
  auto& problems = result.problems;

  std::optional<json> parsed = ParseJobRoot(text, file, &problems);
  if (!parsed) return result;
  json root = std::move(*parsed);
  for (Problem& p : DuplicateKeys(text)) problems.push_back(std::move(p));
  ApplyJobOverrides(overrides, &root, &problems);
  job.overrides = overrides;

  ObjectReader r(root, "", &problems);
  if (auto d = r.String("description", false)) job.description = *d;
  if (auto seq = r.Strings("sequences", true, true)) job.sequences = *seq;

  if (const json* input = r.Object("input", true)) {
    ObjectReader ir(*input, "input", &problems);
    if (auto f = ir.String("format", true)) job.input.format = *f;
    if (const json* o = ir.Object("options", false)) job.input.options = *o;
    ir.RejectUnknown();
  }

  if (const json* engine = r.Object("engine", false)) job.engine = *engine;

  if (const json* pipeline = r.Get("pipeline", true)) {
    if (!pipeline->is_array() || pipeline->empty()) {
      problems.push_back({"pipeline", "expected a non-empty array of stages, got " +
                                          Describe(*pipeline)});
    } else {
      for (std::size_t i = 0; i < pipeline->size(); ++i) ParseStage((*pipeline)[i], i, &job, &problems);
    }
  }

  if (const json* output = r.Object("output", true)) ParseOutput(*output, &job, &problems);

  if (const json* e = r.Object("evaluation", false)) job.evaluation = *e;

  if (auto paths = r.Strings("plugin_paths", false, false))
    for (const auto& p : *paths) job.plugin_paths.push_back(job.Resolve(p));

  r.RejectUnknown();
  return result;
}

JobParseResult ParseJobFile(const fs::path& file, const std::vector<std::string>& overrides) {
  const auto problem = [&](const std::string& message) {
    JobParseResult r;
    r.job.file = file;
    r.problems.push_back({"", message});
    return r;
  };
  // The open rule (host/util/input_file.h): a FIFO or a device named as the job is refused by
  // name, and at most kMaxJobFileBytes are read.
  std::string text;
  try {
    InputFile in = InputFile::Open(file, "a JSON job file");
    if (in.size() > kMaxJobFileBytes)
      return problem(file.string() + ": more than " + std::to_string(kMaxJobFileBytes >> 20) +
                     " MiB: not a job file (a job file is a few kB of JSON)");
    text = in.ReadAll(kMaxJobFileBytes);
  } catch (const std::runtime_error& e) {
    return problem(e.what());
  }
  return ParseJobText(text, file, overrides);
}

}  // namespace imr::io
