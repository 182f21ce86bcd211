// Tests of the ESIM-style event generator: exact crossing times on log-linear ramps, several
// crossings per interval with asymmetric thresholds, the one-threshold tracking bound under
// mismatch and jumps, refractory rule, noise statistics (shot, leak, hot pixels), jitter,
// ordering, determinism and 1.7e18 ns timestamps.
#include "evio/simulator/events.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <stdexcept>
#include <vector>

namespace evio::simulator {
namespace {

constexpr double kEps = 1e-3;
constexpr int64_t kBigBase = 1'700'000'000'123'456'789LL;

// Intensity whose log(I + eps) equals `log_level` (up to float rounding of I).
float intensity_for(double log_level) { return static_cast<float>(std::exp(log_level) - kEps); }

double log_of(float intensity) { return std::log(static_cast<double>(intensity) + kEps); }

int pixel_of(const Event& e, int width) { return e.y * width + e.x; }

// Checks the documented order: time, then pixel index, then ON before OFF.
void expect_sorted(const std::vector<Event>& ev, int width) {
  for (size_t k = 1; k < ev.size(); ++k) {
    const Event& a = ev[k - 1];
    const Event& b = ev[k];
    const bool ok = a.t_ns < b.t_ns ||
                    (a.t_ns == b.t_ns && (pixel_of(a, width) < pixel_of(b, width) ||
                                          (pixel_of(a, width) == pixel_of(b, width) && a.polarity >= b.polarity)));
    ASSERT_TRUE(ok) << "events " << k - 1 << " and " << k << " out of order";
  }
}

std::map<int, std::vector<Event>> by_pixel(const std::vector<Event>& ev, int width) {
  std::map<int, std::vector<Event>> m;
  for (const Event& e : ev) m[pixel_of(e, width)].push_back(e);
  return m;
}

TEST(SimEvents, OptionsValidate) {
  EventSimOptions o;
  std::string why;
  EXPECT_TRUE(o.Validate(&why)) << why;
  o.contrast_threshold_neg = 0;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("contrast_threshold_neg"), std::string::npos);
  o = EventSimOptions();
  o.hot_pixel_fraction = 1.5;
  EXPECT_FALSE(o.Validate(&why));
  o = EventSimOptions();
  o.refractory_ns = -1;
  EXPECT_FALSE(o.Validate(&why));
  o = EventSimOptions();
  o.shot_noise_rate_hz = std::nan("");
  EXPECT_FALSE(o.Validate(&why));
  o = EventSimOptions();
  o.threshold_min = 0;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_THROW(EventGenerator(8, 8, o), std::invalid_argument);
  EXPECT_THROW(EventGenerator(0, 8, EventSimOptions()), std::invalid_argument);
}

TEST(SimEvents, UsageErrorsThrow) {
  EventGenerator g(4, 3, EventSimOptions());
  cv::Mat img(3, 4, CV_32F, cv::Scalar(0.5));
  std::vector<Event> ev;
  EXPECT_THROW(g.step(img, 10, &ev), std::logic_error);
  EXPECT_THROW(g.reset(cv::Mat(3, 5, CV_32F, cv::Scalar(0.5)), 0), std::invalid_argument);
  EXPECT_THROW(g.reset(cv::Mat(3, 4, CV_8U, cv::Scalar(5)), 0), std::invalid_argument);
  g.reset(img, 100);
  EXPECT_THROW(g.step(img, 100, &ev), std::invalid_argument);
  EXPECT_THROW(g.step(img, 50, &ev), std::invalid_argument);
  cv::Mat bad_labels(3, 4, CV_8U, cv::Scalar(0));
  std::vector<uint16_t> lab;
  EXPECT_THROW(g.step(img, 200, &ev, &bad_labels, &lab), std::invalid_argument);
}

TEST(SimEvents, ThresholdMismatchStatistics) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.05;
  o.contrast_threshold_neg = 0.3;
  o.threshold_mismatch_std = 0.05;
  o.threshold_min = 0.03;
  EventGenerator g(200, 100, o);
  const int n = 200 * 100;
  int clamped = 0;
  double sum_neg = 0, sum2_neg = 0;
  for (int i = 0; i < n; ++i) {
    const double p = g.threshold_pos().ptr<double>()[i];
    const double q = g.threshold_neg().ptr<double>()[i];
    ASSERT_GE(p, 0.03);
    ASSERT_GE(q, 0.03);
    if (p < 0.03 + 1e-8) ++clamped;  // clamped (thresholds are float values >= threshold_min)
    sum_neg += q;
    sum2_neg += q * q;
  }
  // P(N(0.05, 0.05) < 0.03) = Phi(-0.4) = 0.3446.
  const double frac = static_cast<double>(clamped) / n;
  EXPECT_NEAR(frac, 0.3446, 5 * std::sqrt(0.3446 * 0.6554 / n));
  const double mean = sum_neg / n, sd = std::sqrt(sum2_neg / n - mean * mean);
  EXPECT_NEAR(mean, 0.3, 5 * 0.05 / std::sqrt(n));
  EXPECT_NEAR(sd, 0.05, 0.002);
  // Same seed, same thresholds; other seed, other thresholds.
  EventGenerator g2(200, 100, o);
  EXPECT_EQ(cv::norm(g.threshold_neg(), g2.threshold_neg(), cv::NORM_INF), 0.0);
  o.seed = 2;
  EventGenerator g3(200, 100, o);
  EXPECT_GT(cv::norm(g.threshold_neg(), g3.threshold_neg(), cv::NORM_INF), 0.01);
}

TEST(SimEvents, ConstantImageGivesNoEvents) {
  EventSimOptions o;
  o.threshold_mismatch_std = 0.05;
  o.refractory_ns = 100'000;
  EventGenerator g(64, 48, o);
  cv::Mat img(48, 64, CV_32F);
  cv::randu(img, 0.0, 1.0);
  g.reset(img, 5);
  const cv::Mat ref0 = g.reference().clone();
  std::vector<Event> ev;
  for (int k = 1; k <= 2000; ++k) g.step(img, 5 + k * 1'000'000LL, &ev);
  EXPECT_TRUE(ev.empty()) << ev.size() << " events";
  EXPECT_EQ(g.last_max_log_change(), 0.0);
  EXPECT_EQ(cv::norm(ref0, g.reference(), cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(ref0, g.log_intensity(), cv::NORM_INF), 0.0);
}

TEST(SimEvents, ToLogMatchesStdLog) {
  EventSimOptions o;
  o.log_eps = 1e-3;
  EventGenerator g(5, 1, o);
  cv::Mat img = (cv::Mat_<float>(1, 5) << 0.f, 1e-6f, 0.25f, 7.5f, -3.f);
  const cv::Mat l = g.to_log(img);
  ASSERT_EQ(l.type(), CV_64F);
  for (int x = 0; x < 4; ++x) EXPECT_NEAR(l.at<double>(0, x), log_of(img.at<float>(0, x)), 1e-14);
  EXPECT_NEAR(l.at<double>(0, 4), std::log(1e-3), 1e-14);  // negative intensity reads as 0
  // NaN and values in (-eps, 0) read as 0; +inf and values beyond FLT_MAX as FLT_MAX.
  cv::Mat odd = (cv::Mat_<double>(1, 5) << std::nan(""), -5e-4, 1e300, HUGE_VAL, -HUGE_VAL);
  const cv::Mat lo = g.to_log(odd);
  const double l_max = std::log(static_cast<double>(FLT_MAX) + 1e-3);
  EXPECT_NEAR(lo.at<double>(0, 0), std::log(1e-3), 1e-14);
  EXPECT_NEAR(lo.at<double>(0, 1), std::log(1e-3), 1e-14);
  EXPECT_NEAR(lo.at<double>(0, 2), l_max, 1e-12);
  EXPECT_NEAR(lo.at<double>(0, 3), l_max, 1e-12);
  EXPECT_NEAR(lo.at<double>(0, 4), std::log(1e-3), 1e-14);
  // step() applies the same mapping: an image of such values gives finite levels and no crash.
  g.reset(cv::Mat(1, 5, CV_64F, cv::Scalar(0.5)), 0);
  std::vector<Event> ev;
  g.step(odd, 1'000'000, &ev);
  for (int x = 0; x < 5; ++x) EXPECT_NEAR(g.log_intensity().at<double>(0, x), lo.at<double>(0, x), 1e-12);
  EXPECT_FALSE(ev.empty());
  expect_sorted(ev, 5);
}

// Pixels whose log intensity is piecewise linear in time: events at the analytic crossing
// times within 1 ns, over irregular steps, with threshold mismatch and asymmetric thresholds.
void ramp_test(int64_t base) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.15;
  o.contrast_threshold_neg = 0.35;
  o.threshold_mismatch_std = 0.03;
  o.log_eps = kEps;
  const int w = 6;
  EventGenerator g(w, 1, o);
  // slopes in log units per second; pixel 4 and 5 reverse at t_rev.
  // Levels stay within (-5.5, 10) so log(I + eps) is well above log(eps) and I fits a float.
  const double a[w] = {-1.0, 0.5, 4.0, 5.0, -0.5, 3.0};
  const double b1[w] = {300, 450, -350, -500, 400, -420};
  const double b2[w] = {300, 450, -350, -500, -600, 380};
  std::vector<int64_t> times = {0};
  std::mt19937_64 rng(7);
  while (times.back() < 19'000'000) times.push_back(times.back() + 30'000 + static_cast<int64_t>(rng() % 1'500'000));
  const int64_t t_rev = times[times.size() / 2];
  const int64_t t_end = times.back();
  auto level = [&](int i, int64_t t) {
    const double s1 = 1e-9 * static_cast<double>(std::min(t, t_rev));
    const double s2 = 1e-9 * static_cast<double>(std::max<int64_t>(t - t_rev, 0));
    return a[i] + b1[i] * s1 + b2[i] * s2;
  };
  auto image = [&](int64_t t) {
    cv::Mat m(1, w, CV_32F);
    for (int i = 0; i < w; ++i) m.at<float>(0, i) = intensity_for(level(i, t));
    return m;
  };
  g.reset(image(0), base);
  std::vector<Event> ev;
  for (size_t k = 1; k < times.size(); ++k) g.step(image(times[k]), base + times[k], &ev);
  expect_sorted(ev, w);
  const auto per = by_pixel(ev, w);
  for (int i = 0; i < w; ++i) {
    const double cp = g.threshold_pos().at<double>(0, i), cn = g.threshold_neg().at<double>(0, i);
    // Expected events: walk the reference through the first and second linear pieces.
    std::vector<std::pair<double, int>> expected;  // (t in ns relative to base, polarity)
    double ref = a[i];
    auto piece = [&](double t_start, double l_start, double slope, double t_stop) {
      for (;;) {
        const double target = slope > 0 ? ref + cp : ref - cn;
        const double t = t_start + (target - l_start) / slope * 1e9;
        if (t > t_stop) break;
        expected.push_back({t, slope > 0 ? 1 : -1});
        ref = target;
      }
    };
    piece(0, a[i], b1[i], static_cast<double>(t_rev));
    piece(static_cast<double>(t_rev), level(i, t_rev), b2[i], static_cast<double>(t_end));
    const auto it = per.find(i);
    ASSERT_NE(it, per.end()) << "pixel " << i;
    const std::vector<Event>& got = it->second;
    ASSERT_EQ(got.size(), expected.size()) << "pixel " << i;
    ASSERT_GT(expected.size(), 10u);
    for (size_t k = 0; k < got.size(); ++k) {
      EXPECT_EQ(got[k].polarity, expected[k].second) << "pixel " << i << " event " << k;
      EXPECT_NEAR(static_cast<double>(got[k].t_ns - base), expected[k].first, 1.0) << "pixel " << i << " event " << k;
    }
  }
}

TEST(SimEvents, LinearRampExactCrossingTimes) { ramp_test(0); }
TEST(SimEvents, LinearRampExactCrossingTimesAtLargeTimestamps) { ramp_test(kBigBase); }

TEST(SimEvents, SeveralCrossingsPerIntervalAsymmetricThresholds) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.15;
  o.contrast_threshold_neg = 0.35;
  o.log_eps = kEps;
  EventGenerator g(1, 1, o);
  const double l0 = 0.3;
  g.reset(cv::Mat(1, 1, CV_32F, cv::Scalar(intensity_for(l0))), 1000);
  std::vector<Event> ev;
  g.step(cv::Mat(1, 1, CV_32F, cv::Scalar(intensity_for(l0 + 1.0))), 1'001'000, &ev);
  // floor(1.0 / 0.15) = 6 ON events at fractions 0.15 k of the 1 ms step.
  ASSERT_EQ(ev.size(), 6u);
  for (int k = 1; k <= 6; ++k) {
    EXPECT_EQ(ev[k - 1].polarity, 1);
    EXPECT_NEAR(static_cast<double>(ev[k - 1].t_ns), 1000 + 0.15 * k * 1e6, 1.0);
  }
  EXPECT_NEAR(g.reference().at<double>(0, 0), l0 + 0.9, 1e-6);
  // Back down by 1.0: L - r goes 0.1 -> -0.9, crossing -0.35 and -0.70 (C- = 0.35).
  ev.clear();
  g.step(cv::Mat(1, 1, CV_32F, cv::Scalar(intensity_for(l0))), 2'001'000, &ev);
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[0].polarity, -1);
  EXPECT_EQ(ev[1].polarity, -1);
  EXPECT_NEAR(static_cast<double>(ev[0].t_ns), 1'001'000 + 0.45e6, 1.0);
  EXPECT_NEAR(static_cast<double>(ev[1].t_ns), 1'001'000 + 0.80e6, 1.0);
  EXPECT_NEAR(g.reference().at<double>(0, 0), l0 + 0.9 - 0.7, 1e-6);
  EXPECT_NEAR(g.last_max_log_change(), 1.0, 1e-6);
}

// Smooth random intensity sequences with occasional jumps of several thresholds: after every
// step, for every pixel, L(t) - L(t0) - sum(polarity * C_pixel(polarity)) lies in (-C-, C+).
TEST(SimEvents, EventsTrackLogIntensityWithinOneThreshold) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.2;
  o.contrast_threshold_neg = 0.25;
  o.threshold_mismatch_std = 0.04;
  o.log_eps = kEps;
  const int w = 48, h = 32;
  EventGenerator g(w, h, o);
  std::mt19937_64 rng(11);
  auto unif = [&](double lo, double hi) { return lo + (hi - lo) * static_cast<double>(rng() >> 11) * 0x1.0p-53; };
  const double kx = unif(0.1, 0.4), ky = unif(0.1, 0.4), om = unif(50, 200), ph = unif(0, 6);
  cv::Mat jump_mask(h, w, CV_64F, cv::Scalar(0.0));
  auto image = [&](double t_s) {
    cv::Mat m(h, w, CV_32F);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const double l = 1.2 * std::sin(kx * x + ky * y + om * t_s + ph) + 0.6 * std::cos(0.3 * kx * x - om * 0.7 * t_s) +
                         jump_mask.at<double>(y, x) - 1.0;
        m.at<float>(y, x) = static_cast<float>(std::exp(l));
      }
    return m;
  };
  cv::Mat img = image(0);
  g.reset(img, 0);
  cv::Mat l_start(h, w, CV_64F), sum(h, w, CV_64F, cv::Scalar(0.0));
  for (int i = 0; i < w * h; ++i) l_start.ptr<double>()[i] = log_of(img.ptr<float>()[i]);
  int64_t t = 0;
  size_t total = 0, jumps = 0;
  for (int k = 0; k < 300; ++k) {
    t += 100'000 + static_cast<int64_t>(rng() % 3'000'000);
    if (k % 25 == 7) {  // a jump of several thresholds on a random rectangle
      const int x0 = static_cast<int>(rng() % (w / 2)), y0 = static_cast<int>(rng() % (h / 2));
      jump_mask(cv::Rect(x0, y0, w / 3, h / 3)) += (rng() % 2 ? 1.0 : -1.0) * unif(0.9, 1.6);
      ++jumps;
    }
    img = image(1e-9 * static_cast<double>(t));
    std::vector<Event> ev;
    g.step(img, t, &ev);
    total += ev.size();
    for (const Event& e : ev) {
      const cv::Mat& c = e.polarity > 0 ? g.threshold_pos() : g.threshold_neg();
      sum.at<double>(e.y, e.x) += e.polarity * c.at<double>(e.y, e.x);
    }
    for (int i = 0; i < w * h; ++i) {
      const double change = log_of(img.ptr<float>()[i]) - l_start.ptr<double>()[i];
      const double residual = change - sum.ptr<double>()[i];
      ASSERT_LT(residual, g.threshold_pos().ptr<double>()[i] + 1e-9) << "step " << k << " pixel " << i;
      ASSERT_GT(residual, -g.threshold_neg().ptr<double>()[i] - 1e-9) << "step " << k << " pixel " << i;
    }
  }
  EXPECT_GT(jumps, 5u);
  EXPECT_GT(total, 50'000u);  // the sequence really drives many crossings
}

TEST(SimEvents, RefractoryHoldsReferenceAtCurrentLevel) {
  // Ramp of 1000 log units/s, C+ = 0.2 (0.2 ms per threshold), refractory 0.5 ms: the pixel fires
  // at 0.2 ms, is held until 0.7 ms with the reference following L, then needs another full
  // threshold: events every 0.7 ms.
  EventSimOptions o;
  o.contrast_threshold_pos = 0.2;
  o.refractory_ns = 500'000;
  o.log_eps = kEps;
  EventGenerator g(1, 1, o);
  auto img = [&](int64_t t) { return cv::Mat(1, 1, CV_32F, cv::Scalar(intensity_for(-1.0 + 1e-6 * t))); };
  g.reset(img(0), kBigBase);
  std::vector<Event> ev;
  for (int64_t t = 300'000; t <= 10'000'000; t += 300'000) g.step(img(t), kBigBase + t, &ev);
  ASSERT_EQ(ev.size(), 14u);  // 0.2 + 0.7 k <= 9.9 ms
  for (size_t k = 0; k < ev.size(); ++k) {
    EXPECT_EQ(ev[k].polarity, 1);
    EXPECT_NEAR(static_cast<double>(ev[k].t_ns - kBigBase), 200'000.0 + 700'000.0 * k, 1.0) << k;
  }
}

TEST(SimEvents, RefractoryMinimumSpacingWithNoise) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.1;
  o.contrast_threshold_neg = 0.1;
  o.threshold_mismatch_std = 0.02;
  o.refractory_ns = 2'000'000;
  o.shot_noise_rate_hz = 50;
  o.hot_pixel_fraction = 0.05;
  o.hot_pixel_rate_hz = 2000;
  const int w = 32, h = 24;
  EventGenerator g(w, h, o);
  auto image = [&](int64_t t) {
    cv::Mat m(h, w, CV_32F);
    const double s = 1e-9 * static_cast<double>(t);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) m.at<float>(y, x) = static_cast<float>(std::exp(2.0 * std::sin(0.3 * x + 40 * s) + 0.1 * y));
    return m;
  };
  g.reset(image(0), 0);
  std::vector<Event> ev;
  int64_t t = 0;
  for (int k = 0; k < 400; ++k) {
    t += 250'000 + (k % 7) * 111'111;
    g.step(image(t), t, &ev);
  }
  ASSERT_GT(ev.size(), 5000u);
  for (const auto& [pix, list] : by_pixel(ev, w)) {
    for (size_t k = 1; k < list.size(); ++k)
      ASSERT_GE(list[k].t_ns - list[k - 1].t_ns, o.refractory_ns) << "pixel " << pix << " event " << k;
  }
  // Without the refractory period the same input gives many more events.
  o.refractory_ns = 0;
  EventGenerator g0(w, h, o);
  g0.reset(image(0), 0);
  std::vector<Event> ev0;
  t = 0;
  for (int k = 0; k < 400; ++k) {
    t += 250'000 + (k % 7) * 111'111;
    g0.step(image(t), t, &ev0);
  }
  EXPECT_GT(ev0.size(), ev.size() * 3 / 2);
}

struct NoiseRun {
  std::vector<Event> events;
  std::vector<uint16_t> labels;
  std::vector<int64_t> step_begin;  // step start for each event
};

NoiseRun run_static(const EventSimOptions& o, int w, int h, int64_t dt, int steps, int64_t base = 0) {
  EventGenerator g(w, h, o);
  cv::Mat img(h, w, CV_32F);
  cv::randu(img, 0.1, 1.0);
  cv::Mat lab(h, w, CV_16U, cv::Scalar(3));
  g.reset(img, base);
  NoiseRun r;
  for (int k = 1; k <= steps; ++k) {
    const size_t before = r.events.size();
    g.step(img, base + k * dt, &r.events, &lab, &r.labels);
    r.step_begin.resize(r.events.size(), base + (k - 1) * dt);
    for (size_t j = before; j < r.events.size(); ++j) {
      EXPECT_GT(r.events[j].t_ns, base + (k - 1) * dt);
      EXPECT_LE(r.events[j].t_ns, base + k * dt);
    }
  }
  return r;
}

TEST(SimEvents, ShotNoiseRateAndPolaritySplit) {
  EventSimOptions o;
  o.shot_noise_rate_hz = 2.0;
  const int w = 100, h = 100;
  const int64_t dt = 2'000'000;
  const NoiseRun r = run_static(o, w, h, dt, 2500, 42);  // 5 s
  const double lambda = 2.0 * w * h * 5.0;
  const double n = static_cast<double>(r.events.size());
  EXPECT_NEAR(n, lambda, 5 * std::sqrt(lambda));
  size_t on = 0, early = 0, left = 0;
  for (size_t k = 0; k < r.events.size(); ++k) {
    const Event& e = r.events[k];
    on += e.polarity > 0;
    early += (e.t_ns - r.step_begin[k]) <= dt / 2;
    left += e.x < w / 2;
    ASSERT_EQ(r.labels[k], 0xFFFF);
  }
  const double half_sigma = 5 * std::sqrt(n / 4);
  EXPECT_NEAR(static_cast<double>(on), n / 2, half_sigma);
  EXPECT_NEAR(static_cast<double>(early), n / 2, half_sigma);  // uniform within steps
  EXPECT_NEAR(static_cast<double>(left), n / 2, half_sigma);   // uniform over pixels
  expect_sorted(r.events, w);
}

TEST(SimEvents, LeakRateWithRandomPhase) {
  EventSimOptions o;
  o.leak_rate_hz = 0.5;  // period 2 s
  o.threshold_mismatch_std = 0.03;
  const int w = 100, h = 100;
  const int64_t dt = 5'000'000;
  const NoiseRun r = run_static(o, w, h, dt, 1800, 0);  // 9 s = 4.5 periods
  const auto per = by_pixel(r.events, w);
  size_t total = 0, first_half = 0;
  for (const auto& [pix, list] : per) {
    total += list.size();
    ASSERT_TRUE(list.size() == 4 || list.size() == 5) << "pixel " << pix << ": " << list.size();
    first_half += list[0].t_ns < 1'000'000'000;
    for (size_t k = 0; k < list.size(); ++k) {
      ASSERT_EQ(list[k].polarity, 1);
      if (k > 0) {
        ASSERT_NEAR(static_cast<double>(list[k].t_ns - list[k - 1].t_ns), 2e9, 2.0);
      }
    }
  }
  EXPECT_EQ(per.size(), static_cast<size_t>(w * h));
  const double n = w * h;
  EXPECT_NEAR(static_cast<double>(total), 4.5 * n, 5 * std::sqrt(0.25 * n));
  EXPECT_NEAR(static_cast<double>(first_half), 0.5 * n, 5 * std::sqrt(0.25 * n));  // phases not synchronised
  for (uint16_t l : r.labels) ASSERT_EQ(l, 0xFFFF);  // static scene: leak-only events are noise
}

TEST(SimEvents, HotPixelsFireAtTheirRate) {
  EventSimOptions o;
  o.hot_pixel_fraction = 0.01;
  o.hot_pixel_rate_hz = 200;
  const int w = 100, h = 100;
  const NoiseRun r = run_static(o, w, h, 1'000'000, 2000, 0);  // 2 s
  const auto per = by_pixel(r.events, w);
  EXPECT_EQ(per.size(), 100u);  // exactly round(0.01 * N) hot pixels, all firing
  const double lambda = 100 * 200 * 2.0;
  EXPECT_NEAR(static_cast<double>(r.events.size()), lambda, 5 * std::sqrt(lambda));
  for (const Event& e : r.events) ASSERT_EQ(e.polarity, 1);
  // With a refractory period R the rate becomes rate / (1 + rate R) (a noise event in a reset is lost).
  o.refractory_ns = 1'000'000;
  const NoiseRun rr = run_static(o, w, h, 1'000'000, 2000, 0);
  const double expected = 100 * 2.0 * 200 / (1 + 200 * 1e-3);
  EXPECT_NEAR(static_cast<double>(rr.events.size()), expected, 5 * std::sqrt(expected));
}

TEST(SimEvents, JitterStaysInIntervalAndKeepsOrder) {
  EventSimOptions o;
  o.contrast_threshold_pos = 0.1;
  o.contrast_threshold_neg = 0.1;
  o.log_eps = kEps;
  const int w = 40, h = 20;
  const int64_t dt = 1'000'000;
  // Slow ramps (events of one pixel >= 1.25 ms apart) at per-pixel offsets.
  auto image = [&](int64_t t) {
    cv::Mat m(h, w, CV_32F);
    for (int i = 0; i < w * h; ++i) m.ptr<float>()[i] = intensity_for(0.01 * i + 80.0 * 1e-9 * static_cast<double>(t));
    return m;
  };
  auto run = [&](double jitter, std::vector<int64_t>* step_of) {
    EventSimOptions oj = o;
    oj.timestamp_jitter_ns = jitter;
    EventGenerator g(w, h, oj);
    g.reset(image(0), kBigBase);
    std::vector<Event> ev;
    for (int k = 1; k <= 400; ++k) {
      const size_t before = ev.size();
      g.step(image(k * dt), kBigBase + k * dt, &ev);
      for (size_t j = before; j < ev.size(); ++j) {
        EXPECT_GT(ev[j].t_ns, kBigBase + (k - 1) * dt);
        EXPECT_LE(ev[j].t_ns, kBigBase + k * dt);
        if (step_of) step_of->push_back(kBigBase + (k - 1) * dt);
      }
    }
    expect_sorted(ev, w);
    return ev;
  };
  std::vector<int64_t> step_of;
  const std::vector<Event> clean = run(0, &step_of);
  const std::vector<Event> jit = run(20'000, nullptr);
  ASSERT_EQ(clean.size(), jit.size());
  ASSERT_GT(clean.size(), 20'000u);
  // Heavy jitter: still inside each step and sorted.
  run(400'000, nullptr);
  // Match the k-th event of each pixel; away from step ends the differences are N(0, 20 us).
  std::map<int, std::vector<std::pair<int64_t, int64_t>>> clean_px;  // (t, step begin)
  for (size_t k = 0; k < clean.size(); ++k) clean_px[pixel_of(clean[k], w)].push_back({clean[k].t_ns, step_of[k]});
  const auto jit_px = by_pixel(jit, w);
  double s2 = 0;
  size_t n = 0;
  for (const auto& [pix, list] : clean_px) {
    const std::vector<Event>& jl = jit_px.at(pix);
    ASSERT_EQ(jl.size(), list.size());
    for (size_t k = 0; k < list.size(); ++k) {
      const int64_t off = list[k].first - list[k].second;
      if (off < 150'000 || off > dt - 150'000) continue;
      const double d = static_cast<double>(jl[k].t_ns - list[k].first);
      s2 += d * d;
      ++n;
    }
  }
  ASSERT_GT(n, 10'000u);
  EXPECT_NEAR(std::sqrt(s2 / n), 20'000.0, 20'000.0 * 5 / std::sqrt(2.0 * n));
}

NoiseRun run_full(uint64_t seed, int64_t base) {
  EventSimOptions o;
  o.threshold_mismatch_std = 0.03;
  o.refractory_ns = 300'000;
  o.shot_noise_rate_hz = 5;
  o.leak_rate_hz = 1;
  o.hot_pixel_fraction = 0.02;
  o.hot_pixel_rate_hz = 300;
  o.timestamp_jitter_ns = 50'000;
  o.seed = seed;
  const int w = 40, h = 30;
  EventGenerator g(w, h, o);
  auto image = [&](int64_t t) {
    cv::Mat m(h, w, CV_32F);
    const double s = 1e-9 * static_cast<double>(t);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) m.at<float>(y, x) = static_cast<float>(1.0 + 0.8 * std::sin(0.4 * x - 30 * s + 0.2 * y));
    return m;
  };
  cv::Mat lab(h, w, CV_16U);
  for (int i = 0; i < w * h; ++i) lab.ptr<uint16_t>()[i] = static_cast<uint16_t>(i % 5);
  g.reset(image(0), base);
  NoiseRun r;
  int64_t t = 0;
  for (int k = 0; k < 300; ++k) {
    t += 200'000 + (k % 5) * 77'777;
    g.step(image(t), base + t, &r.events, &lab, &r.labels);
  }
  return r;
}

TEST(SimEvents, DeterministicPerSeed) {
  const NoiseRun a = run_full(5, 0), b = run_full(5, 0), c = run_full(6, 0);
  ASSERT_GT(a.events.size(), 1000u);
  EXPECT_EQ(a.events, b.events);
  EXPECT_EQ(a.labels, b.labels);
  EXPECT_NE(a.events, c.events);
  ASSERT_EQ(a.labels.size(), a.events.size());
  size_t noise = 0;
  for (size_t k = 0; k < a.events.size(); ++k) {
    const Event& e = a.events[k];
    if (a.labels[k] == 0xFFFF) {
      ++noise;
    } else {
      EXPECT_EQ(a.labels[k], (e.y * 40 + e.x) % 5);
    }
  }
  EXPECT_GT(noise, 100u);
  EXPECT_LT(noise, a.events.size());
  expect_sorted(a.events, 40);
}

TEST(SimEvents, LargeTimestampsGiveSameRelativeEvents) {
  const NoiseRun a = run_full(9, 0), b = run_full(9, kBigBase);
  ASSERT_EQ(a.events.size(), b.events.size());
  ASSERT_GT(a.events.size(), 1000u);
  for (size_t k = 0; k < a.events.size(); ++k) {
    Event e = b.events[k];
    e.t_ns -= kBigBase;
    ASSERT_EQ(e, a.events[k]) << k;
  }
  EXPECT_EQ(a.labels, b.labels);
}

TEST(SimEvents, ResetRestartsTheSameRealisation) {
  EventSimOptions o;
  o.shot_noise_rate_hz = 20;
  o.leak_rate_hz = 2;
  EventGenerator g(30, 20, o);
  cv::Mat img(20, 30, CV_32F, cv::Scalar(0.5));
  std::vector<Event> first, second;
  for (std::vector<Event>* out : {&first, &second}) {
    g.reset(img, 1000);
    for (int k = 1; k <= 200; ++k) g.step(img, 1000 + k * 1'000'000LL, out);
  }
  ASSERT_GT(first.size(), 100u);
  EXPECT_EQ(first, second);
}

}  // namespace
}  // namespace evio::simulator
