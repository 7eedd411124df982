#pragma once
// COLMAP's fusion masks (`colmap stereo_fusion --StereoFusion.mask_path`),
// used by the geometric pass and fusion: for image NAME, the mask is
// MASK_DIR/NAME.png, or MASK_DIR/NAME itself when NAME ends in .png and the
// first does not exist. It is box-resampled to the depth map's size, and a
// pixel whose mask value (red channel; grey masks are their grey) is 0 is
// ignored: it gives no point and agrees with no other view, so a masked pixel
// is as if it had no depth. An image without a mask file is used whole, as
// COLMAP does.

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "fusion/geometric_filter.h"

namespace dispmvs::dense {

class ImageMasks {
 public:
  // No masks: Apply changes nothing.
  ImageMasks() = default;
  // Masks from `mask_dir`; throws colmap_io::IoError unless it is a folder.
  explicit ImageMasks(const std::filesystem::path& mask_dir);

  bool enabled() const { return !dir_.empty(); }
  const std::filesystem::path& dir() const { return dir_; }

  // The mask file of `image_name` (COLMAP's two names), nullopt if none.
  std::optional<std::filesystem::path> PathOf(const std::string& image_name) const;

  // The image's mask at width x height (CV_8U, 1 = used, 0 = ignored), or
  // an empty Mat when it has none (or masks are not enabled). A mask file that
  // cannot be read throws colmap_io::IoError: a damaged mask is not silently
  // taken as "use everything".
  cv::Mat Read(const std::string& image_name, int width, int height) const;

  // Sets the depth of the ignored pixels of `view` to 0. Returns how many
  // pixels the mask ignores (0 without a mask).
  std::size_t Apply(const std::string& image_name, fusion::DepthView* view) const;

  // Of `image_names`, how many have a mask file.
  std::size_t CountWithMask(const std::vector<std::string>& image_names) const;

 private:
  std::filesystem::path dir_;
};

}  // namespace dispmvs::dense
