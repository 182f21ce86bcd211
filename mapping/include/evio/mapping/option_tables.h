// The config tables (yaml_config::Table, sensors/config_table.h) of the mapping module's options
// structs: for each YAML key the field it sets, its type, range and unit, declared once. Each
// struct's Validate checks its fields against its table (Table::check) and adds only the
// conditions between fields; `evio` composes the tables into its commands' configs. Keys are the
// fields in YAML spelling; durations are written in ms under keys ending in _ms.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "evio/mapping/cmax.h"
#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/mosaic_image.h"
#include "evio/mapping/poisson.h"
#include "evio/mapping/rotation_relocalization.h"
#include "evio/mapping/weighted_poisson.h"
#include "evio/sensors/config_table.h"

namespace evio::mapping {

const yaml_config::Table<PoissonOptions>& poisson_table();                   // boundary, max_region_side
const yaml_config::Table<WeightedPoissonOptions>& weighted_poisson_table();  // weight_floor, tolerance, max_iterations, preconditioner
// GradientMosaicOptions with its Poisson solvers' keys: poisson_boundary, poisson_max_region_side,
// weight_floor, pcg_tolerance, pcg_max_iterations, pcg_preconditioner.
const yaml_config::Table<GradientMosaicOptions>& gradient_mosaic_table();
const yaml_config::Table<RotationalCmaxOptions>& rotational_cmax_table();
// Every warp model by its name (warp_models()), for the choice keys that take one.
std::vector<std::pair<std::string, WarpModel>> warp_model_choices();
const yaml_config::Table<WarpGeometry>& warp_geometry_table();  // fx, fy, cx, cy, depth_m, plane_normal, plane_distance_m
// CmaxOptions: model, objective, IWE size, blur, pyramid, BFGS stopping, and the warp geometry's keys.
const yaml_config::Table<CmaxOptions>& cmax_table();
const yaml_config::Table<RotationRelocalizationOptions>& relocalization_table();
const yaml_config::Table<LogImageDisplayOptions>& log_image_display_table();

}  // namespace evio::mapping
