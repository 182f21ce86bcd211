// Config tables of the event filters, eFAST, the corner tracker and DART (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

const Table<frontend::RefractoryFilterOptions>& refractory_table() {
  using O = frontend::RefractoryFilterOptions;
  static const Table<O> t = Table<O>("refractory settings")
                                .duration_ms("period_ms", &O::period_ns, Range::kNonNegative)
                                .boolean("per_polarity", &O::per_polarity)
                                .validate();
  return t;
}

const Table<frontend::BackgroundActivityFilterOptions>& background_activity_table() {
  using O = frontend::BackgroundActivityFilterOptions;
  static const Table<O> t = Table<O>("background-activity settings")
                                .duration_ms("window_ms", &O::window_ns, Range::kPositive)
                                .integer("radius", &O::radius, 1, 3)
                                .integer("min_support", &O::min_support, 1, 48)
                                .validate();
  return t;
}

const Table<frontend::EfastOptions>& efast_table() {
  using O = frontend::EfastOptions;
  static const Table<O> t = Table<O>("eFAST settings")
                                .boolean("filter_sae", &O::filter_sae)
                                .duration_ms("filter_window_ms", &O::filter_window_ns, Range::kNonNegative)
                                .validate();
  return t;
}

const Table<frontend::CornerTrackerOptions>& corner_tracker_table() {
  using O = frontend::CornerTrackerOptions;
  static const Table<O> t =
      Table<O>("corner tracker settings")
          .number("max_distance_px", &O::max_distance_px, Range::kPositive, "px")
          .duration_ms("max_gap_ms", &O::max_gap_ns, Range::kPositive)
          .number("position_gain", &O::position_gain, Range::kUnit, "")
          .duration_ms("velocity_window_ms", &O::velocity_window_ns, Range::kPositive)
          .duration_ms("min_velocity_span_ms", &O::min_velocity_span_ns, Range::kPositive)
          .integer("min_length", &O::min_length, 1, 1000000)
          .number("descriptor_ratio", &O::descriptor_ratio, Range::kUnit, "")
          .number("max_descriptor_distance", &O::max_descriptor_distance, Range::kNonNegative,
                  "DART distance, 0..1.414", /*allow_infinity=*/true)
          .validate();
  return t;
}

const Table<frontend::DartOptions>& dart_table() {
  using O = frontend::DartOptions;
  using frontend::DartBinning;
  using frontend::DartNormalisation;
  using frontend::DartPolarity;
  using frontend::DartWeighting;
  static const Table<O> t =
      Table<O>("DART settings")
          .duration_ms("window_ms", &O::window_ns, Range::kNonNegative)
          .integer("rings", &O::rings, 1, frontend::kDartMaxRings)
          .integer("wedges", &O::wedges, 1, frontend::kDartMaxWedges)
          .number("inner_radius_px", &O::inner_radius_px, Range::kPositive, "px")
          .number("outer_radius_px", &O::outer_radius_px, Range::kPositive, "px")
          .choice("polarity", &O::polarity, {{"both", DartPolarity::kBoth}, {"same", DartPolarity::kSame}})
          .choice("normalisation", &O::normalisation,
                  {{"none", DartNormalisation::kNone}, {"l1", DartNormalisation::kL1}, {"l2", DartNormalisation::kL2}})
          .choice("weighting", &O::weighting, {{"count", DartWeighting::kCount}, {"density", DartWeighting::kDensity}})
          .choice("binning", &O::binning, {{"hard", DartBinning::kHard}, {"soft", DartBinning::kSoft}})
          .integer("max_ring_shift", &O::max_ring_shift, 0, frontend::kDartMaxRings - 1)
          .boolean("half_wedge_shifts", &O::half_wedge_shifts)
          .validate();
  return t;
}

}  // namespace evio::apps
