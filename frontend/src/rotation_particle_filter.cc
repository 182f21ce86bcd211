#include "evio/frontend/rotation_particle_filter.h"
#include "evio/frontend/option_tables.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "evio/calib/geometry.h"
#include "evio/frontend/event_filters.h"

namespace evio::frontend {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr float kPiF = 3.14159265358979323846f;
constexpr int kGaussTableBits = 12;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using detail::fast_atan2;

// Bilinear sample at texel-index coordinates (texel centres at integers): x wraps with period W
// (x must be in [-W, 2W)), y is clamped to [0, H-1]. NaN if any texel used is NaN.
inline float sample_index(const float* data, int W, int H, float x, float y) {
  y = std::min(std::max(y, 0.0f), static_cast<float>(H - 1));
  int iy = static_cast<int>(y);
  iy = iy > H - 2 ? H - 2 : iy;
  const float fy = y - static_cast<float>(iy);
  int ix = static_cast<int>(x + static_cast<float>(W)) - W;  // floor for x > -W
  const float fx = x - static_cast<float>(ix);
  ix = ix < 0 ? ix + W : (ix >= W ? ix - W : ix);
  const int ix1 = ix + 1 == W ? 0 : ix + 1;
  const float* r0 = data + static_cast<size_t>(iy) * static_cast<size_t>(W);
  const float* r1 = r0 + W;
  const float a = r0[ix] + fx * (r0[ix1] - r0[ix]);
  const float b = r1[ix] + fx * (r1[ix1] - r1[ix]);
  return a + fy * (b - a);
}

// Equirectangular position of direction (x, y, z) as fractions (u / W in [0, 1], v / H in [0, 1]).
inline void project_fraction(float x, float y, float z, float* un, float* vn) {
  const float lon = fast_atan2(y, x);
  const float polar = fast_atan2(std::sqrt(x * x + y * y), z);
  *un = (lon + kPiF) * (0.5f / kPiF);
  *vn = polar * (1.0f / kPiF);
}

// Exp of a rotation vector as a unit quaternion; Taylor branch for small angles (the usual case:
// one prediction step), calib::so3_exp_quat otherwise.
inline Eigen::Quaterniond exp_quat(const Eigen::Vector3d& phi) {
  const double t2 = phi.squaredNorm();
  if (t2 < 1e-4) {
    const double w = 1.0 - t2 / 8.0 + t2 * t2 / 384.0;
    const double s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0;
    return Eigen::Quaterniond(w, s * phi.x(), s * phi.y(), s * phi.z());
  }
  return calib::so3_exp_quat(phi);
}

}  // namespace

float LogIntensityMapView::sample(float u, float v) const {
  if (!valid() || !std::isfinite(u) || !std::isfinite(v)) return kNaN;
  float x = std::fmod(u - 0.5f, static_cast<float>(width));
  if (x < 0) x += static_cast<float>(width);
  return sample_index(data, width, height, x, v - 0.5f);
}

const char* rotation_motion_model_name(RotationMotionModel m) {
  switch (m) {
    case RotationMotionModel::kRandomWalk: return "random_walk";
    case RotationMotionModel::kConstantVelocity: return "constant_velocity";
    case RotationMotionModel::kParticleVelocity: return "particle_velocity";
  }
  return "unknown";
}

const char* rotation_measurement_model_name(RotationMeasurementModel m) {
  switch (m) {
    case RotationMeasurementModel::kPreviousMean: return "previous_mean";
    case RotationMeasurementModel::kRelativeMotion: return "relative_motion";
    case RotationMeasurementModel::kAuto: return "auto";
  }
  return "unknown";
}

bool RotationParticleFilterOptions::Validate(std::string* why) const {
  if (!rotation_particle_filter_table().check(*this, why)) return false;
  auto num = [](double v) { return yaml_config::yaml_number(v); };
  if (probe_every_batches > 0 && linearize_max_spread_rad > 0 && probe_offset_rad > linearize_max_spread_rad)
    return validation_failed(why, "probe_offset_rad " + num(probe_offset_rad) + " (expected <= linearize_max_spread_rad " +
                         num(linearize_max_spread_rad) + ": probes outside it would change how batches are weighed)");
  const double peak = std::log((1.0 - outlier_probability) / (std::sqrt(2.0 * kPi) * likelihood_std));
  const double floor = std::log(outlier_probability / outlier_range);
  if (!(floor < peak))
    return validation_failed(why, "outlier density eps/outlier_range " + num(outlier_probability / outlier_range) +
                         " is not below the Gaussian peak (1-eps)/(sqrt(2 pi) likelihood_std) " + num(std::exp(peak)) +
                         ": every event would be an outlier");
  if (min_particles > num_particles)
    return validation_failed(why, "min_particles " + std::to_string(min_particles) + " (expected 0..particles " +
                         std::to_string(num_particles) + ")");
  return true;
}

RotationParticleFilter::RotationParticleFilter(int sensor_width, int sensor_height,
                                               std::vector<Eigen::Vector3f> bearings,
                                               const RotationParticleFilterOptions& options)
    : width_(sensor_width), height_(sensor_height), options_(options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("rotation particle filter options: " + why);
  if (sensor_width <= 0 || sensor_height <= 0 || sensor_width > 65536 || sensor_height > 65536)
    throw std::invalid_argument("rotation particle filter: sensor size " + std::to_string(sensor_width) + "x" +
                                std::to_string(sensor_height) + " (expected 1..65536 x 1..65536 pixels)");
  const size_t n = static_cast<size_t>(sensor_width) * static_cast<size_t>(sensor_height);
  if (bearings.size() != n)
    throw std::invalid_argument("rotation particle filter: " + std::to_string(bearings.size()) +
                                " bearings for a " + std::to_string(sensor_width) + "x" +
                                std::to_string(sensor_height) + " sensor (expected one per pixel, row-major)");
  bx_.resize(n);
  by_.resize(n);
  bz_.resize(n);
  for (size_t i = 0; i < n; ++i) {
    Eigen::Vector3f b = bearings[i];
    const float norm = b.norm();
    if (!std::isfinite(norm) || norm < 1e-6f) {
      bx_[i] = by_[i] = bz_[i] = kNaN;
      continue;
    }
    b /= norm;
    bx_[i] = b.x();
    by_[i] = b.y();
    bz_[i] = b.z();
  }
  const double peak = std::log((1.0 - options.outlier_probability) / (std::sqrt(2.0 * kPi) * options.likelihood_std));
  floor_loglik_ = std::log(options.outlier_probability / options.outlier_range) - peak;
  neg_half_inv_var_ = -0.5 / (options.likelihood_std * options.likelihood_std);

  // The Gaussian table: N(0,1) draws from the seed, standardised to zero mean and unit variance.
  gauss_table_.resize(size_t{1} << kGaussTableBits);
  std::mt19937_64 gen(options.seed ^ 0x9e3779b97f4a7c15ULL);
  std::normal_distribution<double> nd(0.0, 1.0);
  std::vector<double> g(gauss_table_.size());
  double mean = 0, var = 0;
  for (double& x : g) mean += (x = nd(gen));
  mean /= static_cast<double>(g.size());
  for (double& x : g) var += (x - mean) * (x - mean);
  const double inv_std = 1.0 / std::sqrt(var / static_cast<double>(g.size()));
  for (size_t i = 0; i < g.size(); ++i) gauss_table_[i] = static_cast<float>((g[i] - mean) * inv_std);

  prev_u_.assign(n, kNaN);
  prev_v_.assign(n, kNaN);
  prev_t_.assign(n, std::numeric_limits<int64_t>::min());
  prev_ref_.assign(n, Eigen::Vector4f::Constant(kNaN));
  stamp_.assign(n, 0);
  reset(Eigen::Quaterniond::Identity(), 0);
}

namespace {
std::vector<Eigen::Vector3f> undistorter_bearings(const EventUndistorter& u) {
  std::vector<Eigen::Vector3f> b(static_cast<size_t>(u.width()) * static_cast<size_t>(u.height()));
  for (int y = 0; y < u.height(); ++y)
    for (int x = 0; x < u.width(); ++x)
      b[static_cast<size_t>(y) * u.width() + x] =
          u.valid(x, y) ? u.bearing(x, y) : Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
  return b;
}
}  // namespace

RotationParticleFilter::RotationParticleFilter(const EventUndistorter& undistorter,
                                               const RotationParticleFilterOptions& options)
    : RotationParticleFilter(undistorter.width(), undistorter.height(), undistorter_bearings(undistorter), options) {}

uint64_t RotationParticleFilter::next_u64() {  // SplitMix64 (Steele, Lea, Flood 2014)
  uint64_t z = (rng_state_ += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// A standard normal draw: a uniformly chosen entry of the 4096-entry table (12 random bits, five
// draws per 64-bit word). Summed over prediction steps the process noise is Gaussian to within
// the table's resolution; the table costs one load instead of a log/sqrt/sin per draw.
float RotationParticleFilter::normal() {
  if (gauss_left_ == 0) {
    gauss_bits_ = next_u64();
    gauss_left_ = 64 / kGaussTableBits;
  }
  const float g = gauss_table_[gauss_bits_ & ((uint64_t{1} << kGaussTableBits) - 1)];
  gauss_bits_ >>= kGaussTableBits;
  --gauss_left_;
  return g;
}

void RotationParticleFilter::reset(const Eigen::Quaterniond& R_w_c, int64_t t_ns) {
  rng_state_ = options_.seed;
  gauss_left_ = 0;
  const int n = options_.num_particles;
  const Eigen::Quaterniond q = R_w_c.normalized();
  particles_.assign(static_cast<size_t>(n), q);
  for (int i = 1; i < n && options_.initial_spread_rad > 0; ++i) {
    const Eigen::Vector3d d(normal(), normal(), normal());
    particles_[static_cast<size_t>(i)] = (q * exp_quat(options_.initial_spread_rad * d)).normalized();
  }
  log_w_.assign(static_cast<size_t>(n), -std::log(static_cast<double>(n)));
  w_.assign(static_cast<size_t>(n), 1.0 / n);
  vel_.assign(static_cast<size_t>(n), Eigen::Vector3d::Zero());
  vel_mean_.setZero();
  t_ns_ = t_ns;
  std::fill(prev_u_.begin(), prev_u_.end(), kNaN);
  std::fill(prev_v_.begin(), prev_v_.end(), kNaN);
  std::fill(prev_t_.begin(), prev_t_.end(), std::numeric_limits<int64_t>::min());
  std::fill(prev_ref_.begin(), prev_ref_.end(), Eigen::Vector4f::Constant(kNaN));
  std::fill(stamp_.begin(), stamp_.end(), 0u);
  batch_id_ = 0;
  stride_counter_ = 0;
  pending_.clear();
  gyro_.clear();
  have_gyro_ = false;
  omega_gyro_c_.setZero();
  omega_hat_c_.setZero();
  have_velocity_ = false;
  vel_ref_t_ns_ = t_ns;
  compute_mean();
  ref_ = mean_;
  vel_ref_q_ = mean_;
  stats_ = RotationParticleFilterStats();
}

void RotationParticleFilter::set_velocity(const Eigen::Vector3d& omega_c_rad_s) {
  const double s = options_.initial_velocity_spread_rad_s;
  for (size_t i = 0; i < vel_.size(); ++i)
    vel_[i] = omega_c_rad_s + (i == 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(s * normal(), s * normal(), s * normal()));
  compute_mean();
}

bool RotationParticleFilter::particle_velocity_active() const {
  return options_.motion_model == RotationMotionModel::kParticleVelocity && !have_gyro_;
}

Eigen::Vector3d RotationParticleFilter::camera_rate_from_imu(const ImuSample& imu, const Eigen::Quaterniond& R_c_b,
                                                             const Eigen::Vector3d& gyro_bias_b) {
  return R_c_b * (imu.gyro - gyro_bias_b);
}

void RotationParticleFilter::add_gyro(int64_t t_ns, const Eigen::Vector3d& omega_c_rad_s) {
  if (!omega_c_rad_s.allFinite()) return;
  if (!gyro_.empty() && t_ns < gyro_.back().first) return;  // out of order: ignored
  gyro_.emplace_back(t_ns, omega_c_rad_s);
}

bool RotationParticleFilter::gyro_fresh(int64_t t_ns) const {
  return !gyro_.empty() && t_ns - gyro_.back().first <= options_.gyro_max_age_ns;
}

// Integral of the gyro rates over [t0, t1], the rate linear between consecutive samples (a sample
// is the rate at its time) and held beyond the last one (and before the first): each piece between
// sample times is one step at its midpoint rate. Holding each sample until the next instead lags
// the rotation by half a sample period (0.5 ms at 1 kHz: 0.33 deg at 670 deg/s). Drops samples no
// longer needed and remembers the rate at t1.
Eigen::Quaterniond RotationParticleFilter::gyro_increment(int64_t t0, int64_t t1) {
  while (gyro_.size() >= 2 && gyro_[1].first <= t0) gyro_.pop_front();
  auto rate_at = [&](size_t k, int64_t t) {  // between samples k and k + 1 (held beyond them)
    if (k + 1 >= gyro_.size() || t <= gyro_[k].first) return gyro_[k].second;
    const double a = static_cast<double>(t - gyro_[k].first) / static_cast<double>(gyro_[k + 1].first - gyro_[k].first);
    return Eigen::Vector3d(gyro_[k].second + std::min(a, 1.0) * (gyro_[k + 1].second - gyro_[k].second));
  };
  Eigen::Quaterniond dq = Eigen::Quaterniond::Identity();
  int64_t s = t0;
  size_t k = 0;
  while (s < t1) {
    const int64_t seg_end = k + 1 < gyro_.size() ? std::min(t1, gyro_[k + 1].first) : t1;
    if (seg_end > s) dq = dq * exp_quat(rate_at(k, s + (seg_end - s) / 2) * (1e-9 * static_cast<double>(seg_end - s)));
    s = seg_end;
    if (k + 1 < gyro_.size() && gyro_[k + 1].first <= s) ++k;
  }
  while (gyro_.size() >= 2 && gyro_[1].first <= t1) gyro_.pop_front();
  omega_gyro_c_ = rate_at(0, t1);
  have_gyro_ = true;
  return dq.normalized();
}

void RotationParticleFilter::predict(int64_t t_ns) {
  if (t_ns <= t_ns_) return;
  const double dt = 1e-9 * static_cast<double>(t_ns - t_ns_);
  Eigen::Quaterniond dR = Eigen::Quaterniond::Identity();
  double sigma = options_.motion_noise_rad_per_sqrt_s;
  if (gyro_fresh(t_ns)) {
    dR = gyro_increment(t_ns_, t_ns);
    ref_ = (ref_ * dR).normalized();
    sigma = options_.gyro_noise_rad_per_sqrt_s;
    ++stats_.gyro_predictions;
    // Particle velocities follow the gyro, so they are sensible if the gyro drops out.
    if (options_.motion_model == RotationMotionModel::kParticleVelocity)
      std::fill(vel_.begin(), vel_.end(), omega_gyro_c_);
  } else {
    have_gyro_ = false;
    if (options_.motion_model == RotationMotionModel::kConstantVelocity && have_velocity_)
      dR = exp_quat(omega_hat_c_ * dt);
  }
  const double s = sigma * std::sqrt(dt);
  if (particle_velocity_active()) {
    // Each particle turns by its own velocity, then the velocity takes its random-walk step.
    const double sw = options_.velocity_noise_rad_s_per_sqrt_s * std::sqrt(dt);
    const double sr = options_.velocity_rotation_noise_rad_per_sqrt_s * std::sqrt(dt);
    for (size_t i = 0; i < particles_.size(); ++i) {
      const Eigen::Vector3d n(sr * normal(), sr * normal(), sr * normal());
      particles_[i] = (particles_[i] * exp_quat(vel_[i] * dt + n)).normalized();
      vel_[i] += Eigen::Vector3d(sw * normal(), sw * normal(), sw * normal());
    }
    t_ns_ = t_ns;
    compute_mean();
    return;
  }
  const bool drift = dR.vec().squaredNorm() > 0;
  for (Eigen::Quaterniond& q : particles_) {
    const Eigen::Vector3d n(s * normal(), s * normal(), s * normal());
    q = drift ? q * dR * exp_quat(n) : q * exp_quat(n);
    q.normalize();
  }
  t_ns_ = t_ns;
  compute_mean();
}

bool RotationParticleFilter::update(const Event* events, size_t n, const LogIntensityMapView& map) {
  if (!map.valid()) return false;
  for (size_t k = 0; k < n; ++k) {
    const Event& e = events[k];
    ++stats_.events;
    if (e.x >= width_ || e.y >= height_) {
      ++stats_.skipped_invalid;
      continue;
    }
    const uint32_t pixel = static_cast<uint32_t>(e.y) * static_cast<uint32_t>(width_) + e.x;
    if (std::isnan(bx_[pixel])) {
      ++stats_.skipped_invalid;
      continue;
    }
    if (!pending_.empty() && e.t_ns - pending_.front().t_ns > options_.max_batch_duration_ns) process_batch(map);
    pending_.push_back({e.t_ns, pixel, static_cast<int8_t>(e.polarity >= 0 ? 1 : -1)});
    if (static_cast<int>(pending_.size()) >= options_.batch_size) process_batch(map);
  }
  return true;
}

bool RotationParticleFilter::flush(const LogIntensityMapView& map) {
  if (!map.valid()) return false;
  if (!pending_.empty()) process_batch(map);
  return true;
}

void RotationParticleFilter::process_batch(const LogIntensityMapView& map) {
  int64_t t_batch = pending_.front().t_ns;
  for (const PendingEvent& e : pending_) t_batch = std::max(t_batch, e.t_ns);
  predict(t_batch);
  ++stats_.batches;
  if (++batch_id_ == 0) {  // stamp wrap-around: clear and start again
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    batch_id_ = 1;
  }

  // Events that weight the particles: previous position known, mosaic known there.
  sbx_.clear();
  sby_.clear();
  sbz_.clear();
  starget_.clear();
  sb2x_.clear();
  sb2y_.clear();
  sb2z_.clear();
  stau1_.clear();
  stau2_.clear();
  const float C = static_cast<float>(options_.contrast_threshold);
  const int W = map.width, H = map.height;
  const bool pv_model = particle_velocity_active();
  const bool relative = options_.measurement_model == RotationMeasurementModel::kRelativeMotion ||
                        (options_.measurement_model == RotationMeasurementModel::kAuto && (have_gyro_ || pv_model));
  const bool pv = relative && pv_model;  // the pixel's previous direction from each particle's velocity
  const double speed = pv ? vel_mean_.norm() : 0.0;  // rad/s
  const Eigen::Quaternionf ref_now_inv = ref_.conjugate().cast<float>();
  for (const PendingEvent& e : pending_) {
    if (stamp_[e.pixel] == batch_id_) {
      ++stats_.skipped_repeat_in_batch;
      continue;
    }
    stamp_[e.pixel] = batch_id_;
    if (options_.event_stride > 1 && (stride_counter_++ % static_cast<uint64_t>(options_.event_stride)) != 0) {
      ++stats_.skipped_stride;
      continue;
    }
    if (std::isnan(prev_u_[e.pixel])) {
      ++stats_.skipped_no_previous;
      continue;
    }
    const Eigen::Vector3f b(bx_[e.pixel], by_[e.pixel], bz_[e.pixel]);
    if (pv) {
      if (t_ns_ - prev_t_[e.pixel] > options_.relative_max_interval_ns ||
          1e-9 * static_cast<double>(t_ns_ - prev_t_[e.pixel]) * speed > options_.relative_max_path_rad) {
        ++stats_.skipped_long_interval;
        continue;
      }
      stau1_.push_back(1e-9f * static_cast<float>(t_ns_ - e.t_ns));
      stau2_.push_back(1e-9f * static_cast<float>(t_ns_ - prev_t_[e.pixel]));
      starget_.push_back(static_cast<float>(e.polarity) * C);
    } else if (relative) {
      // dR b = R_ref(t)^T R_ref(t_prev) b: the pixel's bearing at its previous event, in the
      // camera frame of now.
      const Eigen::Vector4f& c = prev_ref_[e.pixel];
      const Eigen::Vector3f b2 = ref_now_inv * (Eigen::Quaternionf(c[3], c[0], c[1], c[2]) * b);
      sb2x_.push_back(b2.x());
      sb2y_.push_back(b2.y());
      sb2z_.push_back(b2.z());
      starget_.push_back(static_cast<float>(e.polarity) * C);
    } else {
      const float l_prev = sample_index(map.data, W, H, prev_u_[e.pixel] * static_cast<float>(W) - 0.5f,
                                        prev_v_[e.pixel] * static_cast<float>(H) - 0.5f);
      if (std::isnan(l_prev)) {
        ++stats_.skipped_unknown_map;
        continue;
      }
      starget_.push_back(l_prev + static_cast<float>(e.polarity) * C);
    }
    sbx_.push_back(b.x());
    sby_.push_back(b.y());
    sbz_.push_back(b.z());
  }

  const size_t m = starget_.size();
  if (m > 0) {
    // Probes (probe_every_batches): six turned copies of the mean appended for the weighing only.
    const size_t n_real = particles_.size();
    const bool probe = options_.probe_every_batches > 0 && weighted_batch_counter_++ % options_.probe_every_batches == 0;
    if (probe) {
      for (int axis = 0; axis < 3; ++axis)
        for (double sgn : {1.0, -1.0}) {
          Eigen::Vector3d a = Eigen::Vector3d::Zero();
          a[axis] = sgn * options_.probe_offset_rad;
          particles_.push_back((mean_ * exp_quat(a)).normalized());
          if (!vel_.empty()) vel_.push_back(vel_mean_);
        }
    }
    const size_t np = particles_.size();
    stats_.particle_evaluations += static_cast<int64_t>(np * m);  // probes included (work)
    stats_.particle_batches += static_cast<int64_t>(n_real);
    ++stats_.weighted_batches;
    rot_.resize(9 * np);
    for (size_t i = 0; i < np; ++i) {
      const Eigen::Matrix3f R = particles_[i].toRotationMatrix().cast<float>();
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) rot_[9 * i + 3 * r + c] = R(r, c);
    }
    const float ku = static_cast<float>(W) * (0.5f / kPiF);
    const float kv = static_cast<float>(H) * (1.0f / kPiF);
    const float u_off = 0.5f * static_cast<float>(W) - 0.5f;  // (lon + pi) ku - 0.5
    const float nhiv = static_cast<float>(neg_half_inv_var_);
    const float floor_ll = static_cast<float>(floor_loglik_);
    const float* bx = sbx_.data();
    const float* by = sby_.data();
    const float* bz = sbz_.data();
    const float* target = starget_.data();
    const float* b2x = sb2x_.data();
    const float* b2y = sb2y_.data();
    const float* b2z = sb2z_.data();
    const float* data = map.data;
    // ll_[i * m + j]: log-likelihood of event j under particle i (max-mixture), NaN where the
    // particle looks at an unknown texel.
    ll_.resize(np * m);
    if (pv) {
      weigh_particle_velocity(m, map);
    } else if (linearize_batch(m, relative, W, H)) {
      ++stats_.linearized_batches;
      // Linearised: u_i = u0 + M delta_i per event and sample point (see linearize_batch).
      const float* lin = lin_.data();
      const size_t stride = relative ? 16 : 8;
      for (size_t i = 0; i < np; ++i) {
        const float ax = delta_[3 * i], ay = delta_[3 * i + 1], az = delta_[3 * i + 2];
        float* ll_i = &ll_[i * m];
        for (size_t j = 0; j < m; ++j) {
          const float* a = lin + stride * j;
          float L = sample_index(data, W, H, a[0] + a[2] * ax + a[3] * ay + a[4] * az,
                                 a[1] + a[5] * ax + a[6] * ay + a[7] * az);
          if (relative)
            L -= sample_index(data, W, H, a[8] + a[10] * ax + a[11] * ay + a[12] * az,
                              a[9] + a[13] * ax + a[14] * ay + a[15] * az);
          const float r = L - target[j];
          const float ll = nhiv * r * r;
          ll_i[j] = ll < floor_ll ? floor_ll : ll;
        }
      }
    } else {
    for (size_t i = 0; i < np; ++i) {
      const float* R = &rot_[9 * i];
      const float r00 = R[0], r01 = R[1], r02 = R[2], r10 = R[3], r11 = R[4], r12 = R[5], r20 = R[6], r21 = R[7],
                  r22 = R[8];
      float* ll_i = &ll_[i * m];
      for (size_t j = 0; j < m; ++j) {
        const float dx = r00 * bx[j] + r01 * by[j] + r02 * bz[j];
        const float dy = r10 * bx[j] + r11 * by[j] + r12 * bz[j];
        const float dz = r20 * bx[j] + r21 * by[j] + r22 * bz[j];
        const float lon = fast_atan2(dy, dx);
        const float polar = fast_atan2(std::sqrt(dx * dx + dy * dy), dz);
        float L = sample_index(data, W, H, lon * ku + u_off, polar * kv - 0.5f);
        if (relative) {  // minus the mosaic at the particle's direction of the previous event
          const float ex = r00 * b2x[j] + r01 * b2y[j] + r02 * b2z[j];
          const float ey = r10 * b2x[j] + r11 * b2y[j] + r12 * b2z[j];
          const float ez = r20 * b2x[j] + r21 * b2y[j] + r22 * b2z[j];
          L -= sample_index(data, W, H, fast_atan2(ey, ex) * ku + u_off,
                            fast_atan2(std::sqrt(ex * ex + ey * ey), ez) * kv - 0.5f);
        }
        const float r = L - target[j];
        const float ll = nhiv * r * r;
        ll_i[j] = ll < floor_ll ? floor_ll : ll;  // max-mixture; NaN (unknown texel) stays NaN
      }
    }
    }
    // An unknown texel says nothing about the particle: it gets the mean log-likelihood of the
    // particles that see a known texel for the same event (neutral), so the cloud is not pulled
    // towards the mapped part of the mosaic while the camera explores. An event no particle can
    // evaluate weights nobody.
    size_t known_events = 0;
    double probe_sum = std::nan("");
    // (Probes neither count nor set the fill: they take the real particles' fill.)
    for (size_t j = 0; j < m; ++j) {
      float sum = 0;
      int known = 0;
      bool any_nan = false;
      for (size_t i = 0; i < np; ++i) {
        const float v = ll_[i * m + j];
        if (std::isnan(v)) {
          any_nan = true;
        } else if (i < n_real) {
          sum += v;
          ++known;
        }
      }
      if (known > 0) {
        ++stats_.events_used;
        ++known_events;
      }
      if (!any_nan) continue;
      const float fill = known > 0 ? sum / static_cast<float>(known) : 0.0f;
      if (known == 0) ++stats_.skipped_unknown_map;
      for (size_t i = 0; i < np; ++i)
        if (std::isnan(ll_[i * m + j])) ll_[i * m + j] = fill;
    }
    if (probe) {
      double sum = 0;
      for (size_t i = n_real; i < np; ++i)
        for (size_t j = 0; j < m; ++j) sum += static_cast<double>(ll_[i * m + j]);
      probe_sum = known_events > 0 ? sum / static_cast<double>((np - n_real) * known_events) : std::nan("");
      particles_.resize(n_real);
      if (!vel_.empty()) vel_.resize(n_real);
    }
    double weighted_ll = 0;  // the batch's log-likelihood under the prior weights
    for (size_t i = 0; i < n_real; ++i) {
      const float* ll_i = &ll_[i * m];
      float acc = 0;
      for (size_t j = 0; j < m; ++j) acc += ll_i[j];
      weighted_ll += std::exp(log_w_[i]) * static_cast<double>(acc);
      log_w_[i] += static_cast<double>(acc);
    }
    if (known_events > 0) {
      last_loglik_ = weighted_ll / static_cast<double>(known_events);
      last_loglik_events_ = static_cast<int64_t>(known_events);
      if (probe && std::isfinite(probe_sum)) {
        last_probe_ = last_loglik_ - probe_sum;
        last_probe_t_ = t_ns_;
      }
    }
    normalize_weights();
    compute_mean();
    if (effective_sample_size() < options_.resample_ess_fraction * static_cast<double>(particles_.size())) resample();
  }

  // Every event of the batch, used or not, stores its pixel's position under the mean and the
  // reference rotation (which follows the mean unless the gyro drove this prediction).
  if (!have_gyro_) ref_ = mean_;
  const Eigen::Matrix3f Rm = mean_.toRotationMatrix().cast<float>();
  const Eigen::Vector4f ref_now = ref_.coeffs().cast<float>();
  for (const PendingEvent& e : pending_) {
    const Eigen::Vector3f d = Rm * Eigen::Vector3f(bx_[e.pixel], by_[e.pixel], bz_[e.pixel]);
    project_fraction(d.x(), d.y(), d.z(), &prev_u_[e.pixel], &prev_v_[e.pixel]);
    prev_t_[e.pixel] = e.t_ns;
    prev_ref_[e.pixel] = ref_now;
  }
  pending_.clear();
  update_velocity();
}

// kRelativeMotion with particle velocities: fills ll_[i * m + j] for every particle i and used event
// j (max-mixture log-likelihood; NaN where a sample is unknown). The bearing moved back by a
// particle's velocity over tau is b'(tau, w) = Exp(-w tau) b = b + c - tau/2 w x c + O(tau^3),
// c = tau b x w. While the cloud is tight (every particle within linearize_max_spread_rad of the
// mean and |w_i - w_m| tau within the same angle) the texel positions are linearised about the mean
// rotation R_m and mean velocity w_m (per event: the events with a longer tau, or near a pole, are
// projected exactly per particle): with R_i = R_m Exp(delta_i), w_i = w_m + e_i,
// R_i b'(tau, w_i) = R_m (b'_m + delta_i x b'_m + tau b x e_i) + second order, so a sample point is
// at (u0, v0) + M delta_i + N e_i, M = -J_pi R_m [b'_m]x, N = tau J_pi R_m [b]x (14 floats per
// point, two points per event). Otherwise every particle projects both points exactly.
void RotationParticleFilter::weigh_particle_velocity(size_t m, const LogIntensityMapView& map) {
  const size_t np = particles_.size();
  const int W = map.width, H = map.height;
  const float* data = map.data;
  const float ku = static_cast<float>(W) * (0.5f / kPiF), kv = static_cast<float>(H) * (1.0f / kPiF);
  const float u_off = 0.5f * static_cast<float>(W) - 0.5f;
  const float nhiv = static_cast<float>(neg_half_inv_var_);
  const float floor_ll = static_cast<float>(floor_loglik_);
  auto moved = [](const Eigen::Vector3f& b, const Eigen::Vector3f& w, float tau) {
    const Eigen::Vector3f c = tau * b.cross(w);
    return Eigen::Vector3f(b + c - 0.5f * tau * w.cross(c));
  };
  auto skew = [](const Eigen::Vector3f& v) {
    Eigen::Matrix3f k;
    k << 0.0f, -v.z(), v.y(), v.z(), 0.0f, -v.x(), -v.y(), v.x(), 0.0f;
    return k;
  };
  // Rotation offsets and velocity offsets from the mean; the largest velocity offset decides per
  // event whether its points may be linearised (|e| tau within the spread).
  bool lin = options_.linearize_max_spread_rad > 0;
  double max_e = 0;
  if (lin) {
    const double max_spread2 = options_.linearize_max_spread_rad * options_.linearize_max_spread_rad;
    delta_.resize(6 * np);
    const Eigen::Quaterniond mc = mean_.conjugate();
    for (size_t i = 0; i < np && lin; ++i) {
      Eigen::Quaterniond q = mc * particles_[i];
      if (q.w() < 0) q.coeffs() = -q.coeffs();
      const double vn = q.vec().norm();
      const Eigen::Vector3d d = vn > 1e-12 ? Eigen::Vector3d(q.vec() * (2.0 * std::atan2(vn, q.w()) / vn))
                                           : Eigen::Vector3d(2.0 * q.vec());
      const Eigen::Vector3d e = vel_[i] - vel_mean_;
      if (d.squaredNorm() > max_spread2) lin = false;
      max_e = std::max(max_e, e.norm());
      for (int a = 0; a < 3; ++a) {
        delta_[6 * i + a] = static_cast<float>(d[a]);
        delta_[6 * i + 3 + a] = static_cast<float>(e[a]);
      }
    }
  }
  lin_idx_.clear();
  exact_idx_.clear();
  if (lin) {
    const Eigen::Matrix3f Rm = mean_.toRotationMatrix().cast<float>();
    const Eigen::Vector3f wm = vel_mean_.cast<float>();
    const float max_tau = static_cast<float>(options_.linearize_max_spread_rad / std::max(max_e, 1e-9));
    lin_.resize(28 * m);
    for (size_t j = 0; j < m; ++j) {
      bool ok = stau2_[j] <= max_tau && stau1_[j] <= max_tau;
      const Eigen::Vector3f b(sbx_[j], sby_[j], sbz_[j]);
      const Eigen::Matrix3f Rbx = Rm * skew(b);
      for (int k = 0; k < 2 && ok; ++k) {
        const float tau = k == 0 ? stau1_[j] : stau2_[j];
        const Eigen::Vector3f bp = moved(b, wm, tau);
        const Eigen::Vector3f d = Rm * bp;
        const float rxy2 = d.x() * d.x() + d.y() * d.y();
        const float n2 = rxy2 + d.z() * d.z();
        if (!(rxy2 > 0.1f * n2)) {  // within ~18 deg of a pole (or not finite)
          ok = false;
          break;
        }
        const float rxy = std::sqrt(rxy2);
        Eigen::Matrix<float, 2, 3> J;
        J << -d.y() * ku / rxy2, d.x() * ku / rxy2, 0.0f,  //
            d.x() * d.z() * kv / (rxy * n2), d.y() * d.z() * kv / (rxy * n2), -rxy * kv / n2;
        const Eigen::Matrix<float, 2, 3> M = -J * (Rm * skew(bp));
        const Eigen::Matrix<float, 2, 3> N = tau * (J * Rbx);
        float* a = &lin_[28 * j + 14 * k];
        a[0] = fast_atan2(d.y(), d.x()) * ku + u_off;
        a[1] = fast_atan2(rxy, d.z()) * kv - 0.5f;
        for (int c = 0; c < 3; ++c) {
          a[2 + c] = M(0, c);
          a[5 + c] = N(0, c);
          a[8 + c] = M(1, c);
          a[11 + c] = N(1, c);
        }
      }
      (ok ? lin_idx_ : exact_idx_).push_back(static_cast<uint32_t>(j));
    }
  } else {
    for (size_t j = 0; j < m; ++j) exact_idx_.push_back(static_cast<uint32_t>(j));
  }
  if (!lin_idx_.empty()) ++stats_.linearized_batches;
  const float* L0 = lin_.data();
  for (size_t i = 0; i < np; ++i) {
    float* ll_i = &ll_[i * m];
    if (!lin_idx_.empty()) {
      const float* dl = &delta_[6 * i];
      const float d0 = dl[0], d1 = dl[1], d2 = dl[2], e0 = dl[3], e1 = dl[4], e2 = dl[5];
      for (uint32_t j : lin_idx_) {
        const float* a = L0 + 28 * j;
        const float* c = a + 14;
        const float La = sample_index(data, W, H, a[0] + a[2] * d0 + a[3] * d1 + a[4] * d2 + a[5] * e0 + a[6] * e1 + a[7] * e2,
                                      a[1] + a[8] * d0 + a[9] * d1 + a[10] * d2 + a[11] * e0 + a[12] * e1 + a[13] * e2);
        const float Lb = sample_index(data, W, H, c[0] + c[2] * d0 + c[3] * d1 + c[4] * d2 + c[5] * e0 + c[6] * e1 + c[7] * e2,
                                      c[1] + c[8] * d0 + c[9] * d1 + c[10] * d2 + c[11] * e0 + c[12] * e1 + c[13] * e2);
        const float r = La - Lb - starget_[j];
        const float ll = nhiv * r * r;
        ll_i[j] = ll < floor_ll ? floor_ll : ll;  // NaN (unknown texel) stays NaN
      }
    }
    if (exact_idx_.empty()) continue;
    const Eigen::Matrix3f R = particles_[i].toRotationMatrix().cast<float>();
    const Eigen::Vector3f w = vel_[i].cast<float>();
    for (uint32_t j : exact_idx_) {
      const Eigen::Vector3f b(sbx_[j], sby_[j], sbz_[j]);
      float L[2];
      for (int k = 0; k < 2; ++k) {
        const Eigen::Vector3f d = R * moved(b, w, k == 0 ? stau1_[j] : stau2_[j]);
        L[k] = sample_index(data, W, H, fast_atan2(d.y(), d.x()) * ku + u_off,
                            fast_atan2(std::sqrt(d.x() * d.x() + d.y() * d.y()), d.z()) * kv - 0.5f);
      }
      const float r = L[0] - L[1] - starget_[j];
      const float ll = nhiv * r * r;
      ll_i[j] = ll < floor_ll ? floor_ll : ll;
    }
  }
}

// Every particle's projection linearised about the mean: with R_i = R_m Exp(delta_i), the
// direction R_i b = R_m (b + delta_i x b) + O(|delta|^2), so a sample point's texel position is
// (u0, v0) + M delta_i with M = -J_pi(R_m b) R_m [b]x. Per event: one exact projection and a
// 2x3 matrix per sample point instead of one projection per particle. Refused (exact path) when
// the cloud is wider than linearize_max_spread_rad or a direction is within ~18 deg of a pole,
// where the equirectangular u is strongly curved. Fills lin_ (8 floats per sample point: u0, v0,
// M row-major) and delta_ (3 per particle).
bool RotationParticleFilter::linearize_batch(size_t m, bool relative, int W, int H) {
  if (options_.linearize_max_spread_rad <= 0) return false;
  const size_t np = particles_.size();
  delta_.resize(3 * np);
  const Eigen::Quaterniond mc = mean_.conjugate();
  const double max_spread2 = options_.linearize_max_spread_rad * options_.linearize_max_spread_rad;
  for (size_t i = 0; i < np; ++i) {
    Eigen::Quaterniond q = mc * particles_[i];
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    const double vn = q.vec().norm();
    const Eigen::Vector3d d = vn > 1e-12 ? Eigen::Vector3d(q.vec() * (2.0 * std::atan2(vn, q.w()) / vn))
                                         : Eigen::Vector3d(2.0 * q.vec());
    if (d.squaredNorm() > max_spread2) return false;
    delta_[3 * i] = static_cast<float>(d.x());
    delta_[3 * i + 1] = static_cast<float>(d.y());
    delta_[3 * i + 2] = static_cast<float>(d.z());
  }
  const Eigen::Matrix3f Rm = mean_.toRotationMatrix().cast<float>();
  const float ku = static_cast<float>(W) * (0.5f / kPiF), kv = static_cast<float>(H) * (1.0f / kPiF);
  const float u_off = 0.5f * static_cast<float>(W) - 0.5f;
  const size_t points = relative ? 2 : 1;
  lin_.resize(8 * points * m);
  for (size_t j = 0; j < m; ++j) {
    for (size_t k = 0; k < points; ++k) {
      const Eigen::Vector3f b = k == 0 ? Eigen::Vector3f(sbx_[j], sby_[j], sbz_[j]) : Eigen::Vector3f(sb2x_[j], sb2y_[j], sb2z_[j]);
      const Eigen::Vector3f d = Rm * b;
      const float rxy2 = d.x() * d.x() + d.y() * d.y();
      const float n2 = rxy2 + d.z() * d.z();
      if (!(rxy2 > 0.1f * n2)) return false;  // within ~18 deg of a pole (or not finite)
      const float rxy = std::sqrt(rxy2);
      Eigen::Matrix<float, 2, 3> J;
      J << -d.y() * ku / rxy2, d.x() * ku / rxy2, 0.0f,  //
          d.x() * d.z() * kv / (rxy * n2), d.y() * d.z() * kv / (rxy * n2), -rxy * kv / n2;
      Eigen::Matrix3f bx;
      bx << 0.0f, -b.z(), b.y(), b.z(), 0.0f, -b.x(), -b.y(), b.x(), 0.0f;
      const Eigen::Matrix<float, 2, 3> M = -J * (Rm * bx);
      float* a = &lin_[8 * (points * j + k)];
      a[0] = fast_atan2(d.y(), d.x()) * ku + u_off;
      a[1] = fast_atan2(rxy, d.z()) * kv - 0.5f;
      a[2] = M(0, 0), a[3] = M(0, 1), a[4] = M(0, 2);
      a[5] = M(1, 0), a[6] = M(1, 1), a[7] = M(1, 2);
    }
  }
  return true;
}

void RotationParticleFilter::normalize_weights() {
  double mx = -std::numeric_limits<double>::infinity();
  for (double l : log_w_) mx = std::max(mx, l);
  double sum = 0;
  for (size_t i = 0; i < log_w_.size(); ++i) sum += (w_[i] = std::exp(log_w_[i] - mx));
  const double log_sum = std::log(sum);
  for (size_t i = 0; i < log_w_.size(); ++i) {
    log_w_[i] -= mx + log_sum;
    w_[i] /= sum;
  }
}

void RotationParticleFilter::compute_mean() {
  size_t best = 0;
  for (size_t i = 1; i < w_.size(); ++i)
    if (w_[i] > w_[best]) best = i;
  const Eigen::Vector4d ref = particles_[best].coeffs();
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (size_t i = 0; i < particles_.size(); ++i) {
    const Eigen::Vector4d c = particles_[i].coeffs();
    sum += (c.dot(ref) < 0 ? -w_[i] : w_[i]) * c;
  }
  const double norm = sum.norm();
  mean_ = norm > 1e-12 ? Eigen::Quaterniond(sum / norm) : particles_[best];
  if (options_.motion_model == RotationMotionModel::kParticleVelocity && vel_.size() == particles_.size()) {
    vel_mean_.setZero();
    for (size_t i = 0; i < vel_.size(); ++i) vel_mean_ += w_[i] * vel_[i];
  }
}

void RotationParticleFilter::update_velocity() {
  const int64_t dt_ns = t_ns_ - vel_ref_t_ns_;
  if (dt_ns < options_.velocity_window_ns) return;
  const Eigen::Vector3d w = calib::so3_log(vel_ref_q_.conjugate() * mean_) / (1e-9 * static_cast<double>(dt_ns));
  omega_hat_c_ = have_velocity_ ? Eigen::Vector3d(omega_hat_c_ + options_.velocity_smoothing * (w - omega_hat_c_)) : w;
  have_velocity_ = true;
  vel_ref_q_ = mean_;
  vel_ref_t_ns_ = t_ns_;
}

Eigen::Vector3d RotationParticleFilter::angular_velocity_c() const {
  if (have_gyro_) return omega_gyro_c_;
  if (options_.motion_model == RotationMotionModel::kParticleVelocity) return vel_mean_;
  return have_velocity_ ? omega_hat_c_ : Eigen::Vector3d::Zero();
}

double RotationParticleFilter::effective_sample_size() const {
  double s = 0;
  for (double w : w_) s += w * w;
  return s > 0 ? 1.0 / s : 0.0;
}

std::vector<double> RotationParticleFilter::weights() const { return w_; }

void RotationParticleFilter::set_particles(const std::vector<Eigen::Quaterniond>& particles,
                                           const std::vector<double>& weights) {
  if (particles.empty() || particles.size() != weights.size())
    throw std::invalid_argument("set_particles: " + std::to_string(particles.size()) + " particles and " +
                                std::to_string(weights.size()) + " weights (expected equal counts >= 1)");
  double sum = 0;
  for (double w : weights) {
    if (!(w >= 0) || !std::isfinite(w)) throw std::invalid_argument("set_particles: weight not finite and >= 0");
    sum += w;
  }
  if (!(sum > 0)) throw std::invalid_argument("set_particles: weights sum to zero");
  particles_.resize(particles.size());
  for (size_t i = 0; i < particles.size(); ++i) particles_[i] = particles[i].normalized();
  if (vel_.size() != particles.size()) vel_.assign(particles.size(), vel_mean_);
  w_.resize(weights.size());
  log_w_.resize(weights.size());
  for (size_t i = 0; i < weights.size(); ++i) {
    w_[i] = weights[i] / sum;
    log_w_[i] = std::log(w_[i]);  // -inf for zero weights: such particles never come back
  }
  compute_mean();
}

// Systematic resampling (Kitagawa 1996): one uniform offset, N evenly spaced pointers into the
// cumulative weights; with min_particles, N = num_particles and then KLD-sampling's count.
void RotationParticleFilter::resample() {
  // Adaptive: back to num_particles, then down to KLD-sampling's count; fixed: the current count.
  const bool adaptive = options_.min_particles > 0 && options_.min_particles < options_.num_particles;
  const size_t n = particles_.size();
  const size_t n_out = adaptive ? static_cast<size_t>(options_.num_particles) : n;
  const double step = 1.0 / static_cast<double>(n_out);
  double u = step * static_cast<double>(next_u64() >> 11) * (1.0 / 9007199254740992.0);
  // KLD-sampling bins the predicted cloud (Fox: the samples after the motion model), i.e. the
  // particles before resampling with a non-negligible weight (> 0.1 / n): resampled duplicates
  // would under-count its spread.
  const size_t n_new = adaptive ? adaptive_count() : n_out;
  std::vector<Eigen::Quaterniond> out(n_out);
  std::vector<Eigen::Vector3d> out_v(n_out);
  double cum = w_[0];
  size_t k = 0;
  for (size_t i = 0; i < n_out; ++i) {
    while (u > cum && k + 1 < n) cum += w_[++k];
    out[i] = particles_[k];
    out_v[i] = vel_[k];
    u += step;
  }
  if (n_new < n_out) {  // a systematic subsample: every (n_out / n_new)-th of the ordered resampled set
    std::vector<Eigen::Quaterniond> sub(n_new);
    std::vector<Eigen::Vector3d> sub_v(n_new);
    for (size_t i = 0; i < n_new; ++i) {
      sub[i] = out[(2 * i + 1) * n_out / (2 * n_new)];
      sub_v[i] = out_v[(2 * i + 1) * n_out / (2 * n_new)];
    }
    out.swap(sub);
    out_v.swap(sub_v);
  }
  particles_.swap(out);
  vel_.swap(out_v);
  const double w = 1.0 / static_cast<double>(particles_.size());
  w_.assign(particles_.size(), w);
  log_w_.assign(particles_.size(), std::log(w));
  ++stats_.resamples;
  compute_mean();
}

// KLD-sampling's particle count (see min_particles): bins of kld_bin_rad on the rotation offsets
// Log(mean^T R_i) (first order: 2 vec(q) with q sign-aligned to the mean) of the particles whose
// weight exceeds 0.1 / n.
size_t RotationParticleFilter::adaptive_count() const {
  const size_t n_max = static_cast<size_t>(options_.num_particles);
  const Eigen::Quaterniond mc = mean_.conjugate();
  const double inv_bin = 1.0 / options_.kld_bin_rad;
  const double w_min = 0.1 / static_cast<double>(particles_.size());
  std::vector<uint64_t> bins;
  bins.reserve(particles_.size());
  for (size_t i = 0; i < particles_.size(); ++i) {
    if (!(w_[i] > w_min)) continue;
    Eigen::Quaterniond q = mc * particles_[i];
    if (q.w() < 0) q.coeffs() = -q.coeffs();
    uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      const double c = std::clamp(std::floor(2.0 * q.vec()[a] * inv_bin), -1048575.0, 1048575.0);
      key = (key << 21) | static_cast<uint64_t>(static_cast<int64_t>(c) + 1048576);
    }
    bins.push_back(key);
  }
  std::sort(bins.begin(), bins.end());
  const size_t k = static_cast<size_t>(std::unique(bins.begin(), bins.end()) - bins.begin());
  double n_kld = 0;
  if (k > 1) {
    const double km1 = static_cast<double>(k - 1);
    const double a = 2.0 / (9.0 * km1);
    const double b = 1.0 - a + std::sqrt(a) * options_.kld_z;
    n_kld = km1 / (2.0 * options_.kld_epsilon) * b * b * b;
  }
  const double lo = static_cast<double>(options_.min_particles);
  return static_cast<size_t>(std::ceil(std::clamp(n_kld, lo, static_cast<double>(n_max))));
}

void resolve_input_defaults(RotationParticleFilterOptions* o, bool gyro, int event_stride, int min_particles) {
  o->event_stride = event_stride > 0 ? event_stride : (gyro ? 4 : 1);
  o->min_particles = std::min(min_particles >= 0 ? min_particles : (gyro ? 20 : 40), o->num_particles);
}

}  // namespace evio::frontend
