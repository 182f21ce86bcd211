#include "evio/calib/error.h"

#include <utility>

namespace evio {
namespace {
std::string format_input_error(const std::string& file, int64_t line, const std::string& problem,
                               const std::string& expected) {
  std::string s;
  if (!file.empty()) {
    s += file;
    if (line > 0) s += ":" + std::to_string(line);
    s += ": ";
  }
  s += problem;
  if (!expected.empty()) s += " (expected: " + expected + ")";
  return s;
}
}  // namespace

InputError::InputError(std::string file, int64_t line, std::string problem, std::string expected)
    : std::runtime_error(format_input_error(file, line, problem, expected)),
      file_(std::move(file)),
      line_(line),
      problem_(std::move(problem)),
      expected_(std::move(expected)) {}

}  // namespace evio
