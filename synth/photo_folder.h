#pragma once
// Photographs from a folder for photo textures (texture.h): any folder of
// the user's pictures, e.g. the photos in Debian's python3-skimage data folder
// (astronaut, chelsea, coffee, ...; not motorcycle_*, which
// bench/motorcycle_check.sh evaluates on), or a wallpaper package
// (gnome-backgrounds: mostly .webp graphics).
//
// Binary PPM/PGM files are decoded by the project itself (synth/netpbm.h) in
// every build; the other formats need OpenCV, which the LibTorch-only build
// (a bare GPU machine) lacks: there they are skipped with a warning
// (train/gpu_train.sh converts photos to PPM first).
// PhotoFolderDecodesAllFormats() tells which build this is.

#include <cstdint>
#include <ostream>
#include <string>

#include "synth/texture.h"

namespace dispmvs::synth {

struct PhotoFolderOptions {
  int max_photos = 64;   // the first ones in name order (memory: ~2.4 MB each at 512 px)
  int max_side = 512;    // larger photos are shrunk (area averaging) to this longest side
  int min_side = 16;     // smaller ones are skipped with a warning
};

bool PhotoFolderDecodesAllFormats();

// Every .png, .jpg, .jpeg, .bmp, .tif, .tiff, .webp, .ppm or .pgm file
// directly in `folder` (case-insensitive extension, name order), decoded as
// RGB in [0, 1]. Files that cannot be decoded (in a build without OpenCV:
// any but PPM/PGM), or are too small, are skipped with a warning line on
// `warnings` (when not null). Throws std::invalid_argument when the folder
// does not exist or yields no photo.
PhotoSet LoadPhotoFolder(const std::string& folder, const PhotoFolderOptions& options = {},
                         std::ostream* warnings = nullptr);

}  // namespace dispmvs::synth
