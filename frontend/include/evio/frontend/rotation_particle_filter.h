// Rotation tracking against a log-intensity panorama with a particle filter on SO(3): the tracking
// half of Kim, Handa, Benosman, Ieng, Davison, "Simultaneous Mosaicing and Tracking with an Event
// Camera" (BMVC 2014). The camera only rotates and the scene is at infinity; the mosaic
// (equirectangular, calib/equirectangular.h convention, log intensity) is built elsewhere and only
// read here through LogIntensityMapView.
//
// Model and conventions (ARCHITECTURE.md): the state is R_w_c (camera -> world/mosaic frame), one
// unit quaternion per particle with a log-weight. Perturbations are right-multiplicative in the
// camera frame: R <- R * Exp(delta).
//  - Motion: R <- R * dR * Exp(n), n ~ N(0, sigma^2 dt I_3), dt the time step in s. Without gyro,
//    dR = I (random walk, sigma = motion_noise_rad_per_sqrt_s) or, with kConstantVelocity,
//    dR = Exp(w_hat_c dt) with the filter's own smoothed angular-velocity estimate, or, with
//    kParticleVelocity, each particle carries its own camera-frame angular velocity w_i:
//    R_i <- R_i Exp(w_i dt + n), w_i <- w_i + m, m ~ N(0, sigma_w^2 dt I_3). With gyro
//    samples (add_gyro, camera-frame rates), dR is the integral of the rates, linear between
//    samples (held beyond the last), and sigma = gyro_noise_rad_per_sqrt_s.
//  - Measurement (Kim et al.): an event at pixel x (unit bearing b(x) in the camera frame) with
//    polarity p says the log intensity seen by x changed by p*C since x's previous event. With
//    L the mosaic sampled bilinearly at the equirectangular projection pi(.), and R_prev(x) the
//    filter's mean rotation stored when x last fired,
//       z_i = L(pi(R_i b(x))) - L(pi(R_prev(x) b(x))),
//       p(z_i) = (1 - eps) N(z_i; p C, sigma_C^2) + eps / outlier_range,
//    evaluated as a max-mixture (Olson and Agarwal, RSS 2012): log p ~ max(log of the Gaussian
//    term, log of the outlier term), which is within log 2 of the sum and needs no exp/log per
//    event and particle. A batch multiplies the likelihoods of its events (log-weights add).
//  - Resampling: systematic (one seeded uniform) when the effective sample size 1 / sum w^2 falls
//    below resample_ess_fraction * N.
//    With min_particles the count adapts at each resampling (KLD-sampling, Fox 2003): as many
//    particles as the cloud's spread over kld_bin_rad bins calls for, within [min, num_particles].
//  - Estimate: the weighted chordal mean of the particles' quaternions, each sign-aligned with the
//    best particle, normalised. For concentrated clouds it equals the quaternion eigen-mean up to
//    fourth order in the spread, and it is exact for sets symmetric about a rotation.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/calib/fast_math.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend {

class EventUndistorter;

namespace detail {
// atan2 by a minimax polynomial (|error| < 1e-5 rad), used per event and particle for the
// projection: calib::fast_atan2.
using calib::fast_atan2;
}  // namespace detail

// A read-only view of an equirectangular log-intensity mosaic (calib::Equirectangular
// convention: u = (lon + pi) / (2 pi) * width wraps around, v = (pi/2 - lat) / pi * height with
// row 0 up, +z; texel (i, j) has its centre at (i + 0.5, j + 0.5)). Not owned: the memory must
// outlive every update() call that uses the view.
struct LogIntensityMapView {
  int width = 0;              // texels, >= 2
  int height = 0;             // texels, >= 2
  const float* data = nullptr;  // row-major width*height log intensities; NaN = unknown texel
  bool valid() const { return width >= 2 && height >= 2 && data != nullptr; }
  // Bilinear sample at continuous (u, v) (texel centres at +0.5), u wrapping with period width, v
  // clamped to the centres of the first and last rows. NaN when any of the four texels is unknown.
  float sample(float u, float v) const;
};

enum class RotationMotionModel {
  kRandomWalk,        // dR = I between measurements (Kim et al.)
  kConstantVelocity,  // dR = Exp(w_hat_c dt), w_hat_c the filter's smoothed angular velocity
  // Each particle carries an angular velocity w_i (camera frame, rad/s) with a random-walk
  // (constant-velocity) model: R_i <- R_i Exp(w_i dt + n), w_i <- w_i + m. With kRelativeMotion
  // (or kAuto) and no gyro, the measurement moves the pixel's previous direction back with the
  // particle's own velocity (see kRelativeMotion), so velocity hypotheses are weighed by the map.
  kParticleVelocity,
};
const char* rotation_motion_model_name(RotationMotionModel m);  // "random_walk", "constant_velocity", "particle_velocity"

// Where the measurement takes the log intensity "at the pixel's previous event" from.
enum class RotationMeasurementModel {
  // Kim et al.: the mosaic at the pixel's direction under the filter's mean rotation of that time
  // (fixed for every particle). The measurement is relative to the filter's own past estimate:
  // errors in it, and any mismatch between the mosaic's contrast and C, carry over like odometry
  // drift (a mosaic whose contrast is 15% low makes the tracker over-rotate).
  kPreviousMean,
  // The mosaic at the pixel's direction under the particle's own rotation moved back by the
  // reference rotation between the two events (gyro dead reckoning when the gyro drives the
  // prediction, else the filter's mean): z_i = L(pi(R_i b)) - L(pi(R_i dR b)), dR =
  // R_ref(t)^T R_ref(t_prev). Both samples move with the particle, so the particle is placed
  // against the mosaic itself and the displacement comes from the reference: no drift through
  // contrast mismatch. Twice the map samples of kPreviousMean.
  // With kParticleVelocity and no gyro, the reference is each particle's own velocity under a
  // constant-velocity assumption over the pixel's inter-event interval: with t the batch time
  // (the particles' time), t_e the event's and t_p the pixel's previous event's,
  //   z_i = L(pi(R_i Exp(-w_i (t - t_e)) b)) - L(pi(R_i Exp(-w_i (t - t_p)) b)),
  // (Exp(phi) b to second order in phi); events with t - t_p > relative_max_interval_ns are not used.
  kRelativeMotion,
  // kRelativeMotion while the gyro drives the prediction or the particles carry velocities
  // (kParticleVelocity), kPreviousMean otherwise: with the filter's own mean as the reference the
  // relative measurement leaves the rotation's scale free, and the estimate drifts far more than
  // with kPreviousMean (docs/results/mosaic.md).
  kAuto,
};
const char* rotation_measurement_model_name(RotationMeasurementModel m);  // "previous_mean", "relative_motion", "auto"

struct RotationParticleFilterOptions {
  // Particles. Default 100: beyond that the error stops falling (it is set by the
  // measurement, not by the sampling; without gyro the likelihood compares with the filter's own
  // past estimates, so the error behaves like odometry drift), while the cost grows linearly
  // (docs/results/mosaic.md, the filter alone on a known map).
  int num_particles = 100;
  // Adaptive particle count (KLD-sampling, Fox, IJRR 2003): at each resampling the rotation
  // offsets from the mean of the predicted cloud (the particles before resampling, weight above
  // 0.1 / n) are binned in cubes of kld_bin_rad (rad) per axis, and with k occupied bins the
  // new count is Fox's bound
  //   n = (k - 1) / (2 kld_epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) * kld_z)^3
  // (enough particles for a KL divergence below kld_epsilon, dimensionless, with probability
  // Phi(kld_z)) clamped to [min_particles, num_particles] (a systematic subsample of
  // the resampled set). min_particles (<= num_particles; 0 = num_particles = fixed count).
  // A tight cloud (gyro-driven) needs few particles, a wide one keeps up to num_particles.
  // Defaults: bins of 2 mrad (about a third of a texel at 1024 texels per turn) and epsilon 0.5
  // (k = 10 bins: 22 particles); Fox's usual 0.05 asks for at least 66 particles from k = 2 on,
  // so a 100-particle cloud would hardly ever shrink. `evio mosaic` uses min_particles 20 with the
  // gyro (a gyro-driven cloud is tight: about the same error as 100 fixed particles at a fraction
  // of the cost) and 40 without (fewer let the events-only error grow); see
  // resolve_input_defaults below and docs/design-notes.md (Mosaic).
  int min_particles = 0;
  double kld_bin_rad = 0.002;
  double kld_epsilon = 0.5;
  double kld_z = 2.326;  // Phi(2.326) = 0.99
  // Events per measurement update (default 10). Particles are predicted once per batch, to
  // the time of its last event; larger batches amortise prediction, weighting and resampling.
  int batch_size = 10;
  // One event in every event_stride weighs the particles (default 1 = all); the others only
  // record their pixel's previous event. At millions of events per second neighbouring events
  // carry nearly the same information, so a stride trades little accuracy for speed (the
  // particles' cost is linear in the events used).
  int event_stride = 1;
  // Project each event once under the mean and move it to every particle with the projection's
  // Jacobian (first order in the particle's offset from the mean) while every particle is within
  // this angle of the mean, rad (default 0.02: second-order error below 0.03 texel at 1024 px
  // width); 0 = always project exactly per particle. Directions near the poles use the exact path.
  double linearize_max_spread_rad = 0.02;
  // A batch is closed early when the next event is more than this after its first event, ns
  // (default 1 ms), so sparse streams are not held back.
  int64_t max_batch_duration_ns = 1'000'000;
  // Motion model when no gyro sample is available.
  RotationMotionModel motion_model = RotationMotionModel::kRandomWalk;
  RotationMeasurementModel measurement_model = RotationMeasurementModel::kAuto;
  // Random-walk noise density without gyro, rad/sqrt(s) (default 0.3: 1 mrad of spread per
  // 10 us batch; chosen on the known-map scenario, docs/results/mosaic.md).
  double motion_noise_rad_per_sqrt_s = 0.3;
  // Noise density with gyro-driven prediction, rad/sqrt(s) (default 0.03; a wider prediction
  // only spreads the cloud and raises the error, docs/results/mosaic.md). Covers the gyro's white
  // noise, residual bias and the camera-IMU time alignment, so it is far above a real gyro's noise
  // density (~0.003 rad/s/sqrt(Hz)).
  double gyro_noise_rad_per_sqrt_s = 0.03;
  // Gyro samples older than this (relative to the prediction time) are not used, ns (default
  // 20 ms): the filter falls back to motion_model.
  int64_t gyro_max_age_ns = 20'000'000;
  // Event contrast threshold C, log-intensity units (default 0.2).
  double contrast_threshold = 0.2;
  // Standard deviation sigma_C of z around p*C, log-intensity units (default 0.1): event
  // generation noise plus mosaic and interpolation error.
  double likelihood_std = 0.1;
  // Outlier probability eps (default 0.1), and the width of the uniform outlier density,
  // log-intensity units (default 2.0). The outlier floor must lie below the
  // Gaussian's peak (checked by Validate).
  double outlier_probability = 0.1;
  double outlier_range = 2.0;
  // Resample when ESS < fraction * N (default 0.5; 0 never, 1 always).
  double resample_ess_fraction = 0.5;
  // Standard deviation of the initial spread around reset()'s rotation, rad (default 0: all
  // particles at the given rotation).
  double initial_spread_rad = 0.0;
  // Angular velocity from the mean rotation: w = Log(R(t0)^T R(t1)) / (t1 - t0) over windows of at
  // least velocity_window_ns (ns, default 2 ms), smoothed exponentially with weight
  // velocity_smoothing (default 0.5) on each new window.
  int64_t velocity_window_ns = 2'000'000;
  double velocity_smoothing = 0.5;
  // kParticleVelocity: white angular-acceleration noise density on each particle's velocity,
  // rad/s/sqrt(s) (default 2), the rotation's own noise density on top of the velocity
  // (replaces motion_noise_rad_per_sqrt_s), rad/sqrt(s) (default 0.03), and the standard
  // deviation of the velocities set by set_velocity() around the given one, rad/s (default
  // 0.5). The velocity noise must let the cloud follow the fastest motion (too little loses it at
  // high speed) without widening it at slow speed; the rotation noise on top is small, since too
  // little loses fast motion and more loses tracking elsewhere. Chosen on the known-map scenario
  // at 60-500 deg/s (bench/rotation_pf_table; docs/results/mosaic.md).
  double velocity_noise_rad_s_per_sqrt_s = 2.0;
  double velocity_rotation_noise_rad_per_sqrt_s = 0.03;
  double initial_velocity_spread_rad_s = 0.5;
  // kRelativeMotion with particle velocities: an event whose pixel's previous event is more than
  // relative_max_interval_ns before the batch time (ns, default 100 ms), or whose path under
  // the mean velocity since then is longer than relative_max_path_rad (rad, default 0.1:
  // about 16 texels at 1024 per turn), is not used (a constant velocity over a long path is a poor
  // model). The time cap must leave slow motion enough events (a short cap alone starves a slow
  // pan); the path cap bounds the constant-velocity error at high speed. Chosen on the known-map
  // scenario at 60-500 deg/s (docs/results/mosaic.md).
  int64_t relative_max_interval_ns = 100'000'000;
  double relative_max_path_rad = 0.1;
  uint64_t seed = 1;  // seed of every random choice (process noise, resampling)
  // Tracking-quality probes: every probe_every_batches-th weighted batch (0: never) is also
  // weighed under six rotations of the mean turned by +-probe_offset_rad (rad, default 0.01;
  // at most linearize_max_spread_rad when that is on, so linearised batches stay linearised) about each camera axis,
  // with the mean velocity; they never enter the filter. last_probe_contrast() is the cloud's
  // weighted mean log-likelihood per event minus the probes' mean: clearly positive while the
  // estimate sits on the map's optimum, near zero (or negative) when the filter is lost, whatever
  // the scene's own likelihood level.
  int probe_every_batches = 0;
  double probe_offset_rad = 0.01;

  bool Validate(std::string* why) const;
};

struct RotationParticleFilterStats {
  int64_t events = 0;                  // events passed to update()
  int64_t events_used = 0;             // events that weighted the particles
  int64_t skipped_no_previous = 0;     // the pixel had no earlier event since reset()
  int64_t skipped_unknown_map = 0;     // the mosaic is unknown at the previous position, or for every particle
  int64_t skipped_repeat_in_batch = 0; // the pixel already fired earlier in the same batch
  int64_t skipped_long_interval = 0;   // particle velocities: the pixel's previous event is older than relative_max_interval_ns
  int64_t skipped_stride = 0;          // left out by event_stride
  int64_t skipped_invalid = 0;         // outside the sensor, or a pixel without a bearing
  int64_t batches = 0;
  int64_t resamples = 0;
  int64_t linearized_batches = 0;      // batches weighted through the linearised projection
  int64_t gyro_predictions = 0;        // predictions driven (at least partly) by the gyro
  int64_t particle_evaluations = 0;    // particles (and probes) x used events, summed over batches (the filter's work)
  int64_t particle_batches = 0;        // particles summed over the batches with used events (mean = / their count)
  int64_t weighted_batches = 0;        // batches with at least one used event
};

class RotationParticleFilter {
 public:
  // bearings: unit bearing (camera frame) of every sensor pixel, row-major width*height; a
  // non-finite or zero entry marks a pixel whose events are ignored. Throws std::invalid_argument
  // on invalid options or a size mismatch.
  RotationParticleFilter(int sensor_width, int sensor_height, std::vector<Eigen::Vector3f> bearings,
                         const RotationParticleFilterOptions& options = {});
  // Bearings from the undistortion lookup table (invalid pixels ignored).
  RotationParticleFilter(const EventUndistorter& undistorter, const RotationParticleFilterOptions& options = {});

  // All particles at R_w_c (plus initial_spread_rad), equal weights, time t_ns; forgets every
  // pixel's previous event, pending events, gyro samples and the angular-velocity estimate.
  void reset(const Eigen::Quaterniond& R_w_c, int64_t t_ns);

  // Camera-frame angular velocity sample, rad/s, at t_ns (camera clock): the caller converts an
  // IMU sample as omega_c = R_c_b * (gyro_b - bias_b) and shifts its time to the camera clock
  // (see camera_rate_from_imu). Samples must come in time order; predictions integrate the rate
  // linearly interpolated between samples and held beyond the last one, so add each sample before
  // the events that follow it, and the first sample after a batch's events before that batch
  // (else its last interval is held at the earlier rate, which lags by up to a sample period).
  void add_gyro(int64_t t_ns, const Eigen::Vector3d& omega_c_rad_s);
  static Eigen::Vector3d camera_rate_from_imu(const ImuSample& imu, const Eigen::Quaterniond& R_c_b,
                                              const Eigen::Vector3d& gyro_bias_b = Eigen::Vector3d::Zero());

  // kParticleVelocity: every particle's angular velocity (camera frame, rad/s) to omega_c plus
  // N(0, initial_velocity_spread_rad_s^2 I) (e.g. the bootstrap's last rate after reset()).
  void set_velocity(const Eigen::Vector3d& omega_c_rad_s);

  // Moves the particles to t_ns with the motion model (gyro when fresh samples exist). Times
  // before the filter's time are ignored (no backward prediction).
  void predict(int64_t t_ns);

  // Adds events (time-ordered up to small disorder) to the pending batch and processes every
  // complete batch against `map`. Events of an incomplete batch stay pending for the next call
  // (flush() processes them), so results do not depend on how the stream is chunked. Returns
  // false (and processes nothing) when the map view is invalid.
  bool update(const Event* events, size_t n, const LogIntensityMapView& map);
  bool update(const std::vector<Event>& events, const LogIntensityMapView& map) {
    return update(events.data(), events.size(), map);
  }
  // Processes the pending events as a (short) batch.
  bool flush(const LogIntensityMapView& map);

  // Estimate at time(): weighted mean rotation R_w_c.
  Eigen::Quaterniond mean() const { return mean_; }
  int64_t time_ns() const { return t_ns_; }
  // Angular velocity, rad/s: with a fresh gyro sample the latest camera-frame rate given to
  // add_gyro; with kParticleVelocity the particles' weighted mean velocity; otherwise the smoothed
  // difference of mean rotations (velocity_window_ns). The world
  // version is mean() * angular_velocity_c() (a mapper's mosaic pixel velocity of an event with
  // world bearing d is d(pi)/d(d) * (omega_w x d)).
  Eigen::Vector3d angular_velocity_c() const;
  Eigen::Vector3d angular_velocity_w() const { return mean_ * angular_velocity_c(); }
  double effective_sample_size() const;
  // Tracking quality of the latest weighted batch: the mean, over its events that some particle
  // could evaluate, of the log-likelihood (relative to the Gaussian's peak, floored by the outlier
  // probability) under the particles' weights before the batch; NaN before any. A lost filter
  // scores lower than a tracking one, but the level depends on the scene and the map:
  // last_probe_contrast() is the scene-independent test.
  double last_batch_loglik() const { return last_loglik_; }
  int64_t last_batch_loglik_events() const { return last_loglik_events_; }
  // The latest probed batch (probe_every_batches): its weighted mean log-likelihood per event minus
  // the probes' mean, and the batch's time; NaN / 0 before any.
  double last_probe_contrast() const { return last_probe_; }
  int64_t last_probe_t_ns() const { return last_probe_t_; }
  const RotationParticleFilterStats& stats() const { return stats_; }
  const RotationParticleFilterOptions& options() const { return options_; }

  // Particle access (tests, diagnostics). Weights are normalised (sum 1).
  const std::vector<Eigen::Quaterniond>& particles() const { return particles_; }
  // kParticleVelocity: per particle angular velocity (camera frame, rad/s); zeros otherwise.
  const std::vector<Eigen::Vector3d>& particle_velocities() const { return vel_; }
  std::vector<double> weights() const;
  // Replaces the particle set (weights >= 0 with a positive sum, normalised here; sizes must
  // match, any count >= 1) and recomputes the mean; throws std::invalid_argument otherwise. The
  // particle velocities (kParticleVelocity) are kept when the count is unchanged, else all set to
  // the previous mean velocity.
  void set_particles(const std::vector<Eigen::Quaterniond>& particles, const std::vector<double>& weights);
  // Systematic resampling now, regardless of the ESS.
  void resample();

 private:
  struct PendingEvent {
    int64_t t_ns;
    uint32_t pixel;
    int8_t polarity;
  };
  void process_batch(const LogIntensityMapView& map);
  bool linearize_batch(size_t m, bool relative, int W, int H);
  void weigh_particle_velocity(size_t m, const LogIntensityMapView& map);
  bool particle_velocity_active() const;
  void normalize_weights();
  size_t adaptive_count() const;
  void compute_mean();
  void update_velocity();
  Eigen::Quaterniond gyro_increment(int64_t t0, int64_t t1);
  bool gyro_fresh(int64_t t_ns) const;
  float normal();
  uint64_t next_u64();

  int width_, height_;
  RotationParticleFilterOptions options_;
  std::vector<float> bx_, by_, bz_;  // bearings per pixel (SoA); NaN where invalid
  double neg_half_inv_var_ = 0;      // -1 / (2 sigma_C^2)
  double floor_loglik_ = 0;          // outlier log-likelihood relative to the Gaussian peak (< 0)

  std::vector<Eigen::Quaterniond> particles_;
  std::vector<Eigen::Vector3d> vel_;  // kParticleVelocity: angular velocity per particle (camera, rad/s)
  Eigen::Vector3d vel_mean_ = Eigen::Vector3d::Zero();
  std::vector<double> log_w_;  // normalised log-weights
  std::vector<double> w_;      // normalised weights
  Eigen::Quaterniond mean_ = Eigen::Quaterniond::Identity();
  int64_t t_ns_ = 0;

  // Per pixel: equirectangular position (u / width, v / height, so independent of the map's
  // resolution) of the pixel's direction under the mean at its previous event (NaN: none since
  // reset), that event's time, and the batch stamp for repeats.
  std::vector<float> prev_u_, prev_v_;
  std::vector<int64_t> prev_t_;
  // kRelativeMotion: the reference rotation at the pixel's previous event (x, y, z, w; NaN: none).
  std::vector<Eigen::Vector4f> prev_ref_;
  // Reference rotation R_ref: integrates the gyro increments while the gyro drives the prediction,
  // equals the mean otherwise.
  Eigen::Quaterniond ref_ = Eigen::Quaterniond::Identity();
  std::vector<uint32_t> stamp_;
  uint32_t batch_id_ = 0;
  uint64_t stride_counter_ = 0;

  std::vector<PendingEvent> pending_;
  // Scratch of the batch being processed (SoA of the events that weight the particles).
  std::vector<float> sbx_, sby_, sbz_, starget_;
  std::vector<float> sb2x_, sb2y_, sb2z_;  // kRelativeMotion: the bearing moved back, dR b
  std::vector<float> stau1_, stau2_;       // particle velocities: t - t_e and t - t_p, s
  std::vector<float> rot_;  // per-particle float rotation matrices, 9 floats each
  std::vector<float> ll_;   // per particle and used event log-likelihood of the batch
  double last_loglik_ = std::numeric_limits<double>::quiet_NaN();  // last_batch_loglik()
  int64_t last_loglik_events_ = 0;
  double last_probe_ = std::numeric_limits<double>::quiet_NaN();
  int64_t last_probe_t_ = 0;
  int64_t weighted_batch_counter_ = 0;
  std::vector<float> lin_;    // linearised projections of the batch (linearize_batch)
  std::vector<uint32_t> lin_idx_, exact_idx_;  // particle velocities: events weighed linearised / exactly
  std::vector<float> delta_;  // per particle Log(mean^T R_i) (particle velocities: and w_i - w_mean, 6 floats)

  std::deque<std::pair<int64_t, Eigen::Vector3d>> gyro_;
  Eigen::Vector3d omega_gyro_c_ = Eigen::Vector3d::Zero();
  int64_t gyro_last_t_ns_ = 0;
  bool have_gyro_ = false;

  Eigen::Vector3d omega_hat_c_ = Eigen::Vector3d::Zero();
  Eigen::Quaterniond vel_ref_q_ = Eigen::Quaterniond::Identity();
  int64_t vel_ref_t_ns_ = 0;
  bool have_velocity_ = false;

  uint64_t rng_state_ = 0;
  std::vector<float> gauss_table_;  // N(0,1) samples indexed by the RNG
  uint64_t gauss_bits_ = 0;
  int gauss_left_ = 0;

  RotationParticleFilterStats stats_;
};

// The settings that depend on whether a gyro drives the prediction, for the fields left "by input":
// event_stride 0 -> 4 with the gyro (a gyro-driven cloud is tight, neighbouring events add little)
// and 1 without; min_particles -1 -> 20 with the gyro and 40 without (a velocity-carrying cloud
// needs more), never above num_particles (a smaller num_particles gives a fixed count). Values set
// explicitly (stride > 0, min_particles >= 0) are kept. docs/results/mosaic.md has the measurements.
void resolve_input_defaults(RotationParticleFilterOptions* o, bool gyro, int event_stride, int min_particles);

}  // namespace evio::frontend
