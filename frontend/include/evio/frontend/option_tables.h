// The config tables (yaml_config::Table, sensors/config_table.h) of the front-end's options
// structs: for each YAML key the field it sets, its type, range and unit, declared once. Each
// struct's Validate checks its fields against its table (Table::check) and adds only the
// conditions between fields; `evio` composes the tables into its commands' configs. Keys are the
// fields in YAML spelling; durations held in ns are written in ms under keys ending in _ms.
#pragma once

#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/frontend/event_frame.h"
#include "evio/frontend/feature_tracker.h"
#include "evio/frontend/rotation_particle_filter.h"
#include "evio/sensors/config_table.h"

namespace evio::frontend {

const yaml_config::Table<RefractoryFilterOptions>& refractory_table();                   // period_ms, per_polarity
const yaml_config::Table<BackgroundActivityFilterOptions>& background_activity_table();  // window_ms, radius, min_support
const yaml_config::Table<EfastOptions>& efast_table();
const yaml_config::Table<CornerTrackerOptions>& corner_tracker_table();
const yaml_config::Table<DartOptions>& dart_table();
const yaml_config::Table<EventFrameOptions>& event_frame_table();
const yaml_config::Table<FeatureTrackerOptions>& feature_tracker_table();
// Every key, the tracking-quality probes' (rotation_probe_table) last.
const yaml_config::Table<RotationParticleFilterOptions>& rotation_particle_filter_table();
// probe_every_batches, probe_offset_rad: `evio mosaic` sets them in its failure section.
const yaml_config::Table<RotationParticleFilterOptions>& rotation_probe_table();

}  // namespace evio::frontend
