#include "tools/bench/common/frame.h"

#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "tools/bench/common/subprocess.h"

#ifndef IMR_SHARED_DIR
#define IMR_SHARED_DIR IMR_SOURCE_DIR "/../shared"
#endif

namespace imr::bench {

namespace fs = std::filesystem;
using nlohmann::json;

Options::Options(std::string prefix, std::string usage, int error_status)
    : prefix_(std::move(prefix)), usage_(std::move(usage)), error_status_(error_status) {}

Options& Options::Add(const std::string& name, bool takes_value,
                      std::function<std::string(const std::string&)> take) {
  options_.push_back({name, takes_value, std::move(take)});
  return *this;
}

Options& Options::Flag(const std::string& name, bool* to, bool value) {
  return Add(name, false, [to, value](const std::string&) {
    *to = value;
    return std::string();
  });
}

Options& Options::Action(const std::string& name, std::function<void()> act) {
  return Add(name, false, [act](const std::string&) {
    act();
    return std::string();
  });
}

Options& Options::Int(const std::string& name, int* to) {
  return Add(name, true, [to](const std::string& v) {
    char* end = nullptr;
    errno = 0;
    const long x = std::strtol(v.c_str(), &end, 10);
    if (v.empty() || *end || errno || x < INT32_MIN || x > INT32_MAX) return std::string("a whole number");
    *to = static_cast<int>(x);
    return std::string();
  });
}

Options& Options::Uint64(const std::string& name, uint64_t* to) {
  return Add(name, true, [to](const std::string& v) {
    char* end = nullptr;
    errno = 0;
    const unsigned long long x = std::strtoull(v.c_str(), &end, 10);
    if (v.empty() || v[0] == '-' || *end || errno) return std::string("a whole number >= 0");
    *to = x;
    return std::string();
  });
}

Options& Options::Double(const std::string& name, double* to) {
  return Add(name, true, [to](const std::string& v) {
    char* end = nullptr;
    errno = 0;
    const double x = std::strtod(v.c_str(), &end);
    if (v.empty() || *end || errno) return std::string("a number");
    *to = x;
    return std::string();
  });
}

Options& Options::String(const std::string& name, std::string* to) {
  return Add(name, true, [to](const std::string& v) {
    *to = v;
    return std::string();
  });
}

Options& Options::Path(const std::string& name, fs::path* to) {
  return Add(name, true, [to](const std::string& v) {
    *to = v;
    return std::string();
  });
}

Options& Options::List(const std::string& name, std::vector<std::string>* to, char separator) {
  return Add(name, true, [to, separator](const std::string& v) {
    to->clear();
    std::stringstream ss(v);
    if (separator == ' ')
      for (std::string s; ss >> s;) to->push_back(s);
    else
      for (std::string s; std::getline(ss, s, separator);) to->push_back(s);
    return std::string();
  });
}

Options& Options::IntList(const std::string& name, std::vector<int>* to, int min) {
  return Add(name, true, [to, min](const std::string& v) {
    to->clear();
    std::stringstream ss(v);
    for (std::string f; std::getline(ss, f, ',');) {
      char* end = nullptr;
      const long x = std::strtol(f.c_str(), &end, 10);
      if (f.empty() || *end || x < min || x > INT32_MAX)
        return "whole numbers >= " + std::to_string(min) + " apart with commas";
      to->push_back(static_cast<int>(x));
    }
    return std::string();
  });
}

Options& Options::Custom(const std::string& name,
                         std::function<std::string(const std::string&)> take) {
  return Add(name, true, std::move(take));
}

bool Options::Parse(int argc, char** argv, int* status) const {
  for (int i = 0; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "--help" || k == "-h") {
      std::printf("%s", usage_.c_str());
      *status = 0;
      return false;
    }
    const Option* o = nullptr;
    for (const Option& c : options_)
      if (c.name == k) o = &c;
    if (o == nullptr) {
      std::fprintf(stderr, "%s: unknown option '%s'\n%s", prefix_.c_str(), k.c_str(), usage_.c_str());
      *status = error_status_;
      return false;
    }
    if (o->takes_value && i + 1 >= argc) {
      std::fprintf(stderr, "%s: %s needs a value\n%s", prefix_.c_str(), k.c_str(), usage_.c_str());
      *status = error_status_;
      return false;
    }
    const std::string value = o->takes_value ? argv[++i] : "";
    if (const std::string expected = o->take(value); !expected.empty()) {
      std::fprintf(stderr, "%s: %s: expected %s, got '%s'\n", prefix_.c_str(), k.c_str(),
                   expected.c_str(), value.c_str());
      *status = error_status_;
      return false;
    }
  }
  return true;
}

WorkFolder::WorkFolder(const std::string& given, const std::string& bench)
    : path_(given.empty() ? fs::temp_directory_path() /
                                ("imr-bench-" + bench + "-" + std::to_string(getpid()))
                          : fs::path(given)),
      given_(!given.empty()) {
  fs::create_directories(path_);
}

void WorkFolder::Finish(bool remove) const {
  std::error_code ec;
  if (remove && !given_) fs::remove_all(path_, ec);
}

fs::path SharedDir(const std::string& given) {
  if (!given.empty()) return given;
  const char* env = std::getenv("IMR_SHARED_DIR");
  return fs::path(env ? env : IMR_SHARED_DIR);
}

std::string KittiRawSample(const std::string& given) {
  if (!given.empty()) return given;
  return (SharedDir() / "data/kitti-raw-2011_09_26-traffic/2011_09_26/2011_09_26_drive_unknown_sync")
      .lexically_normal()
      .string();
}

std::string ReadFileBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteJson(const fs::path& p, const json& j) { std::ofstream(p) << j.dump(2); }

std::string FindPython() {
  for (const char* py : {"python3", "/usr/bin/python3"})
    if (std::system((std::string(py) + " -c 'import matplotlib' >/dev/null 2>&1").c_str()) == 0)
      return py;
  return "";
}

std::string Format(const char* format, ...) {
  va_list a, b;
  va_start(a, format);
  va_copy(b, a);
  const int n = std::vsnprintf(nullptr, 0, format, a);
  va_end(a);
  std::string s(n > 0 ? static_cast<size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, format, b);
  va_end(b);
  return s;
}

void MarkdownHeader(const std::vector<std::string>& columns) {
  MarkdownRow(columns);
  std::string rule = "|";
  for (size_t i = 0; i < columns.size(); ++i) rule += "---|";
  std::printf("%s\n", rule.c_str());
}

void MarkdownRow(const std::vector<std::string>& cells) {
  std::string line = "|";
  for (const std::string& c : cells) line += " " + c + " |";
  std::printf("%s\n", line.c_str());
}

ImrJobResult RunImrJob(const json& job, const ImrJob& how) {
  WriteJson(how.job_file, job);
  ImrJobResult r;
  r.log = how.log.empty() ? fs::path(how.job_file).replace_extension(".log") : how.log;
  const std::string imr = how.imr.empty() ? (ExeDir() / "imr").string() : how.imr;
  const TimedRun t = RunTimed(how.before + Quote(imr) + " run " + how.args + " " +
                                  Quote(how.job_file.string()) +
                                  (how.extra.empty() ? "" : " " + how.extra),
                              r.log);
  r.status = t.status;
  r.seconds = t.seconds;
  r.peak_rss_mb = t.peak_rss_mb;
  if (job.contains("output") && job["output"].contains("directory"))
    r.report = ReadJson(fs::path(job["output"]["directory"].get<std::string>()) / "report.json");
  return r;
}

}  // namespace imr::bench
