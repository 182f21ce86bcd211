// evio/calib/json.h: numbers, strings, arrays and objects spelled as evio's JSON files spell them.
#include "evio/calib/json.h"

#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace evio {
namespace {

TEST(Json, NumbersAndStrings) {
  EXPECT_EQ(json_number(0.1, 9), "0.1");
  EXPECT_EQ(json_number(0.1), "0.10000000000000001");
  EXPECT_EQ(json_number(240), "240");
  EXPECT_EQ(json_number(NAN), "null");
  EXPECT_EQ(json_string("a \"b\"\\\n"), "\"a \\\"b\\\"\\\\\\u000a\"");
}

TEST(Json, Arrays) {
  EXPECT_EQ(json_numbers(std::vector<double>{1.5, 2}, 9), "[1.5, 2]");
  EXPECT_EQ(json_numbers(std::vector<int>{}), "[]");
  EXPECT_EQ(json_strings(std::vector<std::string>{"flow", "a\"b"}), "[\"flow\", \"a\\\"b\"]");
  EXPECT_EQ(json_strings(std::vector<std::string>{}), "[]");
  EXPECT_EQ(json_array({"{\"a\": 1}", "[2]", "null"}), "[{\"a\": 1}, [2], null]");
  EXPECT_EQ(json_array({}), "[]");
}

TEST(Json, ObjectLayouts) {
  JsonObject inline_object(9);
  inline_object.integer("a", 1).number("b", 0.5).boolean("c", true).string("d", "x").raw("e", "[]");
  EXPECT_EQ(inline_object.str(), "{\"a\": 1, \"b\": 0.5, \"c\": true, \"d\": \"x\", \"e\": []}");
  JsonObject lines(9, JsonObject::Layout::kLines);
  lines.integer("a", 1).raw("b", inline_object.str());
  EXPECT_EQ(lines.str(), "{\n  \"a\": 1,\n  \"b\": {\"a\": 1, \"b\": 0.5, \"c\": true, \"d\": \"x\", \"e\": []}\n}");
  EXPECT_EQ(JsonObject().str(), "{}");
  EXPECT_EQ(JsonObject(9, JsonObject::Layout::kLines).str(), "{}");
}

}  // namespace
}  // namespace evio
