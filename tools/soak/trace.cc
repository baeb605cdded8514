#include "tools/soak/trace.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

namespace imr::soak {
using nlohmann::json;

namespace {

bool ParseLine(const std::string& line, TraceRecord* r, std::string* error) {
  json j;
  try {
    j = json::parse(line);
  } catch (const json::exception&) {
    *error = "not JSON";
    return false;
  }
  if (!j.is_object()) {
    *error = "not a JSON object";
    return false;
  }
  auto integer = [&](const char* key, int64_t* out) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_number_integer()) {
      *error = std::string("\"") + key + "\" missing or not an integer";
      return false;
    }
    *out = it->get<int64_t>();
    return true;
  };
  auto number = [&](const char* key, double* out) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_number()) {
      *error = std::string("\"") + key + "\" missing or not a number";
      return false;
    }
    *out = it->get<double>();
    return true;
  };
  if (!integer("keyframe", &r->keyframe) || !integer("frame", &r->frame) ||
      !integer("points", &r->points) || !integer("vertices", &r->vertices) ||
      !integer("cells", &r->cells) || !integer("cells_in_o", &r->cells_in_o) ||
      !number("rss_bytes", &r->rss_bytes) || !number("engine_seconds", &r->engine_seconds))
    return false;
  if (j.contains("check_seconds")) {
    double c = 0.0;
    if (!number("check_seconds", &c)) return false;
    r->check_seconds = c;
  }
  return true;
}

double Mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

std::vector<double> Column(const std::vector<TraceRecord>& r, double (*get)(const TraceRecord&)) {
  std::vector<double> v;
  v.reserve(r.size());
  for (const TraceRecord& x : r) v.push_back(get(x));
  return v;
}
double Points(const TraceRecord& r) { return static_cast<double>(r.points); }
double Vertices(const TraceRecord& r) { return static_cast<double>(r.vertices); }
double Cells(const TraceRecord& r) { return static_cast<double>(r.cells); }
double Rss(const TraceRecord& r) { return r.rss_bytes; }

}  // namespace

bool ParseTrace(const std::string& text, std::vector<TraceRecord>* records, std::string* note,
                std::string* error) {
  records->clear();
  note->clear();
  std::istringstream in(text);
  std::string line;
  int number = 0;
  const bool complete = text.empty() || text.back() == '\n';
  while (std::getline(in, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    TraceRecord r;
    std::string why;
    if (!ParseLine(line, &r, &why)) {
      if (!complete && in.peek() == std::char_traits<char>::eof()) {
        *note = "line " + std::to_string(number) + " cut short (run killed?): skipped";
        break;
      }
      *error = "line " + std::to_string(number) + ": " + why;
      return false;
    }
    if (!records->empty() && r.keyframe <= records->back().keyframe) {
      *error = "line " + std::to_string(number) + ": keyframe " + std::to_string(r.keyframe) +
               " does not follow keyframe " + std::to_string(records->back().keyframe);
      return false;
    }
    records->push_back(r);
  }
  return true;
}

bool ReadTrace(const std::string& path, std::vector<TraceRecord>* records, std::string* note,
               std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = path + ": cannot read";
    return false;
  }
  std::ostringstream s;
  s << in.rdbuf();
  if (!ParseTrace(s.str(), records, note, error)) {
    *error = path + ": " + *error;
    return false;
  }
  return true;
}

LinearFit FitLine(const std::vector<double>& x, const std::vector<double>& y) {
  LinearFit f;
  f.n = static_cast<int>(std::min(x.size(), y.size()));
  if (f.n == 0) return f;
  // Centred sums: RSS is ~1e8 and points ~1e5, so raw sums of squares would lose digits.
  std::vector<double> xs(x.begin(), x.begin() + f.n), ys(y.begin(), y.begin() + f.n);
  const double mx = Mean(xs), my = Mean(ys);
  double sxx = 0.0, sxy = 0.0;
  for (int i = 0; i < f.n; ++i) {
    sxx += (xs[i] - mx) * (xs[i] - mx);
    sxy += (xs[i] - mx) * (ys[i] - my);
  }
  f.b = sxx > 0.0 ? sxy / sxx : 0.0;
  f.a = my - f.b * mx;
  double ss = 0.0;
  for (int i = 0; i < f.n; ++i) {
    const double r = ys[i] - (f.a + f.b * xs[i]);
    ss += r * r;
    f.max_abs = std::max(f.max_abs, std::fabs(r));
  }
  f.rms = std::sqrt(ss / f.n);
  return f;
}

bool FitLeastSquares(const std::vector<std::vector<double>>& x, const std::vector<double>& y,
                     std::vector<double>* c) {
  const size_t m = x.size(), n = y.size();
  if (n < m + 2) return false;
  for (const auto& col : x)
    if (col.size() != n) return false;
  // Centred and scaled columns: RSS ~1e8 against counts ~1e5 would lose digits in raw sums.
  std::vector<double> mean(m), scale(m);
  for (size_t j = 0; j < m; ++j) {
    mean[j] = Mean(x[j]);
    double ss = 0.0;
    for (double v : x[j]) ss += (v - mean[j]) * (v - mean[j]);
    scale[j] = std::sqrt(ss / static_cast<double>(n));
    if (!(scale[j] > 0.0)) return false;  // a constant column
  }
  const double my = Mean(y);
  // Normal equations of the standardised columns: a correlation matrix, augmented with X'y.
  std::vector<std::vector<double>> A(m, std::vector<double>(m + 1, 0.0));
  for (size_t i = 0; i < n; ++i)
    for (size_t j = 0; j < m; ++j) {
      const double zj = (x[j][i] - mean[j]) / scale[j];
      for (size_t k = 0; k < m; ++k) A[j][k] += zj * (x[k][i] - mean[k]) / scale[k];
      A[j][m] += zj * (y[i] - my);
    }
  // Gaussian elimination with partial pivoting; a tiny pivot of the correlation matrix means
  // collinear columns.
  for (size_t col = 0; col < m; ++col) {
    size_t piv = col;
    for (size_t r = col + 1; r < m; ++r)
      if (std::fabs(A[r][col]) > std::fabs(A[piv][col])) piv = r;
    if (std::fabs(A[piv][col]) < 1e-6 * static_cast<double>(n)) return false;
    std::swap(A[col], A[piv]);
    for (size_t r = 0; r < m; ++r) {
      if (r == col) continue;
      const double f = A[r][col] / A[col][col];
      for (size_t k = col; k <= m; ++k) A[r][k] -= f * A[col][k];
    }
  }
  c->assign(m + 1, 0.0);
  (*c)[0] = my;
  for (size_t j = 0; j < m; ++j) {
    (*c)[j + 1] = A[j][m] / A[j][j] / scale[j];
    (*c)[0] -= (*c)[j + 1] * mean[j];
  }
  return true;
}

std::vector<TraceRecord> SamePhase(const std::vector<TraceRecord>& records) {
  std::vector<TraceRecord> at_checks;
  for (const TraceRecord& r : records)
    if (r.check_seconds) at_checks.push_back(r);
  return at_checks.size() >= 4 ? at_checks : records;
}

bool Analyse(const std::vector<TraceRecord>& r, SoakFigures* f, std::string* error) {
  *f = SoakFigures();
  if (r.size() < 4) {
    *error = "the trace has " + std::to_string(r.size()) + " keyframes; the analysis needs 4";
    return false;
  }
  f->keyframes = static_cast<int>(r.size());
  f->first = r.front();
  f->last = r.back();
  f->frames = r.back().frame + 1;
  f->rss_start = r.front().rss_bytes;
  f->rss_end = r.back().rss_bytes;
  double rise_at_checks = 0.0;
  for (size_t i = 0; i < r.size(); ++i) {
    const TraceRecord& x = r[i];
    f->engine_total_s += x.engine_seconds;
    if (i > 0 && x.check_seconds) rise_at_checks += x.rss_bytes - r[i - 1].rss_bytes;
    if (x.check_seconds) {
      ++f->checks;
      f->check_total_s += *x.check_seconds;
      f->check_max_s = std::max(f->check_max_s, *x.check_seconds);
    }
    if (x.rss_bytes > f->rss_peak) {
      f->rss_peak = x.rss_bytes;
      f->rss_peak_keyframe = x.keyframe;
    }
  }
  const std::vector<double> rss = Column(r, Rss), points = Column(r, Points);
  f->fit_points = FitLine(points, rss);
  f->fit_vertices = FitLine(Column(r, Vertices), rss);
  f->fit_cells = FitLine(Column(r, Cells), rss);

  const double growth = f->rss_end - f->rss_start;
  f->growth_at_checks = growth > 0.0 ? rise_at_checks / growth : 0.0;

  const std::vector<TraceRecord> s = SamePhase(r);
  f->holdout_at_checks = s.size() != r.size();
  const std::vector<double> srss = Column(s, Rss), spoints = Column(s, Points);
  const size_t half = s.size() / 2;
  f->fit_first_half = FitLine(std::vector<double>(spoints.begin(), spoints.begin() + half),
                              std::vector<double>(srss.begin(), srss.begin() + half));
  double worst = -1.0;
  for (size_t i = half; i < s.size(); ++i) {
    const double dev = srss[i] - (f->fit_first_half.a + f->fit_first_half.b * spoints[i]);
    const double rel = srss[i] > 0.0 ? std::fabs(dev) / srss[i] : 0.0;
    if (rel > worst) {
      worst = rel;
      f->holdout_max_dev = dev;
      f->holdout_max_dev_pct = 100.0 * (srss[i] > 0.0 ? dev / srss[i] : 0.0);
      f->holdout_worst_keyframe = s[i].keyframe;
    }
  }
  f->follows_points = worst <= kHoldoutTolerance;
  return true;
}

Decomposition Decompose(const std::vector<const std::vector<TraceRecord>*>& runs) {
  Decomposition d;
  if (runs.size() < 3 || runs[0]->size() < 2) return d;
  std::vector<std::vector<double>> x(3);
  std::vector<double> y;
  for (const auto* run : runs)
    for (const TraceRecord& r : SamePhase(*run)) {
      x[0].push_back(static_cast<double>(r.points));
      x[1].push_back(static_cast<double>(r.vertices - r.points));
      x[2].push_back(static_cast<double>(r.keyframe));
      y.push_back(r.rss_bytes);
    }
  std::vector<double> c;
  if (!FitLeastSquares(x, y, &c)) return d;
  d.ok = true;
  d.a = c[0];
  d.per_point = c[1];
  d.per_steiner = c[2];
  d.per_keyframe = c[3];
  double ss = 0.0;
  for (size_t i = 0; i < y.size(); ++i) {
    const double r = y[i] - (c[0] + c[1] * x[0][i] + c[2] * x[1][i] + c[3] * x[2][i]);
    ss += r * r;
    d.max_abs = std::max(d.max_abs, std::fabs(r));
  }
  d.rms = std::sqrt(ss / static_cast<double>(y.size()));
  const TraceRecord &first = runs[0]->front(), &last = runs[0]->back();
  d.growth = last.rss_bytes - first.rss_bytes;
  d.growth_points = d.per_point * static_cast<double>(last.points - first.points);
  d.growth_steiner = d.per_steiner * static_cast<double>((last.vertices - last.points) -
                                                         (first.vertices - first.points));
  d.growth_keyframes = d.per_keyframe * static_cast<double>(last.keyframe - first.keyframe);
  return d;
}

std::string Mib(double bytes) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", bytes / (1024.0 * 1024.0));
  return b;
}

}  // namespace imr::soak
