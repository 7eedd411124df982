// dispmvs_test_drop_sparse_points SPARSE_DIR: rewrites the sparse model in
// SPARSE_DIR (binary or text, kept as it was) with no 3-D points and no 2-D
// observations: the model of a workspace whose poses are known but whose
// sparse points are gone (or were never triangulated). Used by the
// command-line tests of dispmvs_colmap; exit status 1 with a message on error.

#include <exception>
#include <filesystem>
#include <iostream>

#include "colmap_io/sparse_model.h"
#include "colmap_io/sparse_model_io.h"

int main(int argc, char** argv) {
  using namespace dispmvs::colmap_io;
  if (argc != 2) {
    std::cerr << "usage: dispmvs_test_drop_sparse_points SPARSE_DIR\n";
    return 1;
  }
  try {
    const std::filesystem::path dir = argv[1];
    const SparseModelFormat format = DetectSparseModelFormat(dir);
    SparseModel model = ReadSparseModel(dir);
    model.points3D.clear();
    for (auto& [image_id, image] : model.images) image.points2D.clear();
    if (format == SparseModelFormat::kBinary) {
      WriteSparseModelBinary(model, dir);
    } else {
      WriteSparseModelText(model, dir);
    }
    std::cout << "dropped the sparse points of " << dir.string() << " (" << model.images.size()
              << " images kept)\n";
    return 0;
  } catch (const std::exception& error) {
    std::cerr << "error: " << error.what() << '\n';
    return 1;
  }
}
