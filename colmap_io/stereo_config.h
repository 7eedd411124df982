#pragma once
// The two configuration files of a dense workspace (WORKSPACE/stereo/):
//
// patch-match.cfg: which images get a depth map and with which source views.
// Pairs of lines, a reference image name, then its sources:
//     image1.jpg
//     __auto__, 20          the 20 best images by view selection
//     image2.jpg
//     __all__               every other image
//     image3.jpg
//     image1.jpg, image2.jpg   an explicit, comma-separated list
// fusion.cfg: the images whose depth maps are fused, one name per line.
//
// Both readers follow COLMAP's: lines are trimmed (so Windows line endings and
// padding around names are harmless), blank lines and lines starting with '#'
// are skipped. Errors are IoErrors naming the file and the line.

#include <cstddef>
#include <filesystem>
#include <functional>
#include <istream>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "colmap_io/sparse_model.h"
#include "colmap_io/view_selection.h"

namespace dispmvs::colmap_io {

// The sources line of one patch-match.cfg entry.
struct SourceSpec {
  enum class Kind {
    kAuto,      // "__auto__, N": N images from view selection
    kAll,       // "__all__": every other image of the model
    kExplicit,  // "a.jpg, b.jpg": these images
  };

  static SourceSpec Auto(std::size_t max_num_sources);
  static SourceSpec All();
  static SourceSpec Explicit(std::vector<std::string> names);

  Kind kind = Kind::kAll;
  std::size_t max_num_sources = 0;  // kAuto only, >= 1
  std::vector<std::string> names;   // kExplicit only, non-empty

  bool operator==(const SourceSpec& other) const;
  bool operator!=(const SourceSpec& other) const { return !(*this == other); }
};

struct PatchMatchEntry {
  std::string reference;
  SourceSpec sources;

  bool operator==(const PatchMatchEntry& other) const {
    return reference == other.reference && sources == other.sources;
  }
};

// What image_undistorter writes for every image: "__auto__, 20".
constexpr std::size_t kColmapDefaultAutoSources = 20;
// Largest N accepted in "__auto__, N" (far above any useful value; it only
// rejects garbage).
constexpr std::size_t kMaxAutoSources = 100000;
// The sources per reference dispmvs_colmap takes by default (its
// --max_num_src_images), and dispmvs_eval --compare with it.
constexpr int kDefaultMaxNumSourceImages = 4;

// Parses patch-match.cfg. Throws IoError naming `source_name` and the line on:
// a reference with no sources line after it, a reference "name" that looks
// like a sources line (a keyword or a comma: a missing line shifted the pairs), "__auto__" without a
// count or with a count that is not a positive integer, "__all__" with extra
// fields, an empty or duplicated name in a list, a reference listed as its own
// source, and a reference that appears twice.
std::vector<PatchMatchEntry> ParsePatchMatchConfig(std::istream& in,
                                                   const std::string& source_name);
std::vector<PatchMatchEntry> ReadPatchMatchConfig(const std::filesystem::path& path);

// Writes atomically in the format above. Throws IoError naming `path` when an
// entry cannot be represented (empty name, a name with a comma, a line break,
// surrounding whitespace, a leading '#' or a leading UTF-8 byte order mark, or
// an invalid SourceSpec).
void WritePatchMatchConfig(const std::vector<PatchMatchEntry>& entries,
                           const std::filesystem::path& path);

// Parses fusion.cfg: one image name per line. Throws IoError naming
// `source_name` and the line for a duplicated name.
std::vector<std::string> ParseFusionConfig(std::istream& in, const std::string& source_name);
std::vector<std::string> ReadFusionConfig(const std::filesystem::path& path);
// Writes atomically; IoError naming `path` for names that would not read back.
void WriteFusionConfig(const std::vector<std::string>& names, const std::filesystem::path& path);

// The source image ids of `reference_image_id` under `spec`:
//   kExplicit: the named images, in the listed order; every name must be an
//              image of the model and differ from the reference;
//   kAll:      every other image of the model, by ascending image id;
//   kAuto:     SelectSourceViews(model, reference, N, view_selection).
// Throws IoError naming `config_name` (normally the patch-match.cfg path) and
// the missing image, and std::invalid_argument when the reference is not in
// the model. May return an empty list (kAuto with no overlapping image, or a
// one-image model with kAll); the caller decides whether to skip the image.
std::vector<image_t> ResolveSourceImages(const SourceSpec& spec, image_t reference_image_id,
                                         const SparseModel& model,
                                         const ViewSelectionOptions& view_selection,
                                         const std::string& config_name);

// One resolved patch-match.cfg entry: the unit of work of the dense step.
struct StereoProblem {
  image_t reference_image_id = 0;
  std::vector<image_t> source_image_ids;
};

// Resolves every entry, in file order: the reference must be an image of the
// model (IoError naming `config_name` otherwise), then ResolveSourceImages.
std::vector<StereoProblem> ResolvePatchMatchConfig(const std::vector<PatchMatchEntry>& entries,
                                                   const SparseModel& model,
                                                   const ViewSelectionOptions& view_selection,
                                                   const std::string& config_name);

// The depths the pose-based fallback below samples for a reference
// (e.g. PoseSampleDepths::For); nullopt when nothing says how far the scene is.
using SampleDepthsFunction =
    std::function<std::optional<std::pair<double, double>>(image_t reference_image_id)>;

// ResolvePatchMatchConfig, then the fallback of dispmvs_colmap's plan: an
// `__auto__` entry whose reference shares no sparse point with another image
// (COLMAP's rule gives it no source) takes the first max_num_sources images
// of RankSourceViewsByPose instead, sampling sample_depths(reference); with
// no depths (every camera centre equal) it keeps no source. Those references
// are added to `pose_selected` when it is given.
std::vector<StereoProblem> ResolvePatchMatchConfigWithPoseFallback(
    const std::vector<PatchMatchEntry>& entries, const SparseModel& model,
    const ViewSelectionOptions& view_selection, const std::string& config_name,
    const SampleDepthsFunction& sample_depths, std::set<image_t>* pose_selected = nullptr);

// What to use when a workspace has no patch-match.cfg: every image of the
// model, by ascending image id, with "__auto__, max_num_sources" (the same
// thing image_undistorter writes, with our N). Throws std::invalid_argument
// for max_num_sources == 0.
std::vector<PatchMatchEntry> AutoPatchMatchConfig(const SparseModel& model,
                                                  std::size_t max_num_sources);

// Caps N of every `__auto__, N` entry at max_num_sources (dispmvs_colmap's
// --max_num_src_images: image_undistorter writes `__auto__, 20`, more sources
// than the network takes); explicit lists and `__all__` stay as written.
void CapAutoSources(std::size_t max_num_sources, std::vector<PatchMatchEntry>* entries);

}  // namespace dispmvs::colmap_io
