// evio error types: bad user input (files, configs, calibrations) is reported by throwing
// evio::InputError, which names the file, the 1-based line (0 when not line-oriented), the
// byte offset where useful, and the expected form. apps/ catches it and exits non-zero.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace evio {

class InputError : public std::runtime_error {
 public:
  // what() reads "<file>:<line>: <problem> (expected: <expected>)"; parts that are empty are left out.
  InputError(std::string file, int64_t line, std::string problem, std::string expected = {});

  const std::string& file() const { return file_; }
  int64_t line() const { return line_; }
  const std::string& problem() const { return problem_; }
  const std::string& expected() const { return expected_; }

 private:
  std::string file_;
  int64_t line_;
  std::string problem_;
  std::string expected_;
};

// The Options::Validate(std::string* why) convention: puts msg into *why (when given) and
// returns false, so a check reads `if (x < 0) return validation_failed(why, "x must be >= 0");`.
inline bool validation_failed(std::string* why, const std::string& msg) {
  if (why) *why = msg;
  return false;
}

}  // namespace evio
