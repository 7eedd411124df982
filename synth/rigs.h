#pragma once
// Camera rigs: where the cameras of one sample stand, and the fixed
// environment of that kind of capture (support surfaces and a background
// enclosure around everything). Free-standing objects are added afterwards
// by the scene builder, inside the reference camera's view at the depths
// the rig names, so every sample has structure where the reference looks.
//
//   kTable        object on a table seen from a hemisphere (DTU-like): the
//                 sources sit 5-25 degrees of azimuth and up to 12 of
//                 elevation from the reference, all looking at the table centre
//   kWalkThrough  a camera walking down a room/corridor: sources before and
//                 after the reference along the path, small rotations
//   kTurntable    a circle around the object at one elevation, sources at
//                 multiples of a 6-15 degree step on both sides
//   kOutdoor      ground, hills and far background: depths from about 1 to
//                 1000 units in the same image, small baselines
// All rigs work in scene units of about 1 (the generator applies the global
// metric scale afterwards). World z is up.

#include <string>
#include <vector>

#include "synth/camera.h"
#include "synth/scene.h"

namespace dispmvs::synth {

class Rng;

enum class RigKind { kTable, kWalkThrough, kTurntable, kOutdoor };
constexpr int kNumRigKinds = 4;
std::string RigName(RigKind kind);

// Intrinsics: horizontal field of view drawn uniformly in [fov_min, fov_max]
// per sample; each view then jitters its focal length (x and y
// independently) by up to +-focal_jitter relative and its principal point
// around the image centre ((W - 1) / 2, (H - 1) / 2) by a normal of std
// principal_jitter x image size (clipped at 3 std).
struct IntrinsicsRanges {
  int64_t height = 256, width = 320;
  double fov_min_deg = 40, fov_max_deg = 75;
  double focal_jitter = 0.03;
  double principal_jitter = 0.02;
};

struct Rig {
  RigKind kind = RigKind::kTable;
  std::vector<PinholeCamera> cameras;  // cameras[0] is the reference view
  std::vector<Primitive> environment;  // textures not yet assigned
  double object_depth_min = 1, object_depth_max = 2;  // reference-camera depths for free objects
};

// num_views >= 2 (the reference and at least one source).
Rig MakeRig(RigKind kind, int num_views, const IntrinsicsRanges& intrinsics, Rng& rng);

}  // namespace dispmvs::synth
