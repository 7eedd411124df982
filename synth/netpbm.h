#pragma once
// Binary Netpbm images (P6 colour, P5 grey): the one image format that the
// LibTorch-only build (a bare GPU machine, no OpenCV) can read, so that photo
// textures reach training there too (train/gpu_train.sh converts photos to
// PPM with the machine's Python). The format is a short text header, then raw
// samples: a reader of a few dozen lines, not worth a dependency.

#include <string>

#include <torch/torch.h>

namespace dispmvs::synth {

// Decodes a binary PPM (P6) or PGM (P5) file with maxval 1..65535 (one byte
// per sample up to 255, two big-endian bytes above), header comments allowed,
// as a [3, H, W] float tensor in [0, 1] on the CPU (grey replicated to three
// channels). Throws std::runtime_error naming the file and what is wrong
// (missing, not P5/P6, bad header, truncated samples).
torch::Tensor ReadNetpbm(const std::string& path);

}  // namespace dispmvs::synth
