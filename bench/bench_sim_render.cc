// Render speed of the simulator's scenes at DAVIS240 resolution (240 x 180, radtan distortion):
// panorama, planar room and sprites over it, supersample 1 and 2, with and without the flow
// image. The camera moves between renders as a hand-held one would (about 1 ms apart). The
// baseline is a straightforward double-precision panorama renderer (std::atan2 / std::asin,
// Texture::sample per pixel) run in the same process; ratios are against it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"
#include "evio/calib/geometry.h"
#include "evio/simulator/scene.h"

namespace {

using evio::simulator::CameraState;
using evio::simulator::PixelRays;
using evio::simulator::RenderedView;
using evio::simulator::RenderRequest;
using evio::simulator::Scene;

constexpr int kWidth = 240, kHeight = 180;

evio::calib::PinholeCamera davis_camera() {
  evio::calib::CameraIntrinsics in;
  in.width = kWidth;
  in.height = kHeight;
  in.fx = 199.1;
  in.fy = 198.7;
  in.cx = 121.3;
  in.cy = 88.9;
  in.model = evio::calib::DistortionModel::kRadtan;
  in.distortion = {-0.34, 0.12, 0.0007, -0.0004};
  return evio::calib::PinholeCamera(in);
}

// Hand-held-like motion: a slow wobble in all three axes plus a drift, sampled every 1 ms.
std::vector<CameraState> camera_path(int n) {
  std::vector<CameraState> path(n);
  for (int i = 0; i < n; ++i) {
    const double t = 1e-3 * i;
    CameraState& s = path[i];
    s.t_ns = static_cast<int64_t>(i) * 1'000'000;
    const Eigen::Vector3d phi(0.3 * std::sin(1.1 * t), 0.5 * std::sin(0.7 * t + 1), 0.2 * std::sin(1.9 * t));
    // Base orientation: camera z along world +x, level.
    Eigen::Matrix3d R0;
    R0.col(0) = -Eigen::Vector3d::UnitY();
    R0.col(1) = -Eigen::Vector3d::UnitZ();
    R0.col(2) = Eigen::Vector3d::UnitX();
    s.T_w_c = evio::calib::SE3(Eigen::Matrix3d(evio::calib::so3_exp(phi) * R0),
                               Eigen::Vector3d(0.2 * std::sin(0.5 * t), 0.1 * t, 1.5 + 0.05 * std::sin(2 * t)));
    s.v_c = Eigen::Vector3d(0.1, 0.05, 0.2);
    s.omega_c = Eigen::Vector3d(0.33, 0.35, 0.38);
  }
  return path;
}

std::shared_ptr<const evio::simulator::Texture> procedural(evio::simulator::ProceduralKind kind, int w, int h, uint64_t seed,
                                                     evio::simulator::TextureWrap wrap_u) {
  evio::simulator::ProceduralTextureOptions o;
  o.kind = kind;
  o.width = w;
  o.height = h;
  o.seed = seed;
  o.noise_scale_px = w / 16.0;
  o.octaves = 5;
  o.num_shapes = 60;
  return std::make_shared<const evio::simulator::Texture>(
      evio::simulator::make_procedural_texture(o, wrap_u, evio::simulator::TextureWrap::kClamp));
}

struct Fixture {
  std::vector<CameraState> path = camera_path(1000);
  std::unique_ptr<PixelRays> rays1, rays2;
  std::shared_ptr<const Scene> panorama, panorama_small, planar, sprites;

  Fixture() {
    const auto cam = davis_camera();
    rays1 = std::make_unique<PixelRays>(cam, 1);
    rays2 = std::make_unique<PixelRays>(cam, 2);
    using evio::simulator::ProceduralKind;
    using evio::simulator::TextureWrap;
    panorama = std::make_shared<evio::simulator::PanoramaScene>(
        procedural(ProceduralKind::kNoise, 4096, 2048, 1, TextureWrap::kRepeat));
    // The same kind of texture at 512 x 256: fits the caches, isolates the arithmetic.
    panorama_small = std::make_shared<evio::simulator::PanoramaScene>(
        procedural(ProceduralKind::kNoise, 512, 256, 1, TextureWrap::kRepeat));
    // A 6 x 6 x 3 m room around the camera: floor, ceiling, four walls and a box face.
    auto wall_tex = procedural(ProceduralKind::kShapes, 1024, 512, 2, TextureWrap::kClamp);
    auto floor_tex = procedural(ProceduralKind::kNoise, 1024, 1024, 3, TextureWrap::kClamp);
    std::vector<evio::simulator::TexturedPlane> planes;
    auto add = [&](Eigen::Vector3d c, Eigen::Vector3d u, Eigen::Vector3d v, double w, double h,
                   std::shared_ptr<const evio::simulator::Texture> tex) {
      evio::simulator::TexturedPlane p;
      p.center_w = c;
      p.axis_u_w = u;
      p.axis_v_w = v;
      p.width_m = w;
      p.height_m = h;
      p.texture = std::move(tex);
      planes.push_back(p);
    };
    const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Y = Eigen::Vector3d::UnitY(), Z = Eigen::Vector3d::UnitZ();
    add({0, 0, 0}, X, Y, 6, 6, floor_tex);
    add({0, 0, 3}, X, Y, 6, 6, floor_tex);
    add({3, 0, 1.5}, -Y, Z, 6, 3, wall_tex);
    add({-3, 0, 1.5}, Y, Z, 6, 3, wall_tex);
    add({0, 3, 1.5}, X, Z, 6, 3, wall_tex);
    add({0, -3, 1.5}, -X, Z, 6, 3, wall_tex);
    add({1.8, 0.3, 1.2}, -Y, Z, 0.8, 0.6, floor_tex);
    planar = std::make_shared<evio::simulator::PlanarScene>(planes, 0.1);
    std::vector<evio::simulator::Sprite> sp(3);
    for (int i = 0; i < 3; ++i) {
      sp[i].texture = wall_tex;
      sp[i].shape = i == 1 ? evio::simulator::SpriteShape::kEllipse : evio::simulator::SpriteShape::kRectangle;
      sp[i].width_px = 50 + 10 * i;
      sp[i].height_px = 40;
      sp[i].motion.centre_px = Eigen::Vector2d(60 + 60 * i, 90);
      sp[i].motion.velocity_pxps = Eigen::Vector2d(20, -10);
      sp[i].motion.amplitude_px = Eigen::Vector2d(20, 15);
      sp[i].motion.frequency_hz = Eigen::Vector2d(0.5, 0.7);
      sp[i].motion.angular_rate_radps = 0.5;
    }
    sprites = std::make_shared<evio::simulator::SpriteScene>(planar, sp);
  }
};

Fixture* g_fixture = nullptr;

void render_bench(benchmark::State& state, const Scene* scene, int supersample, bool flow) {
  const PixelRays& rays = supersample == 1 ? *g_fixture->rays1 : *g_fixture->rays2;
  RenderRequest req;
  req.flow = flow;
  RenderedView view;
  size_t i = 0;
  for (auto _ : state) {
    scene->render(g_fixture->path[i++ % g_fixture->path.size()], rays, req, &view);
    benchmark::DoNotOptimize(view.intensity.data);
  }
  state.SetItemsProcessed(state.iterations() * kWidth * kHeight);
}

// Baseline: a direct double-precision panorama renderer with the same footprint model.
void reference_panorama(benchmark::State& state) {
  const auto& pano = static_cast<const evio::simulator::PanoramaScene&>(*g_fixture->panorama);
  const evio::simulator::Texture& tex = pano.texture();
  const PixelRays& rays = *g_fixture->rays1;
  cv::Mat out(kHeight, kWidth, CV_32F);
  size_t i = 0;
  for (auto _ : state) {
    const Eigen::Matrix3d R = g_fixture->path[i++ % g_fixture->path.size()].T_w_c.rotation_matrix();
    for (int y = 0; y < kHeight; ++y) {
      float* row = out.ptr<float>(y);
      for (int x = 0; x < kWidth; ++x) {
        const Eigen::Vector3d d = R * rays.centre(x, y);
        const double lon = std::atan2(d.y(), d.x()), lat = std::asin(std::clamp(d.z(), -1.0, 1.0));
        const double u = (lon + M_PI) / (2 * M_PI) * tex.width(), v = (M_PI / 2 - lat) / M_PI * tex.height();
        const double a = rays.sample_angle_rad(x, y);
        const double fp = a * std::sqrt(tex.width() / (2 * M_PI) * tex.height() / M_PI / std::max(std::cos(lat), 1e-3));
        row[x] = tex.sample(u, v, fp);
      }
    }
    benchmark::DoNotOptimize(out.data);
  }
  state.SetItemsProcessed(state.iterations() * kWidth * kHeight);
}

}  // namespace

int main(int argc, char** argv) {
  Fixture fixture;
  g_fixture = &fixture;
  benchmark::RegisterBenchmark("render/reference_double_panorama_s1", reference_panorama)
      ->Unit(benchmark::kMicrosecond)->MinTime(0.5);
  benchmark::RegisterBenchmark("render/panorama512_s1", render_bench, fixture.panorama_small.get(), 1, false)
      ->Unit(benchmark::kMicrosecond)->MinTime(0.5);
  const std::pair<const char*, const Scene*> scenes[] = {
      {"panorama", fixture.panorama.get()}, {"planar", fixture.planar.get()}, {"sprites", fixture.sprites.get()}};
  for (const auto& [name, scene] : scenes) {
    for (int ss : {1, 2}) {
      for (bool flow : {false, true}) {
        const std::string label = std::string("render/") + name + "_s" + std::to_string(ss) + (flow ? "_flow" : "");
        benchmark::RegisterBenchmark(label.c_str(), render_bench, scene, ss, flow)
            ->Unit(benchmark::kMicrosecond)->MinTime(0.5);
      }
    }
  }
  benchmark::Initialize(&argc, argv);
  evio::bench::CollectingReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const auto ref = reporter.rate.find("render/reference_double_panorama_s1");
  const double base = ref != reporter.rate.end() ? ref->second : 0.0;
  for (const auto& [name, r] : reporter.rate) {
    std::printf(
        "{\"bench\": \"%s\", \"width\": %d, \"height\": %d, \"ns_per_pixel\": %.4g, \"ms_per_render\": %.4g, "
        "\"ratio_vs_reference\": %.3g}\n",
        name.c_str(), kWidth, kHeight, 1e9 / r, 1e3 * kWidth * kHeight / r, base > 0 ? r / base : 0.0);
  }
  return 0;
}
