// dispmvs_bench: time per view and peak memory of one DispMVS forward pass
// (inference, no gradients), with the share of time per network stage.
//
//   dispmvs_bench [--sizes 640x512,1600x1152] [--sources 5] [--config small,paper]
//                 [--precision fp32,bf16] [--coarse_iterations N] [--fine_iterations N] [--device cpu|cuda[:i]]
//                 [--threads 1,2] [--warmup 1] [--reps 3] [--refinement none|ncc]
//                 [--memory 1|0] [--block_cache_mb MB] [--band_megapixels MP]
//
// Random weights and images: the cost of a pass does not depend on their
// values (the network has no data-dependent control flow). For every
// configuration, precision, size and thread count it runs --warmup passes, then --reps
// plain passes (their median and minimum are the time per view), then --reps
// passes with the stage timer attached (model/stage_timer.h) for the
// breakdown. On CUDA the timed passes synchronise at every stage boundary, so
// only their shares are reported, not their total.
//
// Peak memory: on the CPU, the largest growth of the resident set during a
// pass (Linux VmHWM, reset before each pass through /proc/self/clear_refs;
// without that, the peak since the process started), measured first, in a
// forked child whose allocations of 128 KiB and more get their own mappings
// (MapLargeAllocations), so that freed buffers leave the resident set and the
// peak follows the live tensors rather than the allocator's history. On CUDA,
// the caching allocator's peak of allocated bytes during a pass. The timings
// then run with the allocator as the programs set it
// (model/host_allocator.h: freed memory kept for reuse;
// model/large_block_cache.h: blocks of 32 MiB and more kept and reused, with
// --block_cache_mb as their budget, 0 = glibc's mappings as before the
// cache). --memory 0 skips the memory measurement (it runs every pass with
// its large buffers mapped afresh, several times slower at large sizes).
//
// --refinement ncc adds the photometric refinement that dispmvs_colmap runs
// after the network by default (model/photometric_refinement.h) to every
// pass, with its default settings, on the pass's own depth; its share of the
// time is the table's "refine" column, and the peak memory includes it. Its
// cost does not depend on the values either, except through memory
// locality: a random network's depth scatters the sampled source pixels more
// than a real one's.

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <malloc.h>
#include <sys/wait.h>
#include <unistd.h>

#include <torch/cuda.h>
#include <torch/torch.h>

#ifdef DISPMVS_BENCH_CUDA_MEMORY
#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAFunctions.h>
#endif

#include "model/config.h"
#include "model/device.h"
#include "src/program_main.h"
#include "model/dispmvs_net.h"
#include "model/fine_stage_bands.h"
#include "model/host_allocator.h"
#include "model/large_block_cache.h"
#include "model/photometric_refinement.h"
#include "model/precision.h"
#include "model/stage_timer.h"

namespace {

using dispmvs::model::DispMvsInput;
using dispmvs::model::DispMvsNet;
using dispmvs::model::kNumNetStages;
using dispmvs::model::ModelConfig;
using dispmvs::model::NetStage;
using dispmvs::model::NetStageName;
using dispmvs::model::Precision;
using dispmvs::model::StageTimer;

struct ImageSize {
  int64_t width = 0;
  int64_t height = 0;
};

struct Options {
  std::vector<ImageSize> sizes{{640, 512}};
  int64_t sources = 5;
  std::vector<std::string> configs{"small"};
  std::vector<std::string> precisions{"fp32"};  // auto, fp32, bf16 (model/precision.h)
  int64_t coarse_iterations = 0;  // 0: the configuration's own
  int64_t fine_iterations = 0;
  std::string device = "cpu";
  std::vector<int64_t> threads{2};
  int64_t warmup = 1;
  int64_t reps = 3;
  bool refine = false;  // --refinement ncc
  bool memory = true;   // --memory 0: no peak-memory child
  int64_t block_cache_mb = static_cast<int64_t>(dispmvs::model::LargeBlockCacheOptions{}.max_cached_bytes >> 20);
  double band_megapixels = dispmvs::model::kDefaultBandMegapixels;  // --band_megapixels
  dispmvs::model::PhotometricRefinementOptions refinement;  // --refine_propagation_rounds, _levels
};

constexpr const char* kUsage =
    "usage: dispmvs_bench [options]\n"
    "Time per view and peak memory of the DispMVS network (random weights and images),\n"
    "with the share of time per stage.\n"
    "  --sizes WxH[,WxH...]     image sizes (default 640x512)\n"
    "  --sources N              source views per reference (default 5)\n"
    "  --config small,paper     network configurations: paper, small (random start) and/or\n"
    "                           paper_v2, small_v2 (model v2: segment volume, match start) (small)\n"
    "  --precision P[,P...]     arithmetic of the GRU update's convolutions: fp32, bf16, or auto\n"
    "                           (bf16 on a CPU with native bf16, else fp32) (default fp32)\n"
    "  --coarse_iterations N    override the configuration's GRU iterations (0: keep)\n"
    "  --fine_iterations N      same for the fine stage\n"
    "  --device cpu|cuda|cuda:<index> (default cpu)\n"
    "  --threads T[,T...]       intra-op CPU threads (default 2)\n"
    "  --warmup N               untimed passes first (default 1)\n"
    "  --reps N                 timed passes, and as many again for the breakdown (default 3)\n"
    "  --memory 1|0             measure each row's peak memory first, in a child process (1)\n"
    "  --band_megapixels MP     the fine stage in bands of rows of about MP megapixels each,\n"
    "                           as dispmvs_colmap runs it; 0 = the whole image (BAND)\n"
    "  --block_cache_mb MB      budget of kept large tensor blocks for the timings, 0 = no\n"
    "                           cache: glibc maps every block of 32 MiB and more afresh\n"
    "                           (model/large_block_cache.h) (BLOCKCACHE)\n"
    "  --refinement none|ncc    ncc: each pass also runs the photometric refinement of\n"
    "                           dispmvs_colmap's default, timed as the 'refine' column (none)\n"
    "  --refine_steps K         with ncc: the search's hypotheses on each side\n"
    "                           (dispmvs_colmap --refine_steps) (STEPS)\n"
    "  --refine_propagation_rounds K  with ncc: the refinement's propagation rounds\n"
    "                           (dispmvs_colmap --refine_propagation_rounds) (ROUNDS)\n"
    "  --refine_propagation_levels K  with ncc: jumps per round (dispmvs_colmap\n"
    "                           --refine_propagation_levels) (LEVELS)\n"
    "  --refine_propagation_scale S  with ncc: 1, 2 or 4, the resolution propagation runs\n"
    "                           at (dispmvs_colmap --refine_propagation_scale) (SCALE)\n"
    "  --refine_full_resolution_rounds K  with ncc and scale 2 or 4: propagation rounds at\n"
    "                           full resolution after the search (dispmvs_colmap\n"
    "                           --refine_full_resolution_rounds) (FULLROUNDS)\n"
    "  --refine_full_resolution_levels K  with ncc: jumps per full-resolution round\n"
    "                           (dispmvs_colmap --refine_full_resolution_levels) (FULLLEVELS)\n"
    "  --refine_sweep_hypotheses K  with ncc: the sweep's most depths, 0 = off\n"
    "                           (dispmvs_colmap --refine_sweep_hypotheses) (SWEEP)\n"
    "  --refine_unseen_slope_radius R  with ncc: planes extended over pixels no source\n"
    "                           sees, 0 = off (dispmvs_colmap --refine_unseen_slope_radius) (UNSEEN)\n"
    "  --refine_trusted_plane_ncc C  with ncc: long-range planes from pixels with NCC >= C,\n"
    "                           0 = off (dispmvs_colmap --refine_trusted_plane_ncc) (TRUSTED)\n"
    "  --refine_trusted_plane_axis_anchors K  with ncc: long-range planes also from the nearest\n"
    "                           anchors along the row (2), row and column (4), 0 = the nearest\n"
    "                           alone (dispmvs_colmap --refine_trusted_plane_axis_anchors) (AXES)\n"
    "  --refine_window_shift S  with ncc: the best of windows shifted by S pixels, 0 = the\n"
    "                           centred window alone (dispmvs_colmap --refine_window_shift) (SHIFT)\n"
    "  --refine_local_plane_radius R  with ncc: local planes over (2R+1)^2 pixels, 0 = off\n"
    "                           (dispmvs_colmap --refine_local_plane_radius) (LOCAL)\n"
    "  --refine_local_plane_max_change C  with ncc: their largest relative change\n"
    "                           (dispmvs_colmap --refine_local_plane_max_change) (LOCALCHANGE)\n";

// kUsage with the refinement's defaults (dispmvs_colmap's) filled in.
std::string Usage() {
  const dispmvs::model::PhotometricRefinementOptions defaults;
  std::string usage = kUsage;
  const auto fill = [&](const std::string& name, int64_t value) {
    usage.replace(usage.find(name), name.size(), "(" + std::to_string(value) + ")");
  };
  fill("(STEPS)", defaults.steps);
  fill("(ROUNDS)", defaults.propagation_rounds);
  fill("(LEVELS)", defaults.propagation_levels);
  fill("(SCALE)", defaults.propagation_scale);
  fill("(FULLROUNDS)", defaults.full_resolution_rounds);
  fill("(FULLLEVELS)", defaults.full_resolution_levels);
  fill("(SWEEP)", defaults.sweep_hypotheses);
  fill("(UNSEEN)", defaults.unseen_slope_radius);
  fill("(AXES)", defaults.trusted_plane_axis_anchors);
  fill("(SHIFT)", defaults.window_shift);
  fill("(LOCAL)", defaults.local_plane_radius);
  fill("(BLOCKCACHE)",
       static_cast<int64_t>(dispmvs::model::LargeBlockCacheOptions{}.max_cached_bytes >> 20));
  std::ostringstream trusted;
  trusted << "(" << defaults.trusted_plane_min_ncc << ")";
  usage.replace(usage.find("(TRUSTED)"), 9, trusted.str());
  std::ostringstream band;
  band << "(" << dispmvs::model::kDefaultBandMegapixels << ")";
  usage.replace(usage.find("(BAND)"), 6, band.str());
  std::ostringstream local_change;
  local_change << "(" << defaults.local_plane_max_change << ")";
  usage.replace(usage.find("(LOCALCHANGE)"), 13, local_change.str());
  return usage;
}

std::vector<std::string> SplitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream stream(s);
  std::string item;
  while (std::getline(stream, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

// A number in [low, high].
double ParseNumber(const std::string& flag, const std::string& value, double low, double high) {
  size_t used = 0;
  double v = low - 1;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size() || !(v >= low && v <= high)) {
    std::ostringstream range;
    range << "[" << low << ", " << high << "]";
    throw std::invalid_argument(flag + " must be a number in " + range.str() + ", got '" + value + "'");
  }
  return v;
}

double ParseFraction(const std::string& flag, const std::string& value) { return ParseNumber(flag, value, 0, 1); }

int64_t ParseInteger(const std::string& flag, const std::string& value, int64_t min, int64_t max) {
  size_t used = 0;
  int64_t v = 0;
  try {
    v = std::stoll(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size() || v < min || v > max) {
    throw std::invalid_argument(flag + " must be an integer in [" + std::to_string(min) + ", " +
                                std::to_string(max) + "], got '" + value + "'");
  }
  return v;
}

ImageSize ParseSize(const std::string& text) {
  const size_t x = text.find('x');
  if (x == std::string::npos) {
    throw std::invalid_argument("--sizes takes WIDTHxHEIGHT, e.g. 640x512, got '" + text + "'");
  }
  ImageSize size;
  size.width = ParseInteger("--sizes width", text.substr(0, x), 16, 16384);
  size.height = ParseInteger("--sizes height", text.substr(x + 1), 16, 16384);
  return size;
}

Options ParseArgs(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      std::cout << Usage();
      std::exit(0);
    }
    if (i + 1 >= argc) throw std::invalid_argument("missing value after " + flag);
    const std::string value = argv[++i];
    if (flag == "--sizes") {
      o.sizes.clear();
      for (const auto& s : SplitComma(value)) o.sizes.push_back(ParseSize(s));
    } else if (flag == "--sources") {
      o.sources = ParseInteger(flag, value, 1, 64);
    } else if (flag == "--config") {
      o.configs = SplitComma(value);
      for (const auto& c : o.configs) {
        if (c != "paper" && c != "small" && c != "paper_v2" && c != "small_v2") {
          throw std::invalid_argument("--config takes paper, small, paper_v2 and/or small_v2, got '" + c + "'");
        }
      }
    } else if (flag == "--precision") {
      o.precisions = SplitComma(value);
      // The text only; what "auto" means is resolved for the device later.
      for (const auto& p : o.precisions) dispmvs::model::ResolvePrecision(p, torch::kCPU, flag);
    } else if (flag == "--coarse_iterations") {
      o.coarse_iterations = ParseInteger(flag, value, 0, 1000);
    } else if (flag == "--fine_iterations") {
      o.fine_iterations = ParseInteger(flag, value, 0, 1000);
    } else if (flag == "--device") {
      o.device = value;
    } else if (flag == "--threads") {
      o.threads.clear();
      for (const auto& t : SplitComma(value)) o.threads.push_back(ParseInteger(flag, t, 1, 1024));
    } else if (flag == "--warmup") {
      o.warmup = ParseInteger(flag, value, 0, 1000);
    } else if (flag == "--refinement") {
      if (value != "none" && value != "ncc") {
        throw std::invalid_argument("--refinement must be none or ncc, got '" + value + "'");
      }
      o.refine = value == "ncc";
    } else if (flag == "--memory") {
      o.memory = ParseInteger(flag, value, 0, 1) == 1;
    } else if (flag == "--band_megapixels") {
      o.band_megapixels = ParseNumber(flag, value, 0, 1e4);
    } else if (flag == "--block_cache_mb") {
      o.block_cache_mb = ParseInteger(flag, value, 0, int64_t{1} << 20);
    } else if (flag == "--refine_steps") {
      o.refinement.steps = ParseInteger(flag, value, 1, 64);
    } else if (flag == "--refine_propagation_rounds") {
      o.refinement.propagation_rounds = ParseInteger(flag, value, 0, 16);
    } else if (flag == "--refine_propagation_levels") {
      o.refinement.propagation_levels = ParseInteger(flag, value, 1, 16);
    } else if (flag == "--refine_propagation_scale") {
      o.refinement.propagation_scale = ParseInteger(flag, value, 1, 4);
      o.refinement.Check();
    } else if (flag == "--refine_full_resolution_rounds") {
      o.refinement.full_resolution_rounds = ParseInteger(flag, value, 0, 16);
    } else if (flag == "--refine_full_resolution_levels") {
      o.refinement.full_resolution_levels = ParseInteger(flag, value, 1, 16);
    } else if (flag == "--refine_sweep_hypotheses") {
      o.refinement.sweep_hypotheses = ParseInteger(flag, value, 0, 1024);
    } else if (flag == "--refine_unseen_slope_radius") {
      o.refinement.unseen_slope_radius = ParseInteger(flag, value, 0, 64);
    } else if (flag == "--refine_trusted_plane_ncc") {
      o.refinement.trusted_plane_min_ncc = ParseFraction(flag, value);
    } else if (flag == "--refine_trusted_plane_axis_anchors") {
      o.refinement.trusted_plane_axis_anchors = ParseInteger(flag, value, 0, 4);
    } else if (flag == "--refine_window_shift") {
      o.refinement.window_shift = ParseInteger(flag, value, 0, 15);
    } else if (flag == "--refine_local_plane_radius") {
      o.refinement.local_plane_radius = ParseInteger(flag, value, 0, 16);
    } else if (flag == "--refine_local_plane_max_change") {
      o.refinement.local_plane_max_change = ParseFraction(flag, value);
    } else if (flag == "--reps") {
      o.reps = ParseInteger(flag, value, 1, 1000);
    } else {
      throw std::invalid_argument("unknown option " + flag + " (see --help)");
    }
  }
  if (o.sizes.empty() || o.threads.empty() || o.configs.empty() || o.precisions.empty()) {
    throw std::invalid_argument(
        "--sizes, --threads, --config and --precision need at least one value");
  }
  return o;
}

// A plausible rig: reference at the origin, sources on a line, scene 2-6
// units away.
DispMvsInput MakeInput(const ImageSize& size, int64_t sources, const torch::Device& device) {
  const int64_t views = sources + 1;
  DispMvsInput in;
  in.images = torch::rand({1, views, 3, size.height, size.width});
  torch::Tensor K = torch::eye(3);
  K[0][0] = 0.9 * static_cast<double>(size.width);
  K[1][1] = 0.9 * static_cast<double>(size.width);
  K[0][2] = (static_cast<double>(size.width) - 1) / 2;
  K[1][2] = (static_cast<double>(size.height) - 1) / 2;
  in.intrinsics = K.expand({1, views, 3, 3}).clone();
  in.extrinsics = torch::eye(4).expand({1, views, 4, 4}).clone();
  for (int64_t v = 1; v < views; ++v) {
    in.extrinsics[0][v][0][3] = 0.2 * static_cast<double>(v - views / 2 - 1);
    in.extrinsics[0][v][1][3] = 0.05 * static_cast<double>(v);
  }
  in.depth_min = torch::full({1}, 2.0f);
  in.depth_max = torch::full({1}, 6.0f);
  in.images = in.images.to(device);
  in.intrinsics = in.intrinsics.to(device);
  in.extrinsics = in.extrinsics.to(device);
  in.depth_min = in.depth_min.to(device);
  in.depth_max = in.depth_max.to(device);
  return in;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Peak memory of one pass, in bytes, and how it was measured.
class PeakMemoryProbe {
 public:
  explicit PeakMemoryProbe(const torch::Device& device) : device_(device) {
    if (device_.is_cpu()) {
      can_reset_ = ResetPeakRss();
    }
  }

  const char* method() const {
    if (device_.is_cuda()) {
#ifdef DISPMVS_BENCH_CUDA_MEMORY
      return "CUDA allocator peak";
#else
      return "not measured (built without c10_cuda)";
#endif
    }
    return can_reset_ ? "peak RSS growth" : "process peak RSS (clear_refs unavailable)";
  }

  void Start() {
    if (device_.is_cpu()) {
      if (can_reset_) ResetPeakRss();
      baseline_ = can_reset_ ? ReadStatusKb("VmRSS:") * 1024 : 0;
      return;
    }
#ifdef DISPMVS_BENCH_CUDA_MEMORY
    const auto index = device_.index() < 0 ? c10::cuda::current_device() : device_.index();
    c10::cuda::CUDACachingAllocator::resetPeakStats(index);
    // [0] is the aggregate over pool types in every LibTorch version.
    baseline_ = c10::cuda::CUDACachingAllocator::getDeviceStats(index).allocated_bytes[0].current;
#endif
  }

  // Bytes above the state at Start(); -1 when not measured.
  int64_t Stop() const {
    if (device_.is_cpu()) return ReadStatusKb("VmHWM:") * 1024 - baseline_;
#ifdef DISPMVS_BENCH_CUDA_MEMORY
    const auto index = device_.index() < 0 ? c10::cuda::current_device() : device_.index();
    return c10::cuda::CUDACachingAllocator::getDeviceStats(index).allocated_bytes[0].peak -
           baseline_;
#else
    return -1;
#endif
  }

 private:
  // Writing 5 to clear_refs resets VmHWM to the current RSS (Linux >= 4.0).
  static bool ResetPeakRss() {
    std::ofstream clear("/proc/self/clear_refs");
    clear << "5";
    clear.flush();
    return static_cast<bool>(clear);
  }

  static int64_t ReadStatusKb(const std::string& key) {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.compare(0, key.size(), key) == 0) return std::stoll(line.substr(key.size()));
    }
    return 0;
  }

  torch::Device device_;
  bool can_reset_ = false;
  int64_t baseline_ = 0;
};

// glibc keeps freed heap memory resident and raises its mmap threshold
// after large frees, so the resident set would only ever grow and a later
// configuration would look free. A fixed threshold makes every buffer above
// it its own mapping, returned to the system when freed: the resident set
// then follows the live tensors, and its peak growth is the pass's peak.
// (LibTorch's own CPU buffers of a pass are mostly above 128 KiB anyway.)
void MapLargeAllocations() { mallopt(M_MMAP_THRESHOLD, 128 * 1024); }

struct Measurement {
  std::vector<double> seconds;
  int64_t peak_bytes = -1;
  std::vector<double> stage_share;  // per NetStage, of the timed passes' wall time
  double other_share = 0;
  double refine_share = 0;  // the photometric refinement's (--refinement ncc)
};

// The time per view and the stage breakdown, with the allocator as users
// run it.
Measurement MeasureTime(DispMvsNet& net, const DispMvsInput& input, const Options& o,
                        const torch::Device& device) {
  const auto synchronize = [&] {
    if (device.is_cuda()) torch::cuda::synchronize(device.index() < 0 ? -1 : device.index());
  };
  double refine_seconds = 0;
  const auto pass = [&] {
    synchronize();
    const auto start = std::chrono::steady_clock::now();
    const dispmvs::model::DispMvsOutput output = net->forward(input);
    synchronize();
    if (o.refine) {
      const auto refine_start = std::chrono::steady_clock::now();
      dispmvs::model::RefineDepthPhotometrically(input, output, o.refinement);
      synchronize();
      refine_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - refine_start).count();
    }
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  for (int64_t i = 0; i < o.warmup; ++i) pass();

  Measurement m;
  for (int64_t i = 0; i < o.reps; ++i) m.seconds.push_back(pass());

  StageTimer timer(device.is_cuda() ? std::function<void()>(synchronize) : nullptr);
  net->set_stage_timer(&timer);
  double timed_total = 0;
  refine_seconds = 0;
  for (int64_t i = 0; i < o.reps; ++i) timed_total += pass();
  net->set_stage_timer(nullptr);
  for (size_t s = 0; s < kNumNetStages; ++s) {
    m.stage_share.push_back(timer.seconds(static_cast<NetStage>(s)) / timed_total);
  }
  m.refine_share = refine_seconds / timed_total;
  m.other_share = std::max(0.0, 1.0 - (timer.total_seconds() + refine_seconds) / timed_total);
  return m;
}

// Peak memory of a pass: one pass to settle one-time allocations, then the
// largest peak of two.
int64_t MeasurePeakMemory(DispMvsNet& net, const DispMvsInput& input, const torch::Device& device,
                          bool refine, const dispmvs::model::PhotometricRefinementOptions& refinement) {
  const auto pass = [&] {
    const dispmvs::model::DispMvsOutput output = net->forward(input);
    if (refine) {
      dispmvs::model::RefineDepthPhotometrically(input, output, refinement);
    }
  };
  pass();
  PeakMemoryProbe memory(device);
  int64_t peak = -1;
  for (int i = 0; i < 2; ++i) {
    memory.Start();
    pass();
    if (device.is_cuda()) torch::cuda::synchronize(device.index() < 0 ? -1 : device.index());
    peak = std::max(peak, memory.Stop());
  }
  return peak;
}

// Runs `measure` in a forked child (before this process has started any
// LibTorch thread pool, so forking is safe) and returns what it returned;
// -1 per row where the child failed. The parent waits, so the two never
// compete for the cores.
template <typename Fn>
std::vector<int64_t> MeasureCpuMemoryInChild(Fn measure) {
  int fds[2];
  if (pipe(fds) != 0) return {};
  const pid_t pid = fork();
  if (pid < 0) {
    close(fds[0]);
    close(fds[1]);
    return {};
  }
  if (pid == 0) {
    close(fds[0]);
    int status = 0;
    try {
      std::string text;
      for (const int64_t peak : measure()) text += std::to_string(peak) + "\n";
      if (write(fds[1], text.data(), text.size()) != static_cast<ssize_t>(text.size())) status = 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "dispmvs_bench: memory measurement failed: %s\n", e.what());
      status = 1;
    }
    close(fds[1]);
    std::fflush(stderr);
    _exit(status);
  }
  close(fds[1]);
  std::string text;
  char buffer[4096];
  ssize_t got = 0;
  while ((got = read(fds[0], buffer, sizeof buffer)) > 0) text.append(buffer, static_cast<size_t>(got));
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  std::vector<int64_t> peaks;
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) {
    std::istringstream lines(text);
    int64_t peak = 0;
    while (lines >> peak) peaks.push_back(peak);
  }
  return peaks;
}

struct Row {
  std::string config;
  std::string precision;  // as resolved for the device
  int64_t params = 0;
  int64_t coarse_iterations = 0, fine_iterations = 0;
  ImageSize size;
  int64_t threads = 0;
  Measurement m;
};

// The named configuration as dispmvs_train builds it (small_v2: 4 coarse
// iterations, as its shipped weights run), with the iteration overrides.
ModelConfig MakeConfig(const std::string& name, const Options& o) {
  ModelConfig config = ModelConfig::ByName(name);
  if (o.coarse_iterations > 0) config.coarse_iterations = o.coarse_iterations;
  if (o.fine_iterations > 0) config.fine_iterations = o.fine_iterations;
  return config;
}

int64_t CountParameters(DispMvsNet& net) {
  int64_t count = 0;
  for (const auto& p : net->parameters()) count += p.numel();
  return count;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const Options o = ParseArgs(argc, argv);
    const torch::Device device = dispmvs::model::ParseUsableDevice(o.device, "--device");
    torch::manual_seed(0);
    torch::NoGradGuard no_grad;
    std::vector<int64_t> thread_counts = o.threads;
    if (device.is_cuda()) thread_counts.resize(1);  // they do not matter there

    // A row per configuration x size x thread count, in this order.
    std::vector<Precision> precisions;
    for (const std::string& text : o.precisions) {
      precisions.push_back(dispmvs::model::ResolvePrecision(text, device, "--precision"));
    }

    // A row per configuration x precision x size x thread count, in this
    // order.
    std::vector<Row> rows;
    for (const std::string& name : o.configs) {
      const ModelConfig config = MakeConfig(name, o);
      for (const Precision precision : precisions) {
        for (const ImageSize& size : o.sizes) {
          for (const int64_t threads : thread_counts) {
            Row r;
            r.config = name;
            r.precision = dispmvs::model::PrecisionName(precision);
            r.coarse_iterations = config.coarse_iterations;
            r.fine_iterations = config.fine_iterations;
            r.size = size;
            r.threads = threads;
            rows.push_back(r);
          }
        }
      }
    }
    // Runs `measure(net, input, row)` for every row, building each network
    // once.
    const auto for_each_row = [&](const char* what, const auto& measure) {
      size_t index = 0;
      for (const std::string& name : o.configs) {
        DispMvsNet net(MakeConfig(name, o));
        net->eval();
        net->set_fine_band_pixels(static_cast<int64_t>(o.band_megapixels * 1e6));
        net->to(device);
        for (const Precision precision : precisions) {
          net->set_precision(precision);
          for (const ImageSize& size : o.sizes) {
            const DispMvsInput input = MakeInput(size, o.sources, device);
            for (const int64_t threads : thread_counts) {
              Row& row = rows.at(index++);
              torch::set_num_threads(static_cast<int>(threads));
              std::fprintf(stderr, "dispmvs_bench: %s %s %s, %lldx%lld, %lld threads\n", what,
                           name.c_str(), dispmvs::model::PrecisionName(precision),
                           static_cast<long long>(size.width), static_cast<long long>(size.height),
                           static_cast<long long>(threads));
              row.params = CountParameters(net);
              measure(net, input, row);
            }
          }
        }
      }
    };

    // Memory first: on the CPU in a child process that maps large
    // allocations separately (MapLargeAllocations), which slows passes down
    // and would outlast any later timing; the child reports its peaks through
    // a pipe and exits before the timings start.
    const auto measure_memory = [&](DispMvsNet& net, const DispMvsInput& input, Row& row) {
      row.m.peak_bytes = MeasurePeakMemory(net, input, device, o.refine, o.refinement);
    };
    if (device.is_cpu() && o.memory) {
      const std::vector<int64_t> peaks = MeasureCpuMemoryInChild([&] {
        MapLargeAllocations();
        for_each_row("memory of", measure_memory);
        std::vector<int64_t> out;
        for (const Row& r : rows) out.push_back(r.m.peak_bytes);
        return out;
      });
      for (size_t i = 0; i < rows.size() && i < peaks.size(); ++i) rows[i].m.peak_bytes = peaks[i];
    } else if (o.memory) {
      for_each_row("memory of", measure_memory);
    }
    // Timings with the allocator as the programs set it (after the memory
    // child, which maps its large buffers separately instead).
    if (device.is_cpu()) {
      dispmvs::model::KeepFreedTensorMemory();
      if (o.block_cache_mb > 0) {
        dispmvs::model::LargeBlockCacheOptions cache;
        cache.max_cached_bytes = static_cast<std::size_t>(o.block_cache_mb) << 20;
        dispmvs::model::InstallLargeBlockCache(cache);
      }
    }
    for_each_row("timing", [&](DispMvsNet& net, const DispMvsInput& input, Row& row) {
      const int64_t peak = row.m.peak_bytes;
      row.m = MeasureTime(net, input, o, device);
      row.m.peak_bytes = peak;
    });

    std::printf("DispMVS forward pass (inference)%s on %s, N = %lld sources, %lld warm-up, "
                "%lld timed + %lld profiled passes; LibTorch %s\n",
                o.refine ? " + photometric refinement" : "", device.str().c_str(), static_cast<long long>(o.sources),
                static_cast<long long>(o.warmup), static_cast<long long>(o.reps),
                static_cast<long long>(o.reps), TORCH_VERSION);
    std::printf("peak memory: %s; large tensor blocks: %s\n\n",
                o.memory ? PeakMemoryProbe(device).method() : "not measured (--memory 0)",
                !device.is_cpu()            ? "the device's allocator"
                : o.block_cache_mb > 0 ? ("kept for reuse, budget " + std::to_string(o.block_cache_mb) + " MiB").c_str()
                                       : "mapped afresh by glibc (--block_cache_mb 0)");
    std::printf("| config | precision | params | iters | size | threads | median s | min s | peak MiB |");
    for (size_t s = 0; s < kNumNetStages; ++s) {
      std::printf(" %s |", NetStageName(static_cast<NetStage>(s)));
    }
    std::printf(" refine | other |\n|---|---|---|---|---|---|---|---|---|");
    for (size_t s = 0; s <= kNumNetStages + 1; ++s) std::printf("---|");
    std::printf("\n");
    for (const Row& r : rows) {
      std::printf("| %s | %s | %.2fM | %lld+%lld | %lldx%lld | %lld | %.3f | %.3f | ",
                  r.config.c_str(), r.precision.c_str(), static_cast<double>(r.params) / 1e6, static_cast<long long>(r.coarse_iterations),
                  static_cast<long long>(r.fine_iterations), static_cast<long long>(r.size.width),
                  static_cast<long long>(r.size.height), static_cast<long long>(r.threads),
                  Median(r.m.seconds), *std::min_element(r.m.seconds.begin(), r.m.seconds.end()));
      if (r.m.peak_bytes >= 0) {
        std::printf("%.0f |", static_cast<double>(r.m.peak_bytes) / (1024.0 * 1024.0));
      } else {
        std::printf("n/a |");
      }
      for (const double share : r.m.stage_share) std::printf(" %.1f%% |", 100.0 * share);
      std::printf(" %.1f%% | %.1f%% |\n", 100.0 * r.m.refine_share, 100.0 * r.m.other_share);
    }
    return 0;
  });
}
