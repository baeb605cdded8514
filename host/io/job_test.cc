#include "host/io/job.h"

#include "host/io/engine_options.h"

#include <imr/sdk/plugin.hpp>

#include <gtest/gtest.h>

namespace imr::io {
namespace {

bool HasProblem(const std::vector<Problem>& ps, const std::string& text) {
  for (const auto& p : ps)
    if (p.ToString().find(text) != std::string::npos) return true;
  return false;
}

std::string Dump(const std::vector<Problem>& ps) {
  std::string s;
  for (const auto& p : ps) s += p.ToString() + "\n";
  return s;
}

const char* kGood = R"({
  "sequences": ["data/seq*", "other"],
  "input": {"format": "synthetic", "options": {"frames": 10}},
  "engine": {"window": 10},
  "pipeline": [{"kind": "weight_policy", "plugin": "org.imr.policy.nearest", "params": {}},
               {"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
  "output": {"directory": "runs/{job}/{sequence}", "formats": ["obj"]},
  "plugin_paths": ["plugins", "/abs/plugins"]
})";

TEST(Job, ParsesAGoodJobAndResolvesPathsAgainstItsFolder) {
  auto r = ParseJobText(kGood, "/jobs/city.json");
  ASSERT_TRUE(r.ok()) << Dump(r.problems);
  EXPECT_EQ(r.job.sequences.size(), 2u);
  EXPECT_EQ(r.job.pipeline[1].kind, "exporter");
  EXPECT_EQ(r.job.pipeline[1].json_path, "pipeline[1]");
  EXPECT_EQ(r.job.OutputDirectory("seq01"), "/jobs/runs/city/seq01");
  EXPECT_EQ(r.job.plugin_paths[0], "/jobs/plugins");
  EXPECT_EQ(r.job.plugin_paths[1], "/abs/plugins");
  EXPECT_EQ(r.job.output.stem, "mesh");
}

TEST(Job, MalformedJsonGivesLineAndColumn) {
  auto r = ParseJobText("{\n  \"sequences\": [1,\n}", "x.json");
  ASSERT_EQ(r.problems.size(), 1u);
  EXPECT_TRUE(HasProblem(r.problems, "x.json: malformed JSON at line 3, column 1")) << Dump(r.problems);
}

TEST(Job, EmptyFileAndWrongTopLevel) {
  EXPECT_TRUE(HasProblem(ParseJobText("", "e.json").problems, "e.json: malformed JSON at line 1"));
  EXPECT_TRUE(HasProblem(ParseJobText("[1]", "a.json").problems,
                         "expected a JSON object at the top level, got array"));
}

TEST(Job, ReportsEveryStructuralProblem) {
  auto r = ParseJobText(R"({
    "sequences": [],
    "input": {"fromat": "synthetic"},
    "pipeline": [{"kind": "policy", "plugin": 3, "parms": {}}, 7],
    "output": {"directory": "runs/{seq}", "stem": "a/b"},
    "extra": true
  })", "j.json");
  const auto& p = r.problems;
  EXPECT_TRUE(HasProblem(p, "sequences: expected at least one entry")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "input.format: required key is missing")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "input.fromat: unknown key")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[0].kind: expected features, refiner, dense, weight_policy, "
                            "mesh_refiner or exporter, got \"policy\"")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[0].plugin: expected string, got integer 3")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[0].parms: unknown key")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[1]: expected an object")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "output.directory: unknown placeholder {seq}")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "output.stem: expected a file name of letters")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "extra: unknown key")) << Dump(p);
}

TEST(Job, DeepNestingIsRefusedWithItsPositionNotRecursedInto) {
  // 100000 nested arrays: copying or printing them would overflow the stack.
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  const std::string text = "{\"sequences\": [\"a\"],\n \"engine\": " + deep + "}";
  auto r = ParseJobText(text, "/jobs/deep.json");
  ASSERT_EQ(r.problems.size(), 1u) << Dump(r.problems);
  EXPECT_TRUE(HasProblem(r.problems, "/jobs/deep.json: line 2, column 111: arrays and objects "
                                     "nested deeper than 100 levels"))
      << Dump(r.problems);
  // Brackets inside strings do not count; 100 levels are fine.
  r = ParseJobText("{\"description\": \"" + std::string(200, '[') + "\", \"engine\": " +
                       std::string(99, '[') + std::string(99, ']') + "}",
                   "/jobs/ok.json");
  EXPECT_FALSE(HasProblem(r.problems, "nested")) << Dump(r.problems);
  EXPECT_TRUE(HasProblem(r.problems, "engine: expected object")) << Dump(r.problems);
  // A message describing a deep value shows its start only.
  nlohmann::json v = nlohmann::json::array();
  for (int i = 0; i < 100000; ++i) v = nlohmann::json::array({std::move(v)});
  EXPECT_EQ(Describe(v), "[[[[[[[[[...]]]]]]]]]");
  EXPECT_EQ(Describe(nlohmann::json::parse(R"({"a":[1,2],"b":"x"})")), R"({"a":[1,2],"b":"x"})");
}

TEST(Job, IntegersAndTimeoutsOutsideTheirRangeAreNamed) {
  auto edit = [](std::string text, const std::string& from, const std::string& to) {
    return text.replace(text.find(from), from.size(), to);
  };
  const std::string exporter = "\"plugin\": \"org.imr.exporter.assimp\"";
  std::string text = edit(kGood, "\"formats\": [\"obj\"]",
                          "\"formats\": [\"obj\"], \"snapshot_every\": 4294967297");
  text = edit(text, exporter, exporter + ", \"timeout_seconds\": 0");
  auto r = ParseJobText(text, "/jobs/j.json");
  EXPECT_TRUE(HasProblem(r.problems, "output.snapshot_every: expected an integer in [0, 2147483647], "
                                     "got 4294967297"))
      << Dump(r.problems);
  EXPECT_TRUE(HasProblem(r.problems, "pipeline[1].timeout_seconds: expected a number of seconds > 0"))
      << Dump(r.problems);
  r = ParseJobText(edit(kGood, exporter, exporter + ", \"timeout_seconds\": 2.5"), "/jobs/j.json");
  ASSERT_TRUE(r.ok()) << Dump(r.problems);
  EXPECT_EQ(r.job.pipeline[1].timeout_seconds, 2.5);
  EXPECT_EQ(r.job.pipeline[0].timeout_seconds, 0.0);
}

TEST(Job, SeveralSequencesNeedTheSequencePlaceholder) {
  auto r = ParseJobText(R"({"sequences": ["a", "b"], "input": {"format": "synthetic"},
    "pipeline": [{"kind": "exporter", "plugin": "x"}], "output": {"directory": "runs"}})", "j.json");
  EXPECT_TRUE(HasProblem(r.problems, "output.directory: several sequences would share one folder"));
}

TEST(Job, PlaceholdersAreReplacedInOnePass) {
  // A value holding a placeholder is text: the replacement used to find it again and spin.
  EXPECT_EQ(ExpandTemplate("runs/{job}/{sequence}", {{"{sequence}", "x{job}"}, {"{job}", "{job}"}}),
            "runs/{job}/x{job}");
  EXPECT_EQ(ExpandTemplate("{a}{b}{", {{"{a}", "{b}"}, {"{b}", "B"}}), "{b}B{");
  const JobParseResult r = ParseJobText(kGood, "/data/jobs/{job}.json");
  ASSERT_TRUE(r.ok()) << Dump(r.problems);
  EXPECT_EQ(r.job.OutputDirectory("{sequence}"), "/data/jobs/runs/{job}/{sequence}");
  EXPECT_EQ(r.job.BatchDirectory(), "/data/jobs/runs/{job}");
}

TEST(Job, DuplicateKeysAreNamedWithBothPlaces) {
  const std::string text =
      "{\"sequences\": [\"a\"], \"input\": {\"format\": \"synthetic\"},\n"
      " \"pipeline\": [{\"kind\": \"exporter\", \"plugin\": \"x\", \"params\": {\"a\": [{\"k\": 1, \"\\u006b\": 2}]}}],\n"
      " \"output\": {\"directory\": \"runs/{sequence}\"}, \"output\": {}}";
  const JobParseResult r = ParseJobText(text, "j.json");
  EXPECT_TRUE(HasProblem(r.problems, "pipeline[0].params.a[0].k: the key appears twice (line 2, "
                                     "column 69 and line 2, column 77)"))
      << Dump(r.problems);
  EXPECT_TRUE(HasProblem(r.problems, "output: the key appears twice (line 3, column 2 and line 3, "
                                     "column 46)"))
      << Dump(r.problems);
  EXPECT_TRUE(ParseJobText(kGood, "j.json").ok());  // equal keys in different objects are fine
}

TEST(Schema, ChecksTypesRangesEnumsAndUnknownKeys) {
  const nlohmann::json schema = nlohmann::json::parse(R"({
    "window": {"type": "integer", "minimum": 1, "default": 15},
    "ratio": {"type": "number", "minimum": 0, "maximum": 1, "default": 0.5},
    "mode": {"type": "string", "enum": ["a", "b"], "default": "a"},
    "names": {"type": "string_array", "default": []}
  })");
  ASSERT_TRUE(CheckSchema(schema, "s").empty());
  std::vector<Problem> p;
  ValidateAgainstSchema(schema, {{"window", "15"}, {"ratio", 2}, {"mode", "c"}, {"names", {1}},
                                 {"x", 1}},
                        "pipeline[2].params", &p);
  EXPECT_TRUE(HasProblem(p, "pipeline[2].params.window: expected integer >= 1, got \"15\"")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[2].params.ratio: expected number in [0, 1], got 2")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[2].params.mode: expected string (one of \"a\" or \"b\"), got \"c\"")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[2].params.names: expected array of strings, got [1]")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "pipeline[2].params.x: unknown key (expected mode, names, ratio or window)")) << Dump(p);
  EXPECT_EQ(p.size(), 5u);
  const auto filled = WithDefaults(schema, {{"window", 3}});
  EXPECT_EQ(filled["window"], 3);
  EXPECT_EQ(filled["mode"], "a");
}

TEST(Schema, RejectsMalformedSchemas) {
  EXPECT_FALSE(CheckSchema(nlohmann::json::parse(R"({"a": {"type": "int"}})"), "s").empty());
  EXPECT_FALSE(CheckSchema(nlohmann::json::parse(R"({"a": {"type": "integer", "default": "1"}})"), "s").empty());
  EXPECT_FALSE(CheckSchema(nlohmann::json::parse(R"({"a": {"type": "integer", "dflt": 1}})"), "s").empty());
  EXPECT_FALSE(CheckSchema(nlohmann::json::array(), "s").empty());
}

TEST(JobOverrides, PathsValuesAndMistakes) {
  nlohmann::json job = nlohmann::json::parse(
      R"({"engine": {"window": 15}, "pipeline": [{"plugin": "a"}, {"plugin": "b"}]})");
  std::vector<Problem> p;
  ApplyJobOverrides({"engine.window=9", "pipeline[1].params.max_distance=20.5",
                     "pipeline.0.plugin=c", "input.options.frames=40", "output.stem=m",
                     "output.formats=[\"ply\"]", "description=1e999"},
                    &job, &p);
  EXPECT_TRUE(p.empty()) << Dump(p);
  EXPECT_EQ(job["engine"]["window"], 9);
  EXPECT_EQ(job["pipeline"][1]["params"]["max_distance"], 20.5);
  EXPECT_EQ(job["pipeline"][0]["plugin"], "c");
  EXPECT_EQ(job["input"]["options"]["frames"], 40);
  EXPECT_EQ(job["output"]["stem"], "m");  // not JSON: a string
  EXPECT_EQ(job["output"]["formats"], nlohmann::json({"ply"}));
  EXPECT_EQ(job["description"], "1e999");
  const nlohmann::json before = job;
  ApplyJobOverrides({"window", "=1", "engine..window=1", "pipeline[2].plugin=x",
                     "pipeline[x].plugin=y", "engine.window.deeper=1",
                     "engine.w=" + std::string(200, '[') + std::string(200, ']')},
                    &job, &p);
  EXPECT_EQ(p.size(), 7u) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "--set window: expected KEY=VALUE, e.g. engine.steiner_spacing=2"));
  EXPECT_TRUE(HasProblem(p, "--set pipeline[2].plugin=x: pipeline has 2 entries, no [2]")) << Dump(p);
  EXPECT_TRUE(HasProblem(p, "--set engine.window.deeper=1: engine.window is 9, not an object or array"))
      << Dump(p);
  EXPECT_EQ(job, before);
}

// The host and the SDK's plugin wrapper share one validator: the same values pass and fail.
TEST(Schema, TheHostAndThePluginWrapperAgree) {
  const auto schema = nlohmann::json::parse(
      R"({"n": {"type": "integer", "minimum": 1, "default": 3}, "x": {"type": "number"}})");
  for (const char* params : {R"({"n": 5000000000})", R"({"n": -5000000000})", R"({"n": 0})",
                             R"({"n": 2.5})", R"({"m": 1})", R"({"x": "a"})", R"({"n": 7})"}) {
    SCOPED_TRACE(params);
    std::vector<Problem> host;
    ValidateAgainstSchema(schema, nlohmann::json::parse(params), "params", &host);
    std::string wrapper;
    try {
      sdk::detail::CheckedAgainstSchema(schema.dump().c_str(), sdk::Params(nlohmann::json::parse(params)));
    } catch (const sdk::InvalidArgument& e) {
      wrapper = e.what();
    }
    EXPECT_EQ(wrapper, host.empty() ? "" : host[0].ToString());
  }
  EXPECT_EQ(sdk::detail::CheckedAgainstSchema(schema.dump().c_str(), sdk::Params()).Get<int>("n"), 3);
}

TEST(EngineOptionsJson, DefaultsRoundTripAndErrorsNameTheField) {
  engine::EngineOptions o;
  std::vector<Problem> p;
  ASSERT_TRUE(EngineOptionsFromJson(nlohmann::json::object(), &o, &p)) << Dump(p);
  EXPECT_EQ(o.window, 15);
  EXPECT_EQ(o.steiner_spacing, 5.0);
  EXPECT_FALSE(o.transfer_on_insert);
  ASSERT_TRUE(EngineOptionsFromJson(
      {{"visibility_mode", "rays"}, {"rays_per_cell", 1}, {"transfer_on_insert", true}}, &o, &p));
  EXPECT_TRUE(o.transfer_on_insert);
  EXPECT_EQ(EngineOptionsToJson(o)["transfer_on_insert"], true);
  EXPECT_EQ(o.visibility_mode, engine::VisibilityMode::kRays);
  EXPECT_EQ(o.rays_per_cell, 1);
  EXPECT_EQ(EngineOptionsToJson(o)["visibility_mode"], "rays");
  EXPECT_FALSE(EngineOptionsFromJson({{"window", 0}}, &o, &p));
  EXPECT_TRUE(HasProblem(p, "engine.window: expected integer >= 1, got 0")) << Dump(p);
}

}  // namespace
}  // namespace imr::io
