// Config tables of the mapping module's options structs (option_tables.h).
#include "evio/mapping/option_tables.h"

namespace evio::mapping {

using yaml_config::Interval;
using yaml_config::Range;
using yaml_config::Table;

// The solver tables have no validate(): they are read as part of the gradient mosaic's, whose
// Validate covers them.
const Table<PoissonOptions>& poisson_table() {
  using O = PoissonOptions;
  static const Table<O> t = Table<O>("Poisson settings")
                                .choice("boundary", &O::boundary,
                                        {{"periodic_u", PoissonBoundary::kPeriodicU}, {"neumann", PoissonBoundary::kNeumann}})
                                .integer("max_region_side", &O::max_region_side, 1, 1 << 15);
  return t;
}

const Table<WeightedPoissonOptions>& weighted_poisson_table() {
  using O = WeightedPoissonOptions;
  static const Table<O> t = Table<O>("weighted Poisson settings")
                                .number("weight_floor", &O::weight_floor, Interval::open_closed(0, 1), "")
                                .number("tolerance", &O::tolerance, Interval::open(0, 1), "")
                                .integer("max_iterations", &O::max_iterations, 0, 1000000)
                                .choice("preconditioner", &O::preconditioner,
                                        {{"none", PoissonPreconditioner::kNone},
                                         {"jacobi", PoissonPreconditioner::kJacobi},
                                         {"spectral", PoissonPreconditioner::kSpectral},
                                         {"scaled_spectral", PoissonPreconditioner::kScaledSpectral}});
  return t;
}

const Table<GradientMosaicOptions>& gradient_mosaic_table() {
  using O = GradientMosaicOptions;
  static const Table<O> t =
      Table<O>("mosaic settings")
          .integer("width", &O::width, 8, 1 << 15)
          .integer("height", &O::height, 4, 1 << 14)
          .number("contrast_threshold", &O::contrast_threshold, Range::kPositive, "log units")
          .number("initial_gradient_std", &O::initial_gradient_std, Range::kPositive, "log units/px")
          .number("measurement_std_abs", &O::measurement_std_abs, Range::kNonNegative, "1/s")
          .number("measurement_relative_std", &O::measurement_relative_std, Range::kNonNegative, "")
          .seconds_as_ms("min_tau_ms", &O::min_tau_s, Range::kPositive)
          .number("min_speed_px_s", &O::min_speed_px_s, Range::kNonNegative, "px/s")
          .number("min_gradient_std", &O::min_gradient_std, Range::kPositive, "log units/px")
          .integer("seen_min_observations", &O::seen_min_observations, 1, 1000000)
          .number("seen_max_gradient_std", &O::seen_max_gradient_std, Range::kNonNegative, "log units/px")
          .number("max_path_px", &O::max_path_px, Range::kPositive, "mosaic px")
          .boolean("map_viewed_texels", &O::map_viewed_texels)
          .number("weight_reference_std", &O::weight_reference_std, Range::kPositive, "log units/px")
          .number("viewed_edge_weight", &O::viewed_edge_weight, Range::kUnit, "")
          .include(poisson_table(), &O::poisson, {}, "poisson_")
          .include(weighted_poisson_table(), &O::weighted_poisson, {"tolerance", "max_iterations", "preconditioner"})
          .include(weighted_poisson_table(), &O::weighted_poisson, {"weight_floor"}, "pcg_")
          .validate();
  return t;
}

const Table<RotationalCmaxOptions>& rotational_cmax_table() {
  using O = RotationalCmaxOptions;
  static const Table<O> t = Table<O>("contrast maximisation settings")
                                .integer("width", &O::width, 1, 1 << 15)
                                .integer("height", &O::height, 1, 1 << 15)
                                .number("focal_px", &O::focal_px, Range::kPositive, "px")
                                .number("blur_px", &O::blur_sigma_px, Range::kPositive, "px")
                                .number("coarse_blur_factor", &O::coarse_blur_factor, Interval::at_least(1), "")
                                .number("initial_step_radps", &O::initial_step_radps, Range::kPositive, "rad/s")
                                .number("min_step_radps", &O::min_step_radps, Range::kPositive, "rad/s")
                                .integer("max_evaluations", &O::max_evaluations, 10, 100000000)
                                .validate();
  return t;
}

std::vector<std::pair<std::string, WarpModel>> warp_model_choices() {
  std::vector<std::pair<std::string, WarpModel>> out;
  for (WarpModel m : warp_models()) out.emplace_back(warp_model_name(m), m);
  return out;
}

const Table<WarpGeometry>& warp_geometry_table() {
  using O = WarpGeometry;
  // No validate(): read as part of the contrast maximisation's table, whose Validate covers it.
  static const Table<O> t =
      Table<O>("warp geometry settings")
          .number("fx", &O::fx, Range::kPositive, "px")
          .number("fy", &O::fy, Range::kPositive, "px")
          .number("cx", &O::cx, Range::kAny, "px")
          .number("cy", &O::cy, Range::kAny, "px")
          .number("depth_m", &O::depth_m, Range::kPositive, "m")
          .vector3("plane_normal", &O::plane_normal_c, "camera frame")
          .number("plane_distance_m", &O::plane_distance_m, Range::kNonNegative, "m")
          .note("plane_distance_m", "6dof: > 0 uses the plane n.X = distance instead of depth_m");
  return t;
}

const Table<CmaxOptions>& cmax_table() {
  using O = CmaxOptions;
  static const Table<O> t =
      Table<O>("contrast maximisation settings")
          .choice("model", &O::model, warp_model_choices())
          .choice("objective", &O::objective,
                  {{"auto", CmaxObjective::kAuto},
                   {"variance", CmaxObjective::kVariance},
                   {"mean_square", CmaxObjective::kMeanSquare},
                   {"gradient_magnitude", CmaxObjective::kGradientMagnitude},
                   {"normalized_gradient_magnitude", CmaxObjective::kNormalizedGradientMagnitude}})
          .note("objective", "auto: variance for flow and flow_accel, gradient_magnitude for rotation, normalized_gradient_magnitude for similarity, similarity_accel and 6dof")
          .integer("width", &O::width, 1, 100000)
          .integer("height", &O::height, 1, 100000)
          .number("blur_sigma_px", &O::blur_sigma_px, Interval::closed(0, 50), "px of each pyramid level")
          .boolean("use_polarity", &O::use_polarity)
          .integer("pyramid_levels", &O::pyramid_levels, 1, 8)
          .integer("max_iterations", &O::max_iterations, 1, 1000000)
          .number("tolerance_px", &O::tolerance_px, Range::kPositive, "px")
          .number("coarse_tolerance_px", &O::coarse_tolerance_px, Range::kPositive, "px of each coarse level")
          .integer("max_events_coarse", &O::max_events_coarse, 0, 1000000000)
          .note("max_events_coarse", "0: all events on every level")
          .include(warp_geometry_table(), &O::geometry)
          .validate();
  return t;
}

const Table<RotationRelocalizationOptions>& relocalization_table() {
  using O = RotationRelocalizationOptions;
  static const Table<O> t = Table<O>("relocalisation settings")
                                .number("axis_spacing_deg", &O::axis_spacing_deg, Range::kPositive, "deg")
                                .number("roll_step_deg", &O::roll_step_deg, Range::kPositive, "deg")
                                .integer("coarse_bearings", &O::coarse_bearings, 1, 1000000)
                                .integer("fine_bearings", &O::fine_bearings, 1, 10000000)
                                .number("coarse_blur_texels", &O::coarse_blur_texels, Range::kNonNegative, "texels")
                                .number("fine_blur_texels", &O::fine_blur_texels, Range::kNonNegative, "texels")
                                .integer("refine_candidates", &O::refine_candidates, 1, 100000)
                                .number("refine_initial_step_deg", &O::refine_initial_step_deg, Range::kPositive, "deg")
                                .number("refine_final_step_deg", &O::refine_final_step_deg, Range::kPositive, "deg")
                                .validate();
  return t;
}

const Table<LogImageDisplayOptions>& log_image_display_table() {
  using O = LogImageDisplayOptions;
  static const Table<O> t = Table<O>("display settings")
                                .number("gamma", &O::gamma, Range::kPositive, "")
                                .number("low_percentile", &O::low_percentile, Interval::closed_open(0, 100), "%")
                                .number("high_percentile", &O::high_percentile, Interval::open_closed(0, 100), "%")
                                .boolean("linear_intensity", &O::linear_intensity)
                                .boolean("transparent_unseen", &O::transparent_unseen)
                                .number("equalize_clip", &O::equalize_clip, Range::kNonNegative, "CLAHE clip limit")
                                .integer("equalize_tile_px", &O::equalize_tile_px, 8, 65536)
                                .validate();
  return t;
}

}  // namespace evio::mapping
