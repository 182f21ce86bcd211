#include "panorama_rotation_scenario.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "evio/calib/equirectangular.h"
#include "evio/calib/geometry.h"

namespace evio::frontend::test {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Log intensity of the panorama in direction d (unit): plane waves sum_k a_k sin(k_k . d + phi_k)
// with wave numbers 4..30 rad^-1 (wavelengths 0.2..1.6 rad) in random directions.
struct Texture {
  std::vector<Eigen::Vector3d> k;
  std::vector<double> amplitude, phase;
  explicit Texture(uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> nd;
    std::uniform_real_distribution<double> uk(4.0, 30.0), up(0.0, 2 * kPi);
    for (int i = 0; i < 14; ++i) {
      Eigen::Vector3d dir(nd(rng), nd(rng), nd(rng));
      k.push_back(dir.normalized() * uk(rng));
      amplitude.push_back(0.12);
      phase.push_back(up(rng));
    }
  }
  double operator()(const Eigen::Vector3d& d) const {
    double s = 0;
    for (size_t i = 0; i < k.size(); ++i) s += amplitude[i] * std::sin(k[i].dot(d) + phase[i]);
    return s;
  }
};

std::vector<float> render_map(const Texture& tex, int W, int H) {
  const calib::Equirectangular eq(W, H);
  std::vector<float> m(static_cast<size_t>(W) * H);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) m[static_cast<size_t>(j) * W + i] = static_cast<float>(tex(eq.pixel_direction(i, j)));
  return m;
}

// Exact (std::atan2) projection and double bilinear interpolation: independent of the filter's
// float fast path.
double sample_map(const std::vector<float>& m, const calib::Equirectangular& eq, const Eigen::Vector3d& d) {
  const int W = eq.width(), H = eq.height();
  const Eigen::Vector2d uv = eq.project(d);
  const double x = uv.x() - 0.5;
  const double y = std::clamp(uv.y() - 0.5, 0.0, H - 1.0);
  const double fx0 = std::floor(x);
  const double fx = x - fx0;
  int ix = static_cast<int>(fx0);
  ix = (ix % W + W) % W;
  const int ix1 = (ix + 1) % W;
  const int iy = std::min(static_cast<int>(y), H - 2);
  const double fy = y - iy;
  auto at = [&](int i, int j) { return static_cast<double>(m[static_cast<size_t>(j) * W + i]); };
  const double a = at(ix, iy) + fx * (at(ix1, iy) - at(ix, iy));
  const double b = at(ix, iy + 1) + fx * (at(ix1, iy + 1) - at(ix, iy + 1));
  return a + fy * (b - a);
}

}  // namespace

Eigen::Quaterniond PanoramaScenario::truth_at(int64_t t_ns) const {
  if (t_ns <= 0) return truth.front();
  const int64_t k = t_ns / truth_step_ns;
  if (k + 1 >= static_cast<int64_t>(truth.size())) return truth.back();
  const double s = static_cast<double>(t_ns - k * truth_step_ns) / static_cast<double>(truth_step_ns);
  return calib::so3_interpolate(truth[static_cast<size_t>(k)], truth[static_cast<size_t>(k + 1)], s);
}

PanoramaScenario make_panorama_scenario(const PanoramaScenarioConfig& c) {
  PanoramaScenario s;
  const Texture tex(c.seed);
  s.map_width = c.map_width;
  s.map_height = c.map_width / 2;
  s.map = render_map(tex, s.map_width, s.map_height);
  const calib::Equirectangular fine_eq(2 * s.map_width, s.map_width);
  const std::vector<float> fine = render_map(tex, fine_eq.width(), fine_eq.height());

  const int SW = s.sensor_width, SH = s.sensor_height;
  s.bearings.resize(static_cast<size_t>(SW) * SH);
  std::vector<Eigen::Vector3d> bd(s.bearings.size());
  for (int y = 0; y < SH; ++y)
    for (int x = 0; x < SW; ++x) {
      const Eigen::Vector3d b = Eigen::Vector3d((x - 120.0) / 200.0, (y - 90.0) / 200.0, 1.0).normalized();
      bd[static_cast<size_t>(y) * SW + x] = b;
      s.bearings[static_cast<size_t>(y) * SW + x] = b.cast<float>();
    }

  // Trajectory: camera looking along world +x (camera x -> world -y, y -> -z, z -> +x), tilted a
  // little; angular velocity (camera frame) of magnitude speed(t) about a slowly varying axis.
  Eigen::Matrix3d R0;
  R0 << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Eigen::Quaterniond q(calib::so3_exp(Eigen::Vector3d(0.0, 0.0, 0.3)) * R0 * calib::so3_exp(Eigen::Vector3d(0.1, 0, 0)));
  const double peak = c.peak_speed_deg_s * kPi / 180.0;
  const double ramp = 0.25 * c.duration_s;
  auto omega = [&](double t) {
    const double speed = t < ramp ? peak * (0.5 - 0.5 * std::cos(kPi * t / ramp)) : peak;
    const double ph = 2 * kPi * t / c.duration_s;
    const Eigen::Vector3d axis(0.5 * std::sin(1.3 * ph + 0.4), 1.0, 0.4 * std::cos(0.9 * ph));
    return Eigen::Vector3d(speed * axis.normalized());
  };
  const int64_t end_ns = static_cast<int64_t>(std::llround(c.duration_s * 1e9));
  const double h = 1e-9 * static_cast<double>(s.truth_step_ns);
  s.truth.push_back(q);
  for (int64_t t = 0; t < end_ns; t += s.truth_step_ns) {
    q = (q * calib::so3_exp_quat(omega(1e-9 * static_cast<double>(t) + 0.5 * h) * h)).normalized();
    s.truth.push_back(q);
  }

  std::mt19937_64 rng(c.seed * 7919 + 1);
  std::normal_distribution<double> nd;
  for (int64_t t = 0; t <= s.end_ns(); t += c.gyro_period_ns) {
    const Eigen::Vector3d w = omega(1e-9 * static_cast<double>(t)) + c.gyro_bias_rad_s +
                              c.gyro_noise_rad_s * Eigen::Vector3d(nd(rng), nd(rng), nd(rng));
    s.gyro.emplace_back(t, w);
  }

  // Events: render steps of at most 1.5 mrad of rotation.
  const double step_s = std::min(0.0015 / std::max(peak, 1e-3), 0.005);
  const int64_t step_ns = std::max<int64_t>(1000, static_cast<int64_t>(step_s * 1e9));
  const size_t np = bd.size();
  std::vector<double> ref(np), last(np);
  {
    const Eigen::Matrix3d R = s.truth_at(0).toRotationMatrix();
    for (size_t p = 0; p < np; ++p) ref[p] = last[p] = sample_map(fine, fine_eq, R * bd[p]);
  }
  std::normal_distribution<double> tn(0.0, c.timestamp_noise_ns);
  for (int64_t t0 = 0; t0 < s.end_ns();) {
    const int64_t t1 = std::min(s.end_ns(), t0 + step_ns);
    const Eigen::Matrix3d R = s.truth_at(t1).toRotationMatrix();
    for (size_t p = 0; p < np; ++p) {
      const double L = sample_map(fine, fine_eq, R * bd[p]);
      while (std::abs(L - ref[p]) >= c.contrast) {
        const int pol = L > ref[p] ? 1 : -1;
        const double level = ref[p] + pol * c.contrast;
        const double f = (level - last[p]) / (L - last[p]);
        Event e;
        e.t_ns = t0 + static_cast<int64_t>(std::llround(f * static_cast<double>(t1 - t0) + tn(rng)));
        e.t_ns = std::clamp<int64_t>(e.t_ns, 0, s.end_ns());
        e.x = static_cast<uint16_t>(p % SW);
        e.y = static_cast<uint16_t>(p / SW);
        e.polarity = static_cast<int8_t>(pol);
        s.events.push_back(e);
        ref[p] = level;
      }
      last[p] = L;
    }
    t0 = t1;
  }
  const size_t noise = static_cast<size_t>(c.noise_event_fraction * static_cast<double>(s.events.size()));
  std::uniform_int_distribution<int64_t> ut(0, s.end_ns());
  std::uniform_int_distribution<int> ux(0, SW - 1), uy(0, SH - 1), upol(0, 1);
  for (size_t i = 0; i < noise; ++i) {
    Event e;
    e.t_ns = ut(rng);
    e.x = static_cast<uint16_t>(ux(rng));
    e.y = static_cast<uint16_t>(uy(rng));
    e.polarity = static_cast<int8_t>(upol(rng) ? 1 : -1);
    s.events.push_back(e);
  }
  std::stable_sort(s.events.begin(), s.events.end(), [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  return s;
}

PanoramaRunResult run_panorama_filter(const PanoramaScenario& s, const RotationParticleFilterOptions& options,
                                      bool use_gyro, int64_t chunk_ns) {
  constexpr int64_t kEvalNs = 1'000'000;
  RotationParticleFilter pf(s.sensor_width, s.sensor_height, s.bearings, options);
  pf.reset(s.truth_at(0), 0);
  const LogIntensityMapView view = s.view();

  // Cut times: gyro samples (added after the events before them), chunk ends, evaluation times.
  std::vector<std::pair<int64_t, int>> cuts;  // (time, kind bits: 1 gyro, 2 eval)
  // Each gyro sample is added when the events reach the sample before it: the filter then has the
  // first sample after every batch and interpolates the rate (RotationParticleFilter::add_gyro).
  if (use_gyro)
    for (size_t k = 0; k < s.gyro.size(); ++k) cuts.emplace_back(k == 0 ? s.gyro[0].first : s.gyro[k - 1].first, 1);
  for (int64_t t = chunk_ns; t <= s.end_ns(); t += chunk_ns) cuts.emplace_back(t, 0);
  for (int64_t t = kEvalNs; t <= s.end_ns(); t += kEvalNs) cuts.emplace_back(t, 2);
  std::stable_sort(cuts.begin(), cuts.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  PanoramaRunResult r;
  double sum_sq = 0;
  size_t ei = 0, gi = 0;
  using Clock = std::chrono::steady_clock;
  Clock::duration busy{0};
  for (const auto& [t, kind] : cuts) {
    size_t ej = ei;
    while (ej < s.events.size() && s.events[ej].t_ns < t) ++ej;
    const auto c0 = Clock::now();
    if (ej > ei) pf.update(s.events.data() + ei, ej - ei, view);
    if (kind == 1) {
      pf.add_gyro(s.gyro[gi].first, s.gyro[gi].second);
      ++gi;
    }
    busy += Clock::now() - c0;
    ei = ej;
    if (kind == 2) {
      const double err = calib::so3_log(s.truth_at(pf.time_ns()).conjugate() * pf.mean()).norm();
      sum_sq += err * err;
      r.max_rad = std::max(r.max_rad, err);
      r.means.push_back(pf.mean());
      r.times_ns.push_back(pf.time_ns());
      r.omega_c.push_back(pf.angular_velocity_c());
    }
  }
  r.rms_rad = r.means.empty() ? 0.0 : std::sqrt(sum_sq / static_cast<double>(r.means.size()));
  r.filter_seconds = std::chrono::duration<double>(busy).count();
  r.events_per_s = r.filter_seconds > 0 ? static_cast<double>(s.events.size()) / r.filter_seconds : 0.0;
  r.stats = pf.stats();
  return r;
}

}  // namespace evio::frontend::test
