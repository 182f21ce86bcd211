// evio's JSON text: escaped strings and numbers as every JSON file evio writes spells them
// (stats.json, eval.json, simulation.json, sweep rows); JsonObject (below) lays out an object.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace evio {

// The string with '"', '\\' and control characters escaped (no surrounding quotes).
inline std::string json_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", c);
      out += buf;
    } else {
      out += c;
    }
  }
  return out;
}

// A JSON number with `digits` significant digits (17: exact round trip), or null when not finite.
inline std::string json_number(double v, int digits = 17) {
  if (!std::isfinite(v)) return "null";
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.*g", digits, v);
  return buf;
}

// A JSON string: s escaped, in quotes.
inline std::string json_string(const std::string& s) { return "\"" + json_escape(s) + "\""; }

inline std::string json_bool(bool b) { return b ? "true" : "false"; }

// A JSON array of numbers (json_number with `digits`).
template <class Range>
std::string json_numbers(const Range& values, int digits = 17) {
  std::string out = "[";
  bool first = true;
  for (const auto& v : values) {
    out += first ? "" : ", ";
    out += json_number(static_cast<double>(v), digits);
    first = false;
  }
  return out + "]";
}

// A JSON array of strings (json_string each): ["a", "b"].
template <class Range>
std::string json_strings(const Range& values) {
  std::string out = "[";
  bool first = true;
  for (const auto& v : values) {
    out += first ? "" : ", ";
    out += json_string(v);
    first = false;
  }
  return out + "]";
}

// A JSON array of values already encoded (objects, arrays, json_* results): [a, b].
inline std::string json_array(const std::vector<std::string>& encoded) {
  std::string out = "[";
  for (size_t i = 0; i < encoded.size(); ++i) out += (i ? ", " : "") + encoded[i];
  return out + "]";
}

// A JSON object written member by member, in order. Inline: {"a": 1, "b": 2}. Lines (a file's top
// level): "{\n  \"a\": 1,\n  \"b\": 2\n}". Values are encoded by the json_* functions above;
// raw() takes one already encoded (a nested object or array).
class JsonObject {
 public:
  enum class Layout { kInline, kLines };
  explicit JsonObject(int digits = 17, Layout layout = Layout::kInline) : digits_(digits), layout_(layout) {}

  JsonObject& raw(const std::string& key, const std::string& json) {
    body_ += body_.empty() ? (layout_ == Layout::kLines ? "\n  " : "") : (layout_ == Layout::kLines ? ",\n  " : ", ");
    body_ += json_string(key) + ": " + json;
    return *this;
  }
  JsonObject& number(const std::string& key, double v) { return raw(key, json_number(v, digits_)); }
  JsonObject& integer(const std::string& key, int64_t v) { return raw(key, std::to_string(v)); }
  JsonObject& boolean(const std::string& key, bool v) { return raw(key, json_bool(v)); }
  JsonObject& string(const std::string& key, const std::string& v) { return raw(key, json_string(v)); }

  std::string str() const { return "{" + body_ + (layout_ == Layout::kLines && !body_.empty() ? "\n}" : "}"); }

 private:
  int digits_;
  Layout layout_;
  std::string body_;
};

}  // namespace evio
