// The `evio` command: a dispatcher in the style of git. It answers --version and --help itself and
// runs each subcommand as its own program, evio-<name> (<name>_cli.cc), found next to this
// executable (build tree) or in <prefix>/libexec/evio (installed). Each of those links only the
// libraries its command uses, and this one links no shared library beyond the C++ runtime (it
// uses calib's executable_dir), so `evio --version` and a mistyped subcommand cost a few
// milliseconds instead of loading OpenCV, Ceres, PCL and VTK.
// Exit codes: 0 success, 1 bad input, 2 usage error, 3 internal error (as every subcommand).
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "evio/calib/plugin.h"
#include "subcommands.h"

namespace {

using evio::apps::kSubcommands;

// Levenshtein distance (insertions, deletions, substitutions), for subcommand suggestions.
size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

void print_help(FILE* f) {
  std::fprintf(f, "%s\nUsage: evio [OPTIONS] SUBCOMMAND [ARGS]\n\nOptions:\n", evio::apps::kDescription);
  std::fprintf(f, "  -h,--help         Print this help message and exit\n"
                  "  -q,--quiet        Print only warnings and errors on stderr (no progress, no conventions)\n"
                  "  -v,--verbose      Also print debug messages on stderr\n"
                  "  --version         Display program version information and exit\n\nSubcommands:\n");
  for (const auto& s : kSubcommands) std::fprintf(f, "  %-10s %s\n", s.name, s.summary);
  std::fprintf(f, "\nRun 'evio SUBCOMMAND --help' for a subcommand's options.\n");
}

void print_subcommands(FILE* f) {
  std::fprintf(f, "the subcommands are:");
  for (const auto& s : kSubcommands) std::fprintf(f, " %s", s.name);
  std::fprintf(f, "\nRun 'evio --help' or 'evio SUBCOMMAND --help' for more information.\n");
}

}  // namespace

int main(int argc, char** argv) {
  bool help = false;
  int sub = 0;  // index of the subcommand in argv
  for (int i = 1; i < argc && sub == 0; ++i) {
    const std::string a = argv[i];
    if (a == "--version") {
      std::printf("%s\n", evio::apps::kVersion);
      return 0;
    }
    if (a == "-h" || a == "--help") {
      help = true;
    } else if (a == "-q" || a == "--quiet" || a == "-v" || a == "--verbose") {
      // global flags: passed on to the subcommand, which applies them
    } else if (!a.empty() && a[0] == '-') {
      std::fprintf(stderr, "evio: unknown option '%s' before the subcommand; ", a.c_str());
      print_subcommands(stderr);
      return 2;
    } else {
      sub = i;
    }
  }
  if (sub == 0) {
    if (help) {
      print_help(stdout);
      return 0;
    }
    std::fprintf(stderr, "evio: a subcommand is required; ");
    print_subcommands(stderr);
    return 2;
  }

  const std::string name = argv[sub];
  if (evio::apps::subcommand_summary(name.c_str()) == nullptr) {
    // A mistyped subcommand: name it, suggest the closest within 2 edits, list the real ones.
    std::string closest;
    size_t best = 3;
    for (const auto& s : kSubcommands) {
      const size_t d = edit_distance(name, s.name);
      if (d < best) best = d, closest = s.name;
    }
    std::fprintf(stderr, "evio: unknown subcommand '%s'%s; ", name.c_str(),
                 closest.empty() ? "" : (" (did you mean '" + closest + "'?)").c_str());
    print_subcommands(stderr);
    return 2;
  }

  const std::string dir = evio::executable_dir();
  const std::string program = "evio-" + name;
  std::vector<std::string> tried;
  const std::string beside = dir + "/" + program;                    // build tree
  const std::string installed = dir + "/../libexec/evio/" + program;  // <prefix>/bin/evio
  for (const std::string& candidate : {beside, installed}) {
    if (dir.empty() || access(candidate.c_str(), X_OK) != 0) {
      tried.push_back(candidate);
      continue;
    }
    std::vector<char*> args;
    args.push_back(const_cast<char*>(candidate.c_str()));
    for (int i = 1; i < argc; ++i) {
      if (i != sub) args.push_back(argv[i]);
    }
    args.push_back(nullptr);
    execv(candidate.c_str(), args.data());
    std::fprintf(stderr, "evio: internal error: cannot run %s: %s\n", candidate.c_str(), std::strerror(errno));
    return 3;
  }
  std::fprintf(stderr, "evio: internal error: the program %s is missing (looked for", program.c_str());
  for (const std::string& t : tried) std::fprintf(stderr, " %s", t.c_str());
  std::fprintf(stderr, "); reinstall evio\n");
  return 3;
}
