// dispmvs_model_bench: parameter count and CPU time of one DispMVS forward
// pass (inference, no gradients) for the Paper and Small configurations at
// 1, 2, ... intra-op threads. Random weights and images: the cost of a forward
// pass does not depend on them.
//
//   dispmvs_model_bench [--height 512] [--width 640] [--sources 5]
//                       [--reps 3] [--threads 1,2] [--config paper,small]
//
// Each timing is the median of --reps passes after one warm-up pass.

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/config.h"
#include "model/dispmvs_net.h"

namespace {

using dispmvs::model::DispMvsInput;
using dispmvs::model::DispMvsNet;
using dispmvs::model::ModelConfig;

struct Options {
  int64_t height = 512;
  int64_t width = 640;
  int64_t sources = 5;
  int64_t reps = 3;
  std::vector<int64_t> threads{1, 2};
  std::vector<std::string> configs{"paper", "small"};
};

std::vector<std::string> SplitComma(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream stream(s);
  std::string item;
  while (std::getline(stream, item, ',')) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

int64_t ParsePositive(const std::string& flag, const std::string& value, int64_t max) {
  size_t used = 0;
  int64_t v = 0;
  try {
    v = std::stoll(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size() || v < 1 || v > max) {
    throw std::invalid_argument(flag + " must be an integer in [1, " + std::to_string(max) +
                                "], got '" + value + "'");
  }
  return v;
}

Options ParseArgs(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      std::cout << "usage: dispmvs_model_bench [--height H] [--width W] [--sources N] "
                   "[--reps R] [--threads 1,2] [--config paper,small]\n";
      std::exit(0);
    }
    if (i + 1 >= argc) throw std::invalid_argument("missing value after " + flag);
    const std::string value = argv[++i];
    if (flag == "--height") {
      o.height = ParsePositive(flag, value, 8192);
    } else if (flag == "--width") {
      o.width = ParsePositive(flag, value, 8192);
    } else if (flag == "--sources") {
      o.sources = ParsePositive(flag, value, 64);
    } else if (flag == "--reps") {
      o.reps = ParsePositive(flag, value, 1000);
    } else if (flag == "--threads") {
      o.threads.clear();
      for (const auto& t : SplitComma(value)) o.threads.push_back(ParsePositive(flag, t, 1024));
    } else if (flag == "--config") {
      o.configs = SplitComma(value);
      for (const auto& c : o.configs) {
        if (c != "paper" && c != "small") {
          throw std::invalid_argument("--config takes paper and/or small, got '" + c + "'");
        }
      }
    } else {
      throw std::invalid_argument("unknown option " + flag);
    }
  }
  if (o.threads.empty() || o.configs.empty()) {
    throw std::invalid_argument("--threads and --config need at least one value");
  }
  return o;
}

// A plausible rig: reference at the origin, sources on a line, scene 2-6
// units away.
DispMvsInput MakeInput(const Options& o) {
  const int64_t views = o.sources + 1;
  DispMvsInput in;
  in.images = torch::rand({1, views, 3, o.height, o.width});
  torch::Tensor K = torch::eye(3);
  K[0][0] = 0.9 * static_cast<double>(o.width);
  K[1][1] = 0.9 * static_cast<double>(o.width);
  K[0][2] = (static_cast<double>(o.width) - 1) / 2;
  K[1][2] = (static_cast<double>(o.height) - 1) / 2;
  in.intrinsics = K.expand({1, views, 3, 3}).clone();
  in.extrinsics = torch::eye(4).expand({1, views, 4, 4}).clone();
  for (int64_t v = 1; v < views; ++v) {
    in.extrinsics[0][v][0][3] = 0.2 * static_cast<double>(v - views / 2 - 1);
    in.extrinsics[0][v][1][3] = 0.05 * static_cast<double>(v);
  }
  in.depth_min = torch::full({1}, 2.0f);
  in.depth_max = torch::full({1}, 6.0f);
  return in;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = ParseArgs(argc, argv);
    torch::manual_seed(0);
    torch::NoGradGuard no_grad;
    const DispMvsInput input = MakeInput(o);
    std::printf("DispMVS forward pass on CPU: %lldx%lld, N = %lld sources, median of %lld "
                "after 1 warm-up\n",
                static_cast<long long>(o.width), static_cast<long long>(o.height),
                static_cast<long long>(o.sources), static_cast<long long>(o.reps));
    std::printf("%-8s %12s %8s %12s\n", "config", "parameters", "threads", "seconds");
    for (const std::string& name : o.configs) {
      const ModelConfig config = name == "paper" ? ModelConfig::Paper() : ModelConfig::Small();
      DispMvsNet net(config);
      net->eval();
      int64_t parameters = 0;
      for (const auto& p : net->parameters()) parameters += p.numel();
      for (const int64_t threads : o.threads) {
        torch::set_num_threads(static_cast<int>(threads));
        net->forward(input);  // warm-up
        std::vector<double> seconds;
        for (int64_t r = 0; r < o.reps; ++r) {
          const auto start = std::chrono::steady_clock::now();
          const auto out = net->forward(input);
          (void)out.depth.sum().item<float>();  // make sure the work is done
          seconds.push_back(
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        std::printf("%-8s %12lld %8lld %12.3f\n", name.c_str(), static_cast<long long>(parameters),
                    static_cast<long long>(threads), Median(seconds));
        std::fflush(stdout);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "dispmvs_model_bench: " << e.what() << "\n";
    return 1;
  }
}
