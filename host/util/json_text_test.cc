#include "host/util/json_text.h"

#include <gtest/gtest.h>

namespace imr {
namespace {

TEST(JsonText, KeepsUtf8AndEscapesOtherBytes) {
  EXPECT_EQ(JsonText("caf\xC3\xA9"), "caf\xC3\xA9");
  EXPECT_EQ(JsonText("caf\xE9"), "caf\\xE9");  // Latin-1
  EXPECT_EQ(JsonText("\xED\xA0\x80"), "\\xED\\xA0\\x80");  // a UTF-16 surrogate
  EXPECT_EQ(JsonText("\xC0\xAF"), "\\xC0\\xAF");            // overlong '/'
  EXPECT_EQ(JsonText("\xF0\x9F\x98\x80 \xFF"), "\xF0\x9F\x98\x80 \\xFF");
  EXPECT_TRUE(IsUtf8("plain, \xE2\x82\xAC"));
  EXPECT_FALSE(IsUtf8("\xE2\x82"));  // cut short
}

TEST(JsonText, OneLineEscapesControlCharactersAndCuts) {
  EXPECT_EQ(OneLine("1:00:00\ntouch X #"), "1:00:00\\ntouch X #");
  EXPECT_EQ(OneLine(std::string("a\0b\x7f\tc\r", 7)), "a\\x00b\\x7F\\tc\\r");
  EXPECT_EQ(OneLine("caf\xE9"), "caf\\xE9");
  EXPECT_EQ(OneLine(std::string(100, 'z'), 10), std::string(10, 'z') + "... (100 bytes)");
  EXPECT_EQ(OneLine("short", 10), "short");
}

TEST(JsonText, DumpNeverThrowsForBytes) {
  nlohmann::json j = {{"name", "caf\xE9"}, {"list", {"ok", "\xFF"}}};
  j["caf\xE9"] = 1;
  EXPECT_THROW(j.dump(), nlohmann::json::type_error);
  const nlohmann::json back = nlohmann::json::parse(DumpJson(j));
  EXPECT_EQ(back["name"], "caf\\xE9");
  EXPECT_EQ(back["list"][1], "\\xFF");
  EXPECT_EQ(back["caf\\xE9"], 1);
  EXPECT_EQ(DumpJson({{"a", 1}}), "{\"a\":1}");
}

TEST(JsonText, BytesRoundTrip) {
  nlohmann::json j = nlohmann::json::object();
  PutBytes(j, "name", "caf\xE9");
  PutBytes(j, "plain", "street");
  EXPECT_EQ(j["name"], "caf\\xE9");
  EXPECT_TRUE(j.contains("name_base64"));
  EXPECT_FALSE(j.contains("plain_base64"));
  const nlohmann::json back = nlohmann::json::parse(DumpJson(j));
  EXPECT_EQ(GetBytes(back, "name"), "caf\xE9");
  EXPECT_EQ(GetBytes(back, "plain"), "street");
}

}  // namespace
}  // namespace imr
