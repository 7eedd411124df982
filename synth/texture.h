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
//
// Photo textures: a spec with photo >= 0 takes its base colour from that
// photograph of a PhotoSet (e.g. a folder of the user's pictures, see
// photo_folder.h) instead of the pattern, tiled over the surface with
// mirrored repeats (no seams): at rotated, scaled coordinates (ru, rv) (as the
// patterns use, in photo widths), the photo of W x H pixels is read with
// bilinear interpolation at pixel (M(ru) * (W - 1), M(rv * W / H) * (H - 1)),
// M(t) = 1 - |(t mod 2) - 1| (so the photo keeps its aspect ratio). Real
// photographs bring what procedural patterns lack: natural edges, shading
// and clutter at every scale.

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
  int photo = -1;  // index into the PhotoSet; -1: the procedural pattern
};

// Photographs for photo textures: [3, H, W] floating tensors in [0, 1] on the
// CPU, H, W >= 2.
using PhotoSet = std::vector<torch::Tensor>;

// Throws std::invalid_argument naming the first photo that is not as above.
void CheckPhotoSet(const PhotoSet& photos);

// A random texture: pattern drawn uniformly, colours, scales and orientation
// drawn from ranges that keep the pattern visible on a surface about one UV
// unit across that fills part of the image.
TextureSpec RandomTexture(Rng& rng);

// A random photo texture: one of `num_photos` (>= 1) photos, tiled 0.5 to 3
// times per UV unit at a random angle, with a faint detail layer.
TextureSpec RandomPhotoTexture(Rng& rng, int num_photos);

// Albedo [N,3] for points with texture index `texture` ([N] int64, indexing
// `textures`; -1 means no surface and yields `empty_color`) and uv ([N,2],
// floating). The result has uv's dtype and device. Photo textures read
// `photos`, which must then hold their index (std::invalid_argument if not).
torch::Tensor EvaluateAlbedo(const std::vector<TextureSpec>& textures,
                             const torch::Tensor& texture, const torch::Tensor& uv,
                             const std::array<double, 3>& empty_color = {0, 0, 0},
                             const PhotoSet* photos = nullptr);

}  // namespace dispmvs::synth
