// Config table of the CMax commands' event windows (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

const Table<pipeline::CmaxWindowOptions>& cmax_window_table() {
  using O = pipeline::CmaxWindowOptions;
  static const Table<O> t =
      Table<O>("window settings")
          .integer("events", &O::window_events, 1, 1000000000)
          .duration_ms("duration_ms", &O::window_ns, Range::kNonNegative)
          .note("duration_ms", "0: windows of `events` events; > 0: windows of this duration instead")
          .duration_ms("max_duration_ms", &O::max_window_ns, Range::kNonNegative)
          .note("max_duration_ms", "event windows also close when they span this long; 0: no limit")
          .integer("min_events", &O::min_window_events, 1, 1000000000)
          .choice("undistortion", &O::undistortion,
                  {{"auto", pipeline::CmaxUndistortion::kAuto},
                   {"none", pipeline::CmaxUndistortion::kNone},
                   {"lut", pipeline::CmaxUndistortion::kLut}})
          .note("undistortion", "auto: sub-pixel input as is, integer pixels of a distorted camera through the lookup table")
          .number("dither_px", &O::dither_px, yaml_config::Interval::closed(0, 4), "px")
          .note("dither_px", "integer-pixel input: each event moved by a deterministic offset within this square; 0: off")
          .validate();
  return t;
}

}  // namespace evio::apps
