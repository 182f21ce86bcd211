// Motion segmentation by contrast maximisation (Stoffregen, Gallego, Drummond, Kleeman,
// Scaramuzza, "Event-Based Motion Segmentation by Motion Compensation", ICCV 2019): N clusters,
// each with its own warp; every event has soft associations p_kj (sum 1 over clusters). Cluster
// j's IWE is voted with weights p_.j; the objective is the sum over clusters of their contrast.
// Alternating optimisation: (1) each cluster's motion maximises its weighted contrast (BFGS, warm
// started); (2) associations are the clusters' blurred IWE values at the event's warped position,
// normalised over clusters (the event goes where it is in focus). Clusters whose total association
// falls below a share of the events die.
//
// Initialisation: k-means on local flows (CMax flow per image tile, k-means++ with a seed), or
// greedy (one motion fitted to all events, the next to the events the previous ones leave
// blurred, ...), or the previous window's clusters (streaming: refitted to the window first, then
// k-means proposals from the tiles they leave unexplained, for objects that appear).
//
// What the scene requires, stated criteria:
// - Cluster count (clusters = 0: automatic), decided with every cluster on the richest candidate
//   model (a rotating object is one similarity cluster but several flow ones). Start from
//   max_clusters proposals and, while the least useful cluster's gain is below min_cluster_gain,
//   merge it into the cluster whose motion is closest to its own on its events (a new proposal
//   that absorbs a cluster of the last window takes over its label), and re-optimise. A cluster's
//   gain is how much sharper its events are under its own motion than under the best other
//   cluster's: objective_j(own) / max_i objective_j(theta_i) - 1, with objective_j the objective of
//   the IWE of the events assigned to j (those whose most likely cluster it is). Optionally
//   (split_rounds > 0) split then: propose clusters for the image tiles whose local flow the
//   cluster holding them does not explain, alternate and merge again, while proposals survive.
// - Warp model per cluster, simplest first (flow 2 < rotation 3 < similarity 4 = flow_accel 4 <
//   similarity_accel 6 = 6dof 6 parameters; ties in the order given): a richer model replaces the
//   current one when it raises the cluster's objective by more than model_gain_per_parameter per
//   extra parameter (choose_warp_model in warp_model_selection.h, the rule `evio flow --model
//   auto` applies per window).
// Both decisions are returned with the numbers that made them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/mapping/cmax.h"
#include "evio/mapping/warp_model_selection.h"

namespace evio::mapping {

enum class SegmentationInit { kKmeans, kGreedy };

const char* segmentation_init_name(SegmentationInit i);  // "kmeans", "greedy"
std::optional<SegmentationInit> segmentation_init_from_name(const std::string& name);

struct SegmentationOptions {
  // IWE size, blur, pinhole, objective. The objective must be comparable across models and
  // clusters: kAuto here means the normalised gradient magnitude for every model.
  CmaxOptions cmax;
  int clusters = 0;           // fixed number of clusters (>= 1), or 0 = choose automatically
  int max_clusters = 5;       // automatic count: the most clusters considered (>= 1, <= 16)
  // Candidate warp models (sorted by parameter count); the count is decided on the richest, then
  // each cluster takes the simplest that is good enough; empty = {flow}. similarity_accel (a
  // constant acceleration) is not among the defaults: on accelerating objects it gains little
  // accuracy for its time, and on constant-velocity data small clusters take it with spurious
  // accelerations (the per-parameter penalty does not keep it out where it is not needed;
  // docs/results/segment.md). Ask for it when objects accelerate within a window.
  std::vector<WarpModel> models = {WarpModel::kFlow, WarpModel::kSimilarity};
  SegmentationInit init = SegmentationInit::kKmeans;
  int tile_px = 30;           // k-means initialisation: tile size of the local flows, px (>= 8)
  int min_tile_events = 40;   // tiles with fewer events give no local flow (>= 5)
  int iterations = 8;         // alternations of motion and association updates (>= 1)
  int motion_iterations = 6;  // BFGS iterations per cluster per alternation (>= 1)
  // Stop alternating when no association moves by more than this (0..1).
  double association_tolerance = 0.02;
  double min_cluster_share = 0.005;   // clusters with a smaller share of the events die (0..1)
  double min_cluster_gain = 0.06;     // automatic count: gain a cluster needs to survive (> 0)
  double model_gain_per_parameter = 0.01;  // relative objective gain per extra warp parameter (>= 0)
  // An event is noise (label -1) when the clusters' blurred IWEs at its warped positions sum to
  // less than this many times what its own vote alone puts there: a lone event scores about 1
  // (its own vote, shared among the clusters by its associations), one on an edge far more.
  double noise_support = 1.0;
  // With clusters (streaming, split rounds): a tile's local flow proposes a new cluster only when
  // it differs from the flow of the cluster holding most of the tile's events by more than this
  // displacement over the window, px (>= 0). Tile flows are translations of tile_px-wide patches:
  // a rotating object's differ from its field by about its rotation times tile_px / 2 over the window.
  double new_motion_px = 1.0;
  // Automatic count: after the merges, rounds of proposals for the tiles the clusters leave
  // unexplained (as above, against the cluster holding most of the tile's events), each kept
  // only if it survives the merges (>= 0; 0 = none). Off by default: a round did not improve the
  // accuracy consistently and costs time (docs/results/segment.md).
  int split_rounds = 0;
  int footprint_radius_px = 4;  // dilation of a cluster's footprint for the next window, px (>= 0)
  uint64_t seed = 1;          // k-means++ seeding
  bool Validate(std::string* why) const;
};

struct SegmentCluster {
  int id = -1;                 // label; persistent across windows when warm-started
  WarpModel model = WarpModel::kFlow;
  Eigen::VectorXd params;      // units: see cmax.h
  double events = 0;           // sum of associations
  double objective = 0;        // the cluster's weighted objective under its own motion
  double objective_other = 0;  // ... under the best other cluster's motion (0 with one cluster)
  double gain = 0;             // objective / objective_other - 1 (inf-free: 0 with one cluster)
  std::vector<ModelTrial> models;  // the model decision
  // Where the cluster's events were (pixels of its labelled events, dilated by
  // footprint_radius_px), at time footprint_t_ns (the window's t_ref); the next window starts
  // this cluster's associations from it, moved by the cluster's flow.
  MaskU8 footprint;
  int64_t footprint_t_ns = 0;
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();  // of its labelled events, px
};

// One step of the automatic count decision.
struct CountStep {
  int clusters = 0;          // clusters before this step
  bool removed = false;      // false: the count was accepted here
  int removed_id = -1;       // id of the removed cluster (-1 for a proposal of this window)
  WarpModel removed_model = WarpModel::kFlow;
  Eigen::VectorXd removed_params;  // its motion
  double smallest_gain = 0;  // its gain
  double sum_objective = 0;  // sum of the clusters' objectives before the step
};

struct SegmentationResult {
  std::vector<SegmentCluster> clusters;  // alive clusters, in id order
  // Associations, events x clusters (row k = event k), same cluster order; rows sum to 1.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> associations;
  std::vector<int> labels;   // per event: the id of its most likely cluster, or -1 (noise)
  std::vector<CountStep> count_steps;  // the automatic count's decisions (empty for a fixed count)
  int alternations = 0;      // alternations over all re-optimisations
  int evaluations = 0;       // objective evaluations over everything
  double sum_objective = 0;  // sum of the clusters' objectives
};

class MotionSegmenter {
 public:
  // Throws std::invalid_argument with the Validate() message for invalid options.
  explicit MotionSegmenter(const SegmentationOptions& options);
  const SegmentationOptions& options() const { return options_; }
  // The objective in use (options().cmax.objective with kAuto resolved: the normalised gradient
  // magnitude, comparable across models and clusters).
  CmaxObjective objective() const { return cm_options_.objective; }

  // Segments one window. previous (optional): clusters of the previous window (ids, models,
  // params) to start from; new clusters get ids from *next_id (incremented), which the caller
  // keeps across windows. With no previous clusters, ids start at *next_id too.
  SegmentationResult segment(const CmaxEvents& ev, const std::vector<SegmentCluster>* previous, int* next_id);

  // Alternating optimisation from given clusters and associations (weights[j][k], any
  // non-negative values; normalised per event), without count or model decisions: for user
  // initialisations and oracle runs (e.g. ground-truth associations in tests).
  SegmentationResult refine(const CmaxEvents& ev, const std::vector<SegmentCluster>& clusters,
                            const std::vector<std::vector<float>>& weights, int iterations);

  // Local flows of the k-means initialisation, for inspection: one (vx, vy) px/s per tile with
  // enough events, and the tile centres (px).
  void tile_flows(const CmaxEvents& ev, std::vector<Eigen::Vector2d>* flows, std::vector<Eigen::Vector2d>* centres);

 private:
  struct State;
  void alternate(const CmaxEvents& ev, State* s, int iterations);
  void update_associations(const CmaxEvents& ev, State* s);
  double cluster_objective(const CmaxEvents& ev, const State& s, int j, WarpModel m, const Eigen::VectorXd& p);
  void remove_cluster(State* s, int j, int into);
  double self_vote() const;
  void compute_gains(const CmaxEvents& ev, State* s);
  void decide_count(const CmaxEvents& ev, State* s, SegmentationResult* out);
  int add_proposals(const CmaxEvents& ev, State* s, int room, const std::vector<Eigen::Vector2d>& flows,
                    const std::vector<Eigen::Vector2d>& centres, WarpModel base, int* evaluations);
  SegmentationResult finish(const CmaxEvents& ev, State* s, int* next_id);

  SegmentationOptions options_;
  CmaxOptions cm_options_;  // options_.cmax with the objective resolved
};

}  // namespace evio::mapping
