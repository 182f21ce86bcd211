// The config tables (yaml_config::Table, sensors/config_table.h) of the back-end's options
// structs: for each YAML key the field it sets, its type, range and unit, declared once. Each
// struct's Validate checks its fields against its table (Table::check) and adds only the
// conditions between fields; `evio vio` reads its `window` and `init` sections with them.
// Durations held in s or ns are written in ms under keys ending in _ms.
#pragma once

#include "evio/backend/cmax_slam.h"
#include "evio/backend/initialization.h"
#include "evio/backend/sliding_window_estimator.h"
#include "evio/sensors/config_table.h"

namespace evio::backend {

const yaml_config::Table<SlidingWindowOptions>& sliding_window_table();
const yaml_config::Table<StaticInitOptions>& static_init_table();
const yaml_config::Table<VisualInertialInitOptions>& visual_inertial_init_table();
const yaml_config::Table<CmaxSlamOptions>& cmax_slam_table();

}  // namespace evio::backend
