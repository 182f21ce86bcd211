// The config tables (sensors/config_table.h; the library's in evio/frontend/option_tables.h and
// evio/mapping/option_tables.h, the rest in apps/option_tables.h): one declaration per key drives
// reading, validation, --set overrides and the resolved config of `evio vio`, `evio mosaic` and
// `evio corners`; the resolved config lists every key and reads back to the same config; the
// options structs' Validate and the YAML reader reject the same out-of-range values.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "corners_command.h"
#include "evio/calib/error.h"
#include "evio/frontend/option_tables.h"
#include "evio/mapping/option_tables.h"
#include "evio/sensors/config_table.h"
#include "evio_test/temp_dir.h"
#include "mosaic_command.h"
#include "option_tables.h"
#include "vio_command.h"

namespace evio::apps {
namespace {

// The InputError message of f(), or "" when it does not throw.
template <class F>
std::string error_of(F f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return {};
}

std::string write(const evio_test::TempDir& dir, const std::string& name, const std::string& text) {
  const std::string p = dir.file(name);
  std::ofstream(p) << text;
  return p;
}

TEST(ConfigTable, NumbersAreWrittenShortestAndReadBackExactly) {
  using yaml_config::yaml_number;
  EXPECT_EQ(yaml_number(0.1), "0.1");
  EXPECT_EQ(yaml_number(1e-6), "1e-06");
  EXPECT_EQ(yaml_number(1.345), "1.345");
  EXPECT_EQ(yaml_number(10), "10");
  EXPECT_EQ(yaml_number(std::numeric_limits<double>::infinity()), ".inf");
  for (double v : {0.8838834764831844, 2.0 / 3.0, 1e-300, 123456789.123, -9.81}) {
    EXPECT_EQ(std::strtod(yaml_number(v).c_str(), nullptr), v) << yaml_number(v);
  }
}

TEST(ConfigTable, VioResolvedConfigListsEveryKeyAndReadsBack) {
  evio_test::TempDir dir;
  const std::string text = vio_config_text(default_vio_config());
  // Keys the per-command writers used to leave out, and one of each section.
  for (const char* key : {"per_polarity:", "min_window_ms: 10 ", "keep_accumulator:", "ransac_max_iterations:",
                          "border_px:", "min_velocity_span_ms:", "max_descriptor_distance: .inf", "min_bearing_z:",
                          "lookahead_ms:", "imu_history_ms:", "\n  static:\n", "\n  alignment:\n", "gravity_w: [0, 0, -9.81]",
                          "rotation_only_gric_margin:", "tracking_lost_min_tracks:", "klt_window_px: 27 "}) {
    EXPECT_NE(text.find(key), std::string::npos) << key << "\n" << text;
  }
  // Every value line carries its unit and range.
  EXPECT_NE(text.find("events_per_frame: 15000"), std::string::npos);
  EXPECT_NE(text.find("# ms, >= 0"), std::string::npos);
  EXPECT_NE(text.find("# huber | cauchy | none"), std::string::npos);
  std::string again;
  const VioConfig c = load_vio_config(write(dir, "vio.yaml", text), &again);
  EXPECT_EQ(again, text);
  EXPECT_EQ(c.frames.min_window_ns, pipeline::VioPipelineOptions{}.frames.min_window_ns);  // the library's default
}

TEST(ConfigTable, MosaicAndCornersResolvedConfigsReadBack) {
  evio_test::TempDir dir;
  const std::string m = mosaic_config_text(default_mosaic_config());
  for (const char* key : {"global_axis_spacing_deg:", "global_refine_candidates:", "poisson_boundary: periodic_u",
                          "coarse_blur_factor:", "outlier_range:", "linear_intensity:", "\nimu:\n  wait_ms: 1000 "}) {
    EXPECT_NE(m.find(key), std::string::npos) << key << "\n" << m;
  }
  std::string m2;
  load_mosaic_config(write(dir, "mosaic.yaml", m), &m2);
  EXPECT_EQ(m2, m);

  const std::string c = corners_config_text(CornersConfig{});
  for (const char* key : {"per_polarity:", "half_wedge_shifts:", "track_history_ms: 100 "}) {
    EXPECT_NE(c.find(key), std::string::npos) << key << "\n" << c;
  }
  EXPECT_EQ(corners_config_text(load_corners_config(write(dir, "corners.yaml", c))), c);
}

TEST(ConfigTable, SetOverridesApplyAfterTheFileAndErrorsNameThem) {
  evio_test::TempDir dir;
  const std::string file = write(dir, "v.yaml", "frames:\n  events_per_frame: 8000\nwindow: {size: 6}\n");
  const VioConfig c = load_vio_config(file, nullptr, {"frames.events_per_frame=20000", "filters.refractory.per_polarity=true"});
  EXPECT_EQ(c.frames.events_per_frame, 20000);  // --set wins over the file
  EXPECT_EQ(c.window.window_size, 6);
  EXPECT_TRUE(c.refractory.per_polarity);
  EXPECT_TRUE(c.refractory_enabled);
  // Without a file.
  EXPECT_EQ(load_mosaic_config("", nullptr, {"tracker.particles=250"}).tracker.num_particles, 250);
  EXPECT_TRUE(load_corners_config("", {"efast.filter_sae=true"}).efast.filter_sae);

  std::string e = error_of([&] { load_vio_config(file, nullptr, {"frames.evnts=3"}); });
  EXPECT_NE(e.find("--set frames.evnts=3"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'evnts'"), std::string::npos) << e;
  e = error_of([&] { load_vio_config("", nullptr, {"window.size=1"}); });
  EXPECT_NE(e.find("--set window.size=1"), std::string::npos) << e;
  EXPECT_NE(e.find("an integer in [2, 200]"), std::string::npos) << e;
  e = error_of([&] { load_mosaic_config("", nullptr, {"tracker.motion_model=teleport"}); });
  EXPECT_NE(e.find("'teleport' is not allowed"), std::string::npos) << e;
  EXPECT_NE(e.find("random_walk | constant_velocity | particle_velocity"), std::string::npos) << e;
  e = error_of([&] { load_corners_config("", {"efast"}); });
  EXPECT_NE(e.find("no '=' after the key"), std::string::npos) << e;
}

TEST(ConfigTable, FileErrorsGiveFileLineKeyAndExpectedForm) {
  evio_test::TempDir dir;
  const std::string typo = write(dir, "typo.yaml", "frames:\n  events_per_frame: 1000\n  evnts: 3\n");
  std::string e = error_of([&] { load_vio_config(typo); });
  EXPECT_NE(e.find("typo.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("frames.evnts: unknown key 'evnts'"), std::string::npos) << e;
  EXPECT_NE(e.find("events_per_frame"), std::string::npos) << e;  // the allowed keys are listed

  const std::string range = write(dir, "range.yaml", "window:\n  size: 6\n  pixel_sigma: -1\n");
  e = error_of([&] { load_vio_config(range); });
  EXPECT_NE(e.find("range.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("window.pixel_sigma"), std::string::npos) << e;
  EXPECT_NE(e.find("expected: a number > 0 (px)"), std::string::npos) << e;

  // The struct's Validate runs on the section: min window above max window.
  const std::string invalid = write(dir, "invalid.yaml", "frames: {min_window_ms: 100, max_window_ms: 50}\n");
  e = error_of([&] { load_vio_config(invalid); });
  EXPECT_NE(e.find("invalid.yaml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("invalid frame settings"), std::string::npos) << e;

  // One table for the shared structs: the same keys and checks in corners and vio.
  const std::string ba = write(dir, "ba.yaml", "background_activity: {radius: 1, min_support: 9}\n");
  e = error_of([&] { load_corners_config(ba); });
  EXPECT_NE(e.find("invalid background-activity settings"), std::string::npos) << e;
  const std::string ba_vio = write(dir, "ba_vio.yaml", "filters:\n  background_activity: {radius: 1, min_support: 9}\n");
  e = error_of([&] { load_vio_config(ba_vio); });
  EXPECT_NE(e.find("invalid background-activity settings"), std::string::npos) << e;
}

TEST(ConfigTable, SectionsThatArePresentEnableTheirFilter) {
  evio_test::TempDir dir;
  const CornersConfig on = load_corners_config(write(dir, "r.yaml", "refractory: {period_ms: 2}\n"));
  EXPECT_TRUE(on.refractory_enabled);
  EXPECT_EQ(on.refractory.period_ns, 2'000'000);
  const CornersConfig off = load_corners_config(write(dir, "r0.yaml", "refractory: {enabled: false, period_ms: 2}\n"));
  EXPECT_FALSE(off.refractory_enabled);
  EXPECT_FALSE(CornersConfig{}.refractory_enabled);
}

TEST(ConfigTable, ShippedConfigsLoadAndReadBackFromTheirResolvedForm) {
  evio_test::TempDir dir;
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(EVIO_SOURCE_DIR) + "/datasets/vio")) {
    if (entry.path().extension() != ".yaml") continue;
    std::string resolved;
    const VioConfig c = load_vio_config(entry.path().string(), &resolved);
    std::string again;
    load_vio_config(write(dir, "r.yaml", resolved), &again);
    EXPECT_EQ(again, resolved) << entry.path();
    EXPECT_EQ(vio_config_text(c), resolved);
    ++n;
  }
  EXPECT_GE(n, 3);
}

// For every numeric key of `table` and each finite end of its range: a value just outside (the
// bound itself when the end is open, one step beyond when closed) is rejected by the YAML reader
// and by O::Validate, both naming the key; the bound itself, when closed, passes the table's
// check. The library defaults pass Validate. This keeps the ranges in one place: Validate has no
// range of its own that the table could drift from.
template <class O>
void expect_one_range_per_key(const yaml_config::Table<O>& table, const std::string& name) {
  SCOPED_TRACE(name);
  std::string why;
  EXPECT_TRUE(O{}.Validate(&why)) << why;
  const auto keys = table.numeric_keys();
  EXPECT_FALSE(keys.empty());
  int probed = 0;
  for (const auto& k : keys) {
    for (const int side : {-1, +1}) {
      const double bound = side < 0 ? k.range.lo() : k.range.hi();
      if (!std::isfinite(bound)) continue;
      const bool open = side < 0 ? k.range.lo_open() : k.range.hi_open();
      const double step = k.step > 0 ? k.step : (std::abs(bound) + 1) * 1e-9;
      const double outside = open ? bound : bound + side * step;
      const std::string text = yaml_config::yaml_number(outside);
      SCOPED_TRACE(k.key + " = " + text);

      const std::string e = error_of([&] { yaml_config::read_config(table, O{}, "", {k.key + "=" + text}, "test"); });
      EXPECT_NE(e.find(k.key + ": "), std::string::npos) << e;

      O o;
      ASSERT_TRUE(k.set(o, outside));
      why.clear();
      EXPECT_FALSE(o.Validate(&why));
      EXPECT_NE(why.find(k.key + ": is out of range"), std::string::npos) << why;

      if (!open) {
        O at;
        ASSERT_TRUE(k.set(at, bound));
        EXPECT_TRUE(table.check(at, &why)) << why;
      }
      ++probed;
    }
  }
  EXPECT_GT(probed, 0);
}

TEST(ConfigTable, ValidateAndTheReaderRejectTheSameValues) {
  expect_one_range_per_key(frontend::refractory_table(), "refractory");
  expect_one_range_per_key(frontend::background_activity_table(), "background_activity");
  expect_one_range_per_key(frontend::efast_table(), "efast");
  expect_one_range_per_key(frontend::corner_tracker_table(), "corner_tracker");
  expect_one_range_per_key(frontend::dart_table(), "dart");
  expect_one_range_per_key(frontend::event_frame_table(), "event_frame");
  expect_one_range_per_key(frontend::feature_tracker_table(), "feature_tracker");
  expect_one_range_per_key(frontend::rotation_particle_filter_table(), "rotation_particle_filter");
  expect_one_range_per_key(mapping::poisson_table(), "poisson");
  expect_one_range_per_key(mapping::weighted_poisson_table(), "weighted_poisson");
  expect_one_range_per_key(mapping::gradient_mosaic_table(), "gradient_mosaic");
  expect_one_range_per_key(mapping::rotational_cmax_table(), "rotational_cmax");
  expect_one_range_per_key(mapping::warp_geometry_table(), "warp_geometry");
  expect_one_range_per_key(mapping::cmax_table(), "cmax");
  expect_one_range_per_key(mapping::relocalization_table(), "relocalization");
  expect_one_range_per_key(mapping::log_image_display_table(), "log_image_display");
  expect_one_range_per_key(backend::sliding_window_table(), "sliding_window");
  expect_one_range_per_key(backend::static_init_table(), "static_init");
  expect_one_range_per_key(backend::visual_inertial_init_table(), "visual_inertial_init");
  // The window table's non-numeric key with a range of its own, and the init tables' conditions
  // between fields.
  std::string why;
  backend::SlidingWindowOptions w;
  w.gravity_w.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(w.Validate(&why));
  EXPECT_NE(why.find("gravity_w: is not finite"), std::string::npos) << why;
  backend::StaticInitOptions s;
  s.still_tail_ns = s.window_ns + 1;
  EXPECT_FALSE(s.Validate(&why));
  EXPECT_NE(why.find("still_tail_ms must be at most window_ms"), std::string::npos) << why;
  backend::VisualInertialInitOptions v;
  v.max_tracks = v.min_tracks - 1;
  EXPECT_FALSE(v.Validate(&why));
  EXPECT_NE(why.find("max_tracks must be at least min_tracks"), std::string::npos) << why;
}

TEST(ConfigTable, ValidateNamesTheKeyAsTheReaderDoes) {
  frontend::FeatureTrackerOptions o;
  o.grid_cols = 101;  // the table's cap, which Validate did not have before
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_EQ(why, "grid_cols: is out of range (101) (expected: an integer in [1, 100])");
  const std::string e = error_of([] { load_vio_config("", nullptr, {"tracker.grid_cols=101"}); });
  EXPECT_NE(e.find("tracker.grid_cols: "), std::string::npos) << e;
  EXPECT_NE(e.find("(expected: an integer in [1, 100])"), std::string::npos) << e;
}

TEST(ConfigTable, MosaicDerivedDefaults) {
  evio_test::TempDir dir;
  // height follows width; the tracker's contrast threshold follows the mosaic's unless set.
  const MosaicConfig a = load_mosaic_config(write(dir, "a.yaml", "mosaic: {width: 512, contrast_threshold: 0.3}\n"));
  EXPECT_EQ(a.mosaic.height, 256);
  EXPECT_DOUBLE_EQ(a.tracker.contrast_threshold, 0.3);
  const MosaicConfig b = load_mosaic_config(
      write(dir, "b.yaml", "mosaic: {width: 512, height: 200, contrast_threshold: 0.3}\ntracker: {contrast_threshold: 0.25}\n"));
  EXPECT_EQ(b.mosaic.height, 200);
  EXPECT_DOUBLE_EQ(b.tracker.contrast_threshold, 0.25);
}

}  // namespace
}  // namespace evio::apps
