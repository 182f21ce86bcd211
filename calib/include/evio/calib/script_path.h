// Where evio's Python scripts (scripts/*.py: plots, checks) are: next to the sources in a build
// tree, else <prefix>/share/evio/scripts when installed.
#pragma once

#include <string>

namespace evio {

// given when not empty; else the first existing of <source>/scripts/<name> and
// <prefix>/share/evio/scripts/<name> (prefix from /proc/self/exe); empty when none exists.
std::string find_evio_script(const std::string& name, const std::string& given = {});

}  // namespace evio
