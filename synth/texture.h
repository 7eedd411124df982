#pragma once
// Procedural albedo textures with some of the statistics of real images.
//
// A texture is a pure function of (texture spec, UV): the same surface point
// gets the same albedo in every view, whatever the viewing distance or pixel
// grid. Each texture combines one base pattern, which sets the kind of
// structure (the variety matters for learning to match), with a multi-octave
// noise "detail" layer that every pattern gets:
//   kNoise     fractal value noise (several octaves): natural, stochastic
//   kPolygons  Voronoi cells with random grey levels: hard-edged polygons
//   kStripes   parallel bands of random levels: hard straight edges
//   kBricks    offset bricks with jittered brightness and mortar lines
//   kChecker   checkerboard with per-cell brightness jitter: repeated pattern
//   kGradient  slow smooth ramps: almost no local structure
//   kFlat      a uniform colour: low-texture patches the network must
//              interpolate over (detail amplitude is kept tiny for these)
// The pattern value p in [0, 1] blends two colours; the detail layer then
// modulates brightness multiplicatively. Results are clamped to [0, 1].

#include <torch/torch.h>

#include <array>
#include <cstdint>
#include <vector>

namespace dispmvs::synth {

class Rng;

enum class Pattern { kNoise, kPolygons, kStripes, kBricks, kChecker, kGradient, kFlat };
constexpr int kNumPatterns = 7;

struct TextureSpec {
  Pattern pattern = Pattern::kNoise;
  std::array<double, 3> color_a{0.5, 0.5, 0.5};
  std::array<double, 3> color_b{0.5, 0.5, 0.5};
  double frequency = 4;         // pattern cells (or periods) per UV unit
  double angle = 0;             // orientation of stripes, bricks, gradients (radians)
  int octaves = 4;              // octaves of the noise pattern (the detail layer has 4)
  double detail = 0.2;          // detail layer amplitude: brightness x (1 +- detail)
  double detail_frequency = 8;  // base frequency of the detail layer
  double jitter = 0.3;          // per-cell brightness jitter (bricks, checker)
  uint32_t seed = 0;
};

// A random texture: pattern drawn uniformly, colours, scales and orientation
// drawn from ranges that keep the pattern visible on a surface about one UV
// unit across that fills part of the image.
TextureSpec RandomTexture(Rng& rng);

// Albedo [N,3] for points with texture index `texture` ([N] int64, indexing
// `textures`; -1 means no surface and yields `empty_color`) and uv ([N,2],
// floating). The result has uv's dtype and device.
torch::Tensor EvaluateAlbedo(const std::vector<TextureSpec>& textures,
                             const torch::Tensor& texture, const torch::Tensor& uv,
                             const std::array<double, 3>& empty_color = {0, 0, 0});

}  // namespace dispmvs::synth
