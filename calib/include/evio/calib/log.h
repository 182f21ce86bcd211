// Minimal logging sink for the library: conventions applied on load, recoverable-input warnings.
// The library never prints to stdout; messages go to a sink that apps can replace (default:
// stderr with a level prefix). Not for per-event use.
#pragma once

#include <functional>
#include <string>

namespace evio {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

using LogSink = std::function<void(LogLevel, const std::string&)>;

// Replaces the sink (thread-safe). Passing an empty function restores the default stderr sink.
void set_log_sink(LogSink sink);
// Messages below this level are dropped (default kInfo).
void set_log_level(LogLevel level);
LogLevel log_level();

void log(LogLevel level, const std::string& message);
inline void log_info(const std::string& m) { log(LogLevel::kInfo, m); }
inline void log_warning(const std::string& m) { log(LogLevel::kWarning, m); }
inline void log_debug(const std::string& m) { log(LogLevel::kDebug, m); }

}  // namespace evio
