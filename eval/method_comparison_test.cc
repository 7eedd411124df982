// Method-against-method comparison without ground truth, on the example
// workspace: its exact depth maps stand for method A, a copy perturbed by a
// known per-pixel pattern for method B, so that every count is known in
// advance; and two clouds whose distances are known exactly.

#include "eval/method_comparison.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "eval/comparison_report.h"
#include "examples/example_workspace.h"
#include "model/json.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::eval {
namespace {

namespace fs = std::filesystem;
using colmap_io::DenseArray;

// B's depth at pixel index i of a map whose exact depth is d.
float Perturbed(std::size_t i, float d) {
  switch (i % 10) {
    case 0: return 0;               // missing
    case 1: case 2: return d * 1.015f;  // 1.49 % apart: within 2 %, not 1 %
    case 3: return d * 1.04f;       // 3.92 % apart: within 5 % only
    case 4: return d * 1.2f;        // 18 % apart: none
    default: return d;              // equal
  }
}

class MethodComparisonTest : public ::testing::Test {
 protected:
  void SetUp() override {
    examples::ExampleWorkspaceOptions options;
    options.seed = 1;
    options.sampling = examples::GroundTruthSampling::kColmapDenseIndexing;
    examples::WriteExampleWorkspace(root_, options);
    const colmap_io::Workspace workspace(root_);
    for (const auto& entry : fs::directory_iterator(root_ / "ground_truth" / "depth_maps")) {
      const std::string name = entry.path().stem().string();  // NAME.bin -> NAME
      const DenseArray exact = colmap_io::ReadDenseArray(entry.path());
      DenseArray perturbed = exact;
      for (std::size_t i = 0; i < exact.size(); ++i) {
        perturbed.data()[i] = Perturbed(i, exact.data()[i]);
        const bool valid = exact.data()[i] > 0;
        expected_.pixels += 1;
        expected_.valid_a += valid ? 1 : 0;
        if (!valid || i % 10 == 0) continue;
        expected_.valid_b += 1;
        expected_.shared += 1;
        expected_.within_1 += i % 10 >= 5 ? 1 : 0;
        expected_.within_2 += (i % 10 >= 5 || i % 10 == 1 || i % 10 == 2) ? 1 : 0;
        expected_.within_5 += i % 10 != 4 ? 1 : 0;
      }
      colmap_io::WriteDenseArray(exact, workspace.DepthMapPath(name, "exact"));
      colmap_io::WriteDenseArray(perturbed, workspace.DepthMapPath(name, "perturbed"));
      ++views_;
    }
  }

  ::dispmvs::testing::TempDir dir_;
  fs::path root_ = dir_.path() / "ws";
  AgreementSums expected_;
  int views_ = 0;
};

TEST_F(MethodComparisonTest, CountsMatchThePerturbationAndExactMapsAreConsistent) {
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "perturbed";
  const MethodComparison report = CompareMethods(root_, options);
  ASSERT_EQ(views_, 7);
  EXPECT_EQ(report.views_compared, 7);
  const AgreementSums& got = report.pooled;
  EXPECT_EQ(got.pixels, expected_.pixels);
  EXPECT_EQ(got.valid_a, expected_.valid_a);
  EXPECT_EQ(got.valid_b, expected_.valid_b);
  EXPECT_EQ(got.shared, expected_.shared);
  EXPECT_EQ(got.within_1, expected_.within_1);
  EXPECT_EQ(got.within_2, expected_.within_2);
  EXPECT_EQ(got.within_5, expected_.within_5);
  // Exact maps agree with their sources wherever a source sees the same
  // surface; B's perturbed pixels (40 %) mostly fail the 1 % test.
  const Agreement f = Fractions(got);
  EXPECT_EQ(got.checked_a, got.valid_a);  // every view has sources with maps
  EXPECT_GT(f.consistency_a, 0.85);
  EXPECT_LT(f.consistency_b, f.consistency_a - 0.2);
  for (const ViewComparison& view : report.views) {
    EXPECT_EQ(view.width, 320);
    EXPECT_EQ(view.height, 240);
    EXPECT_EQ(view.sources_a, 4);
  }

  // Symmetric: swapping A and B swaps the per-type numbers only.
  std::swap(options.type_a, options.type_b);
  const MethodComparison swapped = CompareMethods(root_, options);
  EXPECT_EQ(swapped.pooled.valid_a, got.valid_b);
  EXPECT_EQ(swapped.pooled.within_2, got.within_2);
  EXPECT_EQ(swapped.pooled.consistent_a, got.consistent_b);

  // JSON carries the same counts.
  const model::json::Value json = model::json::Parse(ComparisonToJson(report));
  EXPECT_EQ(model::json::AsUint64(*json.Find("pooled")->Find("within_5")),
            static_cast<uint64_t>(expected_.within_5));
  EXPECT_EQ(json.Find("views")->array.size(), 7u);
  EXPECT_EQ(json.Find("clouds")->type, model::json::Value::Type::kNull);
}

TEST_F(MethodComparisonTest, MapsAtHalfSizeAreComparedAtTheSmallerSize) {
  const colmap_io::Workspace workspace(root_);
  // B at 160x120 (max_image_size 160): the exact depth sampled at even pixels.
  int64_t shared = 0;
  for (const auto& entry : fs::directory_iterator(root_ / "ground_truth" / "depth_maps")) {
    const std::string name = entry.path().stem().string();
    const DenseArray exact = colmap_io::ReadDenseArray(entry.path());
    DenseArray half(160, 120, 1, 0.0f);
    for (int row = 0; row < 120; ++row) {
      for (int col = 0; col < 160; ++col) {
        half.at(row, col) = exact.at(2 * row, 2 * col);
        shared += half.at(row, col) > 0 ? 1 : 0;
      }
    }
    colmap_io::WriteDenseArray(half, workspace.DepthMapPath(name, "half"));
  }
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "half";
  const MethodComparison report = CompareMethods(root_, options);
  EXPECT_EQ(report.pooled.pixels, 7 * 160 * 120);
  EXPECT_EQ(report.pooled.shared, shared);
  EXPECT_EQ(report.pooled.within_1, shared);  // the same depths
  EXPECT_EQ(report.views[0].width, 160);
}

TEST_F(MethodComparisonTest, CloudsAgainstEachOther) {
  // A: a 20x20 lattice of spacing h; B: the points with i + j even. Each
  // point A has and B lacks is h from B: A -> B = h / 2 on average, B -> A = 0.
  const double h = 0.1;
  std::vector<colmap_io::PlyPoint> a, b;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) {
      colmap_io::PlyPoint p;
      p.xyz = {static_cast<float>(i * h), static_cast<float>(j * h), 1.0f};
      a.push_back(p);
      if ((i + j) % 2 == 0) b.push_back(p);
    }
  }
  colmap_io::WritePlyPoints(a, dir_.path() / "a.ply");
  colmap_io::WritePlyPoints(b, dir_.path() / "b.ply");
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "perturbed";
  options.ply_a = (dir_.path() / "a.ply").string();
  options.ply_b = (dir_.path() / "b.ply").string();
  options.tau_relative = 0.01;   // of B's diagonal (about 2.6): below h
  options.cutoff_relative = 1.0;
  const MethodComparison report = CompareMethods(root_, options);
  ASSERT_TRUE(report.clouds.has_value());
  const CloudMetrics& m = report.clouds->a_against_b;
  EXPECT_EQ(m.num_points, 400);
  EXPECT_EQ(m.num_gt_points, 200);
  EXPECT_NEAR(m.accuracy, h / 2, 1e-6);
  EXPECT_NEAR(m.completeness, 0, 1e-9);
  EXPECT_DOUBLE_EQ(m.precision, 0.5);
  EXPECT_DOUBLE_EQ(m.recall, 1.0);
  EXPECT_NEAR(m.fscore, 2.0 / 3.0, 1e-12);
}

// Without sparse points COLMAP's `__auto__` rule finds no source; the
// sources then come from the camera poses, as in dispmvs_colmap's plan, so
// the consistency figures are still there: four sources for the inner
// views of the example's arc, three for its two ends (what
// SelectSourceViewsByPose keeps there, as dispmvs_colmap's plan does).
TEST_F(MethodComparisonTest, SourcesComeFromThePosesWithoutSparsePoints) {
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "perturbed";
  const MethodComparison with_points = CompareMethods(root_, options);
  const colmap_io::Workspace workspace(root_);
  colmap_io::SparseModel model = workspace.ReadModel();
  model.points3D.clear();
  for (auto& [image_id, image] : model.images) image.points2D.clear();
  colmap_io::WriteSparseModelBinary(model, workspace.SparseDir());
  ASSERT_TRUE(workspace.ReadModel().points3D.empty());

  const MethodComparison without = CompareMethods(root_, options);
  EXPECT_EQ(without.pooled.within_2, with_points.pooled.within_2);
  EXPECT_EQ(without.pooled.checked_a, without.pooled.valid_a);
  EXPECT_GT(Fractions(without.pooled).consistency_a, 0.85);
  EXPECT_LT(Fractions(without.pooled).consistency_b, Fractions(without.pooled).consistency_a - 0.2);
  for (const ViewComparison& view : without.views) {
    const bool end = view.name == "view_00.png" || view.name == "view_06.png";
    EXPECT_EQ(view.sources_a, end ? 3 : 4) << view.name;
  }
}

TEST_F(MethodComparisonTest, AutoSourcesAreCappedAsDispmvsColmapCapsThem) {
  // image_undistorter writes `__auto__, 20`; dispmvs_colmap takes at most
  // --max_num_src_images (4 by default) of them, and so must the check.
  const colmap_io::Workspace workspace(root_);
  colmap_io::WritePatchMatchConfig(colmap_io::AutoPatchMatchConfig(workspace.ReadModel(), 20),
                                   workspace.PatchMatchConfigPath());
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "perturbed";
  for (const ViewComparison& view : CompareMethods(root_, options).views) {
    EXPECT_EQ(view.sources_a, 4) << view.name;
  }
  options.max_num_src_images = 20;
  int most = 0;
  for (const ViewComparison& view : CompareMethods(root_, options).views) {
    most = std::max(most, view.sources_a);
  }
  EXPECT_GT(most, 4);  // 7 images: up to 6 sources share points with a view
  options.max_num_src_images = 0;
  EXPECT_THROW(CompareMethods(root_, options), std::invalid_argument);
}

TEST_F(MethodComparisonTest, RefusesBadRequests) {
  MethodComparisonOptions options;
  options.type_a = "exact";
  options.type_b = "exact";
  EXPECT_THROW(CompareMethods(root_, options), std::invalid_argument);
  options.type_b = "nothing";
  options.type_a = "none";
  EXPECT_THROW(CompareMethods(root_, options), std::invalid_argument);  // no map of either
  options.type_a = "exact";
  options.ply_a = "a.ply";  // B missing
  EXPECT_THROW(CompareMethods(root_, options), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::eval
