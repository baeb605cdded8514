// The engine options table drives the schema, the reading and the writing of the job's "engine"
// object, and docs/engine.md's list is its output.
#include "host/io/engine_options.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

namespace imr::io {
namespace {
using nlohmann::json;

// A value of the option's type other than its default (and inside its bounds).
json OtherValue(const json& spec) {
  const std::string type = spec["type"];
  if (type == "boolean") return !spec["default"].get<bool>();
  if (type == "integer") return spec["default"].get<int>() + 1;
  if (type == "number") return spec.contains("maximum") ? spec["maximum"].get<double>() / 2
                                                        : spec["default"].get<double>() + 0.5;
  for (const json& e : spec["enum"])
    if (e != spec["default"]) return e;
  return spec["default"];
}

TEST(EngineOptionTable, EveryOptionIsReadAndWrittenThroughItsOwnField) {
  for (const EngineOption& option : EngineOptionTable()) {
    SCOPED_TRACE(option.name);
    EXPECT_FALSE(option.schema.value("description", "").empty());
    if (!option.read) {
      EXPECT_EQ(option.name, "scale");  // the pipeline's, not the engine's
      continue;
    }
    // Defaults: the schema's default is what EngineOptions{} holds.
    EXPECT_EQ(option.write(engine::EngineOptions{}), option.schema["default"]);
    // Another value in, the same value out, and no other option changed.
    const json value = OtherValue(option.schema);
    ASSERT_NE(value, option.schema["default"]);
    engine::EngineOptions o;
    std::vector<Problem> problems;
    ASSERT_TRUE(EngineOptionsFromJson({{option.name, value}}, &o, &problems))
        << (problems.empty() ? "" : problems[0].ToString());
    json expected = EngineOptionsToJson(engine::EngineOptions{});
    expected[option.name] = value;
    EXPECT_EQ(EngineOptionsToJson(o), expected);
  }
}

TEST(EngineOptionTable, CheckInvariantsIsTheFieldOfTheSameName) {
  engine::EngineOptions o;
  std::vector<Problem> problems;
  ASSERT_TRUE(EngineOptionsFromJson({{"check_invariants", true}}, &o, &problems));
  EXPECT_TRUE(o.check_invariants);
}

TEST(EngineOptionTable, TheEngineDocListsExactlyTheTable) {
  std::ifstream in(std::string(IMR_SOURCE_DIR) + "/docs/engine.md");
  ASSERT_TRUE(in) << "docs/engine.md not found";
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string doc = ss.str();
  const std::string begin = "<!-- engine-options:begin -->\n", end = "<!-- engine-options:end -->";
  const auto b = doc.find(begin), e = doc.find(end);
  ASSERT_NE(b, std::string::npos);
  ASSERT_NE(e, std::string::npos);
  EXPECT_EQ(doc.substr(b + begin.size(), e - b - begin.size()),
            SchemaMarkdown(EngineOptionsSchema()))
      << "docs/engine.md's engine options differ from the table: paste the output of "
         "`imr options --markdown --only engine` between the markers";
}

}  // namespace
}  // namespace imr::io
