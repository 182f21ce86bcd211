// evio's plugins: shared modules built with evio (lib<name>.so in <build>/lib/evio, installed to
// <prefix>/lib/evio) that wrap a dependency with a heavy start-up (OpenCV's imgcodecs pulls in
// GDAL and about 140 shared libraries, PCL's I/O pulls in VTK) behind plain C entry points. The
// code that needs one opens it at its first use, so programs that never call it do not load the
// dependency at start-up.
#pragma once

#include <string>

namespace evio {

// The plugin `file` (e.g. "libevio_pcl_io.so"), opened once per process (later calls return the
// same handle). Looked for in $EVIO_PLUGIN_DIR alone when it is set; else in
// <executable>/../lib/evio and <executable>/../../lib/evio (bin/ and libexec/evio/ of an installed
// tree, apps/ of the build tree), then the configured install folder, then the build tree. Throws std::runtime_error naming
// every place tried (or dlopen's message) when it cannot be opened.
void* open_plugin(const std::string& file);

// The folder of the running executable (from /proc/self/exe), or "" when unknown.
std::string executable_dir();

// The symbol `name` of a plugin opened by open_plugin; throws std::runtime_error when missing.
void* plugin_symbol(void* handle, const std::string& file, const char* name);

}  // namespace evio
