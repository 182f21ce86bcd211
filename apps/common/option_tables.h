// The config table (yaml_config::Table) of each library options struct a command's --config can
// set: one declaration of its YAML keys, types, ranges and units, shared by `evio corners`,
// `evio vio` and `evio mosaic` (each composes these into its own config's table in
// <name>_command.cc). Keys are the struct's fields in YAML spelling; durations held in ns (or s)
// are written in ms under keys ending in _ms.
#pragma once

#include "evio/backend/initialization.h"
#include "evio/backend/sliding_window_estimator.h"
#include "evio/calib/calibration_io.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/frontend/event_frame.h"
#include "evio/frontend/feature_tracker.h"
#include "evio/frontend/rotation_particle_filter.h"
#include "evio/mapping/cmax.h"
#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/mosaic_image.h"
#include "evio/mapping/rotation_relocalization.h"
#include "evio/pipeline/cmax_windows.h"
#include "evio/sensors/config_table.h"

namespace evio::apps {

// option_tables_events.cc, option_tables_frames.cc, option_tables_rotation.cc (one file per group, so
// a program links only the modules whose tables it uses)
const yaml_config::Table<frontend::RefractoryFilterOptions>& refractory_table();           // period_ms, per_polarity
const yaml_config::Table<frontend::BackgroundActivityFilterOptions>& background_activity_table();  // window_ms, radius, min_support
const yaml_config::Table<frontend::EfastOptions>& efast_table();
const yaml_config::Table<frontend::CornerTrackerOptions>& corner_tracker_table();
const yaml_config::Table<frontend::DartOptions>& dart_table();
const yaml_config::Table<frontend::EventFrameOptions>& event_frame_table();
const yaml_config::Table<frontend::FeatureTrackerOptions>& feature_tracker_table();
// Without probe_every_batches / probe_offset_rad (the mosaic's failure section holds them).
const yaml_config::Table<frontend::RotationParticleFilterOptions>& rotation_particle_filter_table();

// option_tables_backend.cc and option_tables_mapping.cc
const yaml_config::Table<calib::ImuNoise>& imu_noise_table();  // Kalibr's imu0 densities
const yaml_config::Table<backend::SlidingWindowOptions>& sliding_window_table();
const yaml_config::Table<backend::StaticInitOptions>& static_init_table();
const yaml_config::Table<backend::VisualInertialInitOptions>& visual_inertial_init_table();
// GradientMosaicOptions with its Poisson solvers' keys (weight_floor, pcg_*, poisson_boundary, ...).
const yaml_config::Table<mapping::GradientMosaicOptions>& gradient_mosaic_table();
const yaml_config::Table<mapping::RotationalCmaxOptions>& rotational_cmax_table();
// Every warp model by its name (mapping::warp_models()), for the choice keys that take one.
std::vector<std::pair<std::string, mapping::WarpModel>> warp_model_choices();
// CmaxOptions (mapping/cmax.h): model, objective, IWE size, blur, pyramid, BFGS stopping, pinhole, 6dof depth/plane.
const yaml_config::Table<mapping::CmaxOptions>& cmax_table();
// events, duration_ms, max_duration_ms, min_events, undistortion, dither_px
const yaml_config::Table<pipeline::CmaxWindowOptions>& cmax_window_table();
const yaml_config::Table<mapping::RotationRelocalizationOptions>& relocalization_table();
const yaml_config::Table<mapping::LogImageDisplayOptions>& log_image_display_table();

// The event filters' sections of a command config C (members refractory_enabled, refractory,
// background_activity_enabled, background_activity): `enabled` plus the filter's keys; a section
// that is there turns its filter on unless it says `enabled: false`.
template <class C>
yaml_config::Table<C> refractory_section() {
  yaml_config::Table<C> t("refractory settings");
  t.boolean("enabled", &C::refractory_enabled)
      .include(refractory_table(), &C::refractory)
      .on_present([](C& c) { c.refractory_enabled = true; });
  return t;
}
template <class C>
yaml_config::Table<C> background_activity_section() {
  yaml_config::Table<C> t("background-activity settings");
  t.boolean("enabled", &C::background_activity_enabled)
      .include(background_activity_table(), &C::background_activity)
      .on_present([](C& c) { c.background_activity_enabled = true; });
  return t;
}

}  // namespace evio::apps
