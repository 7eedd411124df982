#pragma once
// Fills a rig's environment with random textured objects.
//
// Each object is centred on the ray of a random reference pixel (up to 10%
// outside the image, so some objects are cut by the border) at a depth drawn
// log-uniformly in the rig's object depth range, with a size proportional
// to that depth (angular radius about 2-17 degrees), so objects are visible
// at every depth and occlude each other. Shapes: quads, boxes, thin boxes
// (boards and rods), spheres, cylinders (some thin: poles) and height-field
// blocks, in random orientations. Objects are shrunk where they would
// contain or touch a camera. Every primitive gets its own random texture.

#include "synth/rigs.h"
#include "synth/scene.h"

namespace dispmvs::synth {

class Rng;

// With num_photos > 0 and photo_probability > 0, each texture is a photo
// texture (RandomPhotoTexture) with that probability; otherwise no extra
// random numbers are drawn, so scenes stay those of a build without photos.
struct PhotoTextureChoice {
  int num_photos = 0;
  double photo_probability = 0;
};

Scene BuildScene(const Rig& rig, int num_objects, int64_t height, int64_t width, Rng& rng,
                 const PhotoTextureChoice& photos = {});

}  // namespace dispmvs::synth
