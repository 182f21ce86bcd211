// The config tables (yaml_config::Table) of the options structs that have no table in their own
// module yet: the IMU noise densities and the CMax commands' event windows
// (pipeline::CmaxWindowOptions); and the event filters' sections of a command config. The
// front-end's, the mapping module's and the back-end's tables live beside their structs
// (evio/frontend/option_tables.h, evio/mapping/option_tables.h, evio/backend/option_tables.h). Each command composes these into
// its own config's table in <name>_command.cc. Keys are the struct's fields in YAML spelling;
// durations held in ns (or s) are written in ms under keys ending in _ms.
#pragma once

#include "evio/backend/option_tables.h"
#include "evio/calib/calibration_io.h"
#include "evio/frontend/option_tables.h"
#include "evio/pipeline/cmax_windows.h"
#include "evio/sensors/config_table.h"

namespace evio::apps {

// option_tables_backend.cc
const yaml_config::Table<calib::ImuNoise>& imu_noise_table();  // Kalibr's imu0 densities
using backend::sliding_window_table;  // evio/backend/option_tables.h
using backend::static_init_table;           // evio/backend/option_tables.h
using backend::visual_inertial_init_table;  // evio/backend/option_tables.h

// option_tables_pipeline.cc: events, duration_ms, max_duration_ms, min_events, undistortion, dither_px
const yaml_config::Table<pipeline::CmaxWindowOptions>& cmax_window_table();

// The event filters' sections of a command config C (members refractory_enabled, refractory,
// background_activity_enabled, background_activity): `enabled` plus the filter's keys; a section
// that is there turns its filter on unless it says `enabled: false`.
template <class C>
yaml_config::Table<C> refractory_section() {
  yaml_config::Table<C> t("refractory settings");
  t.boolean("enabled", &C::refractory_enabled)
      .include(frontend::refractory_table(), &C::refractory)
      .on_present([](C& c) { c.refractory_enabled = true; });
  return t;
}
template <class C>
yaml_config::Table<C> background_activity_section() {
  yaml_config::Table<C> t("background-activity settings");
  t.boolean("enabled", &C::background_activity_enabled)
      .include(frontend::background_activity_table(), &C::background_activity)
      .on_present([](C& c) { c.background_activity_enabled = true; });
  return t;
}

}  // namespace evio::apps
