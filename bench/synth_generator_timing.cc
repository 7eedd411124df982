// synth_generator_timing: how long synth::GenerateSample takes per scene, at
// two sizes, in wall time and process CPU time (the fairer number on a
// shared machine). What a training step pays for a new scene (see
// TrainOptions::scene_reuse), and what supersampling and JPEG compression
// add to it.
//
//   synth_generator_timing [samples per size, default 8] [supersampling, default 1]
//                          [JPEG quality of every view, 0 = none (default)]

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <utility>

#include <torch/torch.h>

#include "synth/generator.h"

int main(int argc, char** argv) {
  const int samples = argc > 1 ? std::atoi(argv[1]) : 8;
  const int supersampling = argc > 2 ? std::atoi(argv[2]) : 1;
  const int jpeg_quality = argc > 3 ? std::atoi(argv[3]) : 0;
  if (samples < 1 || supersampling < 1 || supersampling > 7 || supersampling % 2 == 0 || jpeg_quality < 0 ||
      jpeg_quality > 100) {
    std::fprintf(stderr,
                 "usage: synth_generator_timing [samples per size >= 1] [supersampling: 1, 3, 5 or 7] "
                 "[JPEG quality: 0 (none) to 100]\n");
    return 2;
  }
  for (const auto& [height, width] : {std::pair<int64_t, int64_t>{256, 320}, {512, 640}}) {
    dispmvs::synth::SynthConfig config;
    config.height = height;
    config.width = width;
    config.num_views = 6;
    config.supersampling = supersampling;
    config.jpeg_quality_min = config.jpeg_quality_max = jpeg_quality;
    dispmvs::synth::GenerateSample(config, 0, torch::kCPU);  // warm-up
    const std::clock_t cpu_start = std::clock();
    const auto start = std::chrono::steady_clock::now();
    for (int s = 1; s <= samples; ++s) dispmvs::synth::GenerateSample(config, s, torch::kCPU);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double cpu_seconds = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
    std::printf("%lldx%lld x %d views, %d x %d rays per pixel, JPEG quality %d, torch threads %d: %.3f s wall, "
                "%.3f s CPU per sample (mean of %d)\n",
                static_cast<long long>(width), static_cast<long long>(height), config.num_views, supersampling,
                supersampling, jpeg_quality, torch::get_num_threads(), seconds / samples, cpu_seconds / samples, samples);
  }
  return 0;
}
