// Small helpers for tests that check files written by the apps.
#pragma once

#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>

namespace evio_test {

// The whole file as text ("" when it cannot be opened).
inline std::string read_text(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// The first number written as "key": <number> in a JSON text; NaN when absent.
inline double json_number(const std::string& json, const std::string& key) {
  std::smatch m;
  if (!std::regex_search(json, m, std::regex("\"" + key + "\": ([-0-9.eE+]+)"))) return std::nan("");
  return std::stod(m[1]);
}

}  // namespace evio_test
