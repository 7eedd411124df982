#pragma once
// The programs' default for the network's fine stage in bands of rows
// (DispMvsNetImpl::set_fine_band_pixels, dispmvs_colmap --band_megapixels).
// Free of LibTorch, so that dense/depth_estimator.h can name it.

namespace dispmvs::model {

// Megapixels of one band, halos included: a 4:3 image up to about 3
// megapixels (2000x1500) runs whole, a larger one in bands, and the fine
// stage's maps stay near 1 GB with four sources whatever the image size.
inline constexpr double kDefaultBandMegapixels = 4.0;

}  // namespace dispmvs::model
