// Small JSON helpers shared by the subcommands that write JSON (info, eval, simulate, corners, vio).
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

namespace evio::apps {

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

}  // namespace evio::apps
