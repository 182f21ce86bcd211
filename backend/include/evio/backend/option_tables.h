// The config table (yaml_config::Table, sensors/config_table.h) of the sliding-window estimator's
// options: for each YAML key the field it sets, its type, range and unit, declared once.
// SlidingWindowOptions::Validate checks the fields against it (Table::check) and adds only the
// conditions between fields; `evio vio` reads its `window` section with it. Durations held in s are
// written in ms under keys ending in _ms.
#pragma once

#include "evio/backend/sliding_window_estimator.h"
#include "evio/sensors/config_table.h"

namespace evio::backend {

const yaml_config::Table<SlidingWindowOptions>& sliding_window_table();

}  // namespace evio::backend
