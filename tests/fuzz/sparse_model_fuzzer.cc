// libFuzzer target for the sparse-model readers. The first input byte picks
// the reader (cameras, images or points3D), the rest is the file content.
// Built twice: as sparse_model_binary_fuzzer (DISPMVS_FUZZ_TEXT=0) for the
// .bin readers and as sparse_model_text_fuzzer (=1) for the .txt readers.
//
// Properties checked, besides "no crash, no sanitizer report, no huge
// allocation" (run with -rss_limit_mb):
//  * the readers throw nothing but IoError;
//  * whatever they accept, the writer can write, and reading that back and
//    writing it again gives the same bytes (a stable round trip).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "colmap_io/error.h"
#include "colmap_io/sparse_model_io.h"

#ifndef DISPMVS_FUZZ_TEXT
#error "define DISPMVS_FUZZ_TEXT to 0 (binary readers) or 1 (text readers)"
#endif

namespace {

using dispmvs::colmap_io::IoError;
using dispmvs::colmap_io::SparseModel;

using Reader = void (*)(std::istream&, const std::string&, SparseModel*);
using Writer = void (*)(const SparseModel&, std::ostream&, const std::string&);

struct FilePart {
  Reader read;
  Writer write;
};

#if DISPMVS_FUZZ_TEXT
constexpr FilePart kParts[] = {
    {dispmvs::colmap_io::ReadCamerasText, dispmvs::colmap_io::WriteCamerasText},
    {dispmvs::colmap_io::ReadImagesText, dispmvs::colmap_io::WriteImagesText},
    {dispmvs::colmap_io::ReadPoints3DText, dispmvs::colmap_io::WritePoints3DText},
};
#else
constexpr FilePart kParts[] = {
    {dispmvs::colmap_io::ReadCamerasBinary, dispmvs::colmap_io::WriteCamerasBinary},
    {dispmvs::colmap_io::ReadImagesBinary, dispmvs::colmap_io::WriteImagesBinary},
    {dispmvs::colmap_io::ReadPoints3DBinary, dispmvs::colmap_io::WritePoints3DBinary},
};
#endif

std::string Write(const FilePart& part, const SparseModel& model) {
  std::ostringstream out;
  part.write(model, out, "fuzz-output");
  return out.str();
}

SparseModel Read(const FilePart& part, const std::string& bytes) {
  std::istringstream in(bytes);
  SparseModel model;
  part.read(in, "fuzz-input", &model);
  return model;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const FilePart& part = kParts[data[0] % 3];
  const std::string content(reinterpret_cast<const char*>(data) + 1, size - 1);
  SparseModel model;
  try {
    model = Read(part, content);
  } catch (const IoError&) {
    return 0;  // rejected cleanly: the expected outcome for most inputs
  }
  std::string first;
  try {
    first = Write(part, model);
  } catch (const IoError&) {
    // The text writer refuses image names with whitespace; the text reader
    // never yields such names and the binary writer accepts any name.
    std::abort();
  }
  // Write(Read(Write(m))) == Write(m): nothing is lost or altered on the way.
  if (Write(part, Read(part, first)) != first) std::abort();
  return 0;
}
