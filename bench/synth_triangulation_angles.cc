// synth_triangulation_angles: how wide the generated scenes' baselines are,
// as the angle each source view subtends with the reference at a point of
// the scene: the point on the reference's optical axis at the median depth of
// its ground truth. Rendered small (64 x 48), since only the depths' median
// is needed; one line per rig and one for all (percentiles of the angle over
// (scene, source) pairs, and the share beyond 15 and 30 degrees).
//
//   synth_triangulation_angles [scenes, default 300]

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "synth/generator.h"

namespace {

double Percentile(std::vector<double> values, double fraction) {
  std::sort(values.begin(), values.end());
  return values[static_cast<size_t>(std::lround(fraction * static_cast<double>(values.size() - 1)))];
}

void PrintRow(const std::string& name, const std::vector<double>& angles) {
  if (angles.empty()) return;
  const auto share_above = [&](double limit) {
    return static_cast<double>(std::count_if(angles.begin(), angles.end(), [&](double a) { return a > limit; })) /
           static_cast<double>(angles.size());
  };
  std::printf("%-12s %6zu  %6.1f %6.1f %6.1f %6.1f %6.1f   %5.3f %5.3f\n", name.c_str(), angles.size(),
              Percentile(angles, 0.1), Percentile(angles, 0.5), Percentile(angles, 0.9), Percentile(angles, 0.99),
              *std::max_element(angles.begin(), angles.end()), share_above(15), share_above(30));
}

}  // namespace

int main(int argc, char** argv) {
  const int scenes = argc > 1 ? std::atoi(argv[1]) : 300;
  if (scenes < 1) {
    std::fprintf(stderr, "usage: synth_triangulation_angles [scenes >= 1]\n");
    return 2;
  }
  dispmvs::synth::SynthConfig config;  // the training scenes' generator, rigs drawn per scene
  config.height = 48;
  config.width = 64;
  config.num_views = 6;
  std::map<std::string, std::vector<double>> by_rig;
  std::vector<double> all;
  for (int seed = 0; seed < scenes; ++seed) {
    const dispmvs::synth::SynthScene scene = dispmvs::synth::DrawScene(config, seed);
    const dispmvs::synth::SynthSample sample = dispmvs::synth::RenderSample(scene, config, torch::kCPU);
    const torch::Tensor depth = sample.depths[0][0].to(torch::kDouble);
    const torch::Tensor valid = depth.masked_select(depth > 0);
    if (valid.numel() == 0) continue;
    // The cameras are at unit scale, the rendered depths metric.
    using dispmvs::synth::Vec3;
    const dispmvs::synth::PinholeCamera& first = scene.cameras[0];
    const Vec3 reference = first.Center();
    const Vec3 axis = dispmvs::synth::Transposed(first.rotation) * Vec3{0, 0, 1};  // camera z in the world
    const Vec3 point = reference + (valid.median().item<double>() / scene.scale) * axis;
    for (size_t v = 1; v < scene.cameras.size(); ++v) {
      const Vec3 a = reference - point, b = scene.cameras[v].Center() - point;
      const double cosine = dispmvs::synth::Dot(a, b) / (dispmvs::synth::Norm(a) * dispmvs::synth::Norm(b));
      const double degrees = std::acos(std::clamp(cosine, -1.0, 1.0)) * 180.0 / M_PI;
      by_rig[sample.rig].push_back(degrees);
      all.push_back(degrees);
    }
  }
  std::printf("triangulation angle of each source with the reference, degrees (%d scenes, %d views)\n", scenes,
              config.num_views);
  std::printf("%-12s %6s  %6s %6s %6s %6s %6s   %5s %5s\n", "rig", "pairs", "p10", "p50", "p90", "p99", "max", ">15",
              ">30");
  for (const auto& [rig, angles] : by_rig) PrintRow(rig, angles);
  PrintRow("all", all);
  return 0;
}
