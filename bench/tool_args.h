// Argument parsing shared by the bench table tools (cmax_rotation_table, reconstruct_quality,
// reconstruct_budget): the value after option argv[*i], advancing *i; exits with 2 naming the
// option when it is missing.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

inline std::string next_arg(int argc, char** argv, int* i) {
  if (*i + 1 >= argc) {
    std::fprintf(stderr, "%s needs a value\n", argv[*i]);
    std::exit(2);
  }
  return argv[++*i];
}
