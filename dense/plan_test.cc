// PlanMinConsistentViews and NumSourcesWithMaps on plans made by hand: which
// sources count (only those that get a depth map), when the default is
// lowered per reference, when a value the user gave is refused.

#include "dense/plan.h"

#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/model_builder.h"

namespace dispmvs::dense {
namespace {

using colmap_io::image_t;
using colmap_io::StereoProblem;

// Images named a.png, b.png, ... on a line (the geometry does not matter
// here), and the problems (reference, sources) given by their indices.
DensePlan MakePlan(int num_images, const std::vector<std::pair<int, std::vector<int>>>& problems) {
  testing::ModelBuilder builder;
  const auto camera = builder.AddPinholeCamera(64, 48, 50, 50, 32, 24);
  std::vector<image_t> ids;
  for (int i = 0; i < num_images; ++i) {
    const std::string name = std::string(1, static_cast<char>('a' + i)) + ".png";
    ids.push_back(
        builder.AddImageLookingAt(camera, name, {static_cast<double>(i), 0, -5}, {0, 0, 0}));
  }
  DensePlan plan;
  plan.model = builder.model();
  for (const auto& [reference, sources] : problems) {
    StereoProblem problem;
    problem.reference_image_id = ids.at(reference);
    for (int source : sources) problem.source_image_ids.push_back(ids.at(source));
    plan.problems.push_back(problem);
  }
  return plan;
}

// The message of the std::invalid_argument `call` throws ("" if none).
template <typename Call>
std::string ErrorOf(Call call) {
  try {
    call();
  } catch (const std::invalid_argument& error) {
    return error.what();
  }
  return "";
}

bool Contains(const std::string& text, const std::string& fragment) {
  return text.find(fragment) != std::string::npos;
}

TEST(PlanMinConsistentViewsTest, StereoPairLowersTheDefault) {
  DensePlan plan = MakePlan(2, {{0, {1}}, {1, {0}}});
  EXPECT_EQ(NumSourcesWithMaps(plan, plan.problems[0]), 1);
  EXPECT_EQ(NumSourcesWithMaps(plan, plan.problems[1]), 1);
  const std::string warning = PlanMinConsistentViews(2, /*user_set=*/false, &plan);
  EXPECT_TRUE(Contains(warning, "--min_num_consistent is 2 by default")) << warning;
  EXPECT_TRUE(Contains(warning, "2 of 2 reference image(s)")) << warning;
  EXPECT_TRUE(Contains(warning, "(a.png, b.png)")) << warning;
  EXPECT_TRUE(Contains(warning, "using 1 for them")) << warning;
  EXPECT_FALSE(Contains(warning, "\n")) << warning;
  const image_t a = plan.problems[0].reference_image_id, b = plan.problems[1].reference_image_id;
  EXPECT_EQ(plan.min_consistent_views, (std::map<image_t, int>{{a, 1}, {b, 1}}));
  // What the data allows needs no word, and clears an earlier lowering.
  EXPECT_EQ(PlanMinConsistentViews(1, false, &plan), "");
  EXPECT_TRUE(plan.min_consistent_views.empty());
  EXPECT_EQ(PlanMinConsistentViews(0, true, &plan), "");
  EXPECT_EQ(PlanMinConsistentViews(1, true, &plan), "");
}

TEST(PlanMinConsistentViewsTest, StereoPairRefusesAnExplicitValueItCannotMeet) {
  DensePlan plan = MakePlan(2, {{0, {1}}, {1, {0}}});
  const std::string error = ErrorOf([&] { PlanMinConsistentViews(2, /*user_set=*/true, &plan); });
  EXPECT_TRUE(Contains(error, "--min_num_consistent 2 cannot be met")) << error;
  EXPECT_TRUE(Contains(error, "at most 1, as in a stereo pair")) << error;
  EXPECT_TRUE(Contains(error, "pass --min_num_consistent 1 or less")) << error;
  EXPECT_TRUE(plan.min_consistent_views.empty());
}

TEST(PlanMinConsistentViewsTest, OnlyTheShortReferencesChange) {
  // a, b, c see each other; d (the end of a path) has c alone.
  DensePlan plan = MakePlan(4, {{0, {1, 2}}, {1, {0, 2}}, {2, {0, 1}}, {3, {2}}});
  const image_t d = plan.problems[3].reference_image_id;
  std::string warning = PlanMinConsistentViews(2, false, &plan);
  EXPECT_TRUE(Contains(warning, "1 of 4 reference image(s)")) << warning;
  EXPECT_TRUE(Contains(warning, "(d.png)")) << warning;
  EXPECT_EQ(plan.min_consistent_views, (std::map<image_t, int>{{d, 1}}));
  // The user's 2: kept, with a word about d.
  warning = PlanMinConsistentViews(2, true, &plan);
  EXPECT_TRUE(Contains(warning, "--min_num_consistent 2: 1 of 4 reference image(s)")) << warning;
  EXPECT_TRUE(Contains(warning, "will keep no pixel")) << warning;
  EXPECT_TRUE(plan.min_consistent_views.empty());
  // 3: nobody has that many.
  const std::string error = ErrorOf([&] { PlanMinConsistentViews(3, true, &plan); });
  EXPECT_TRUE(Contains(error, "--min_num_consistent 3 cannot be met")) << error;
  EXPECT_TRUE(Contains(error, "at most 2)")) << error;
  // A default of 3 would be lowered to what each has.
  warning = PlanMinConsistentViews(3, false, &plan);
  EXPECT_TRUE(Contains(warning, "4 of 4 reference image(s)")) << warning;
  EXPECT_TRUE(Contains(warning, "using 1 to 2 (what each has)")) << warning;
  EXPECT_EQ(plan.min_consistent_views.at(d), 1);
  EXPECT_EQ(plan.min_consistent_views.at(plan.problems[0].reference_image_id), 2);
}

TEST(PlanMinConsistentViewsTest, OnlySourcesWithMapsCount) {
  // a's sources b, c are no references: they get no map, so a has nothing to
  // agree with, and no value but 0 keeps anything.
  DensePlan plan = MakePlan(3, {{0, {1, 2}}});
  EXPECT_EQ(NumSourcesWithMaps(plan, plan.problems[0]), 0);
  for (bool user_set : {false, true}) {
    const std::string error = ErrorOf([&] { PlanMinConsistentViews(2, user_set, &plan); });
    EXPECT_TRUE(Contains(error, "no reference image has a source view with a depth map")) << error;
    EXPECT_TRUE(Contains(error, "--min_num_consistent 0")) << error;
  }
  EXPECT_EQ(PlanMinConsistentViews(0, true, &plan), "");

  // A reference without sources gets no map, nor does one whose image file
  // is missing; a source listed twice is one map.
  plan = MakePlan(5, {{0, {1, 1, 2, 3}}, {1, {0}}, {2, {}}, {3, {0}}, {4, {3}}});
  plan.missing_images = {plan.problems[3].reference_image_id};
  EXPECT_EQ(NumSourcesWithMaps(plan, plan.problems[0]), 1);  // b
  EXPECT_EQ(NumSourcesWithMaps(plan, plan.problems[4]), 0);  // d is missing
  const std::string warning = PlanMinConsistentViews(2, false, &plan);
  // a, b and e get maps (c has no source, d no file); all three are short.
  EXPECT_TRUE(Contains(warning, "3 of 3 reference image(s)")) << warning;
  EXPECT_TRUE(Contains(warning, "(a.png, b.png, e.png)")) << warning;
  EXPECT_TRUE(Contains(warning, "1 of them have no source with a depth map")) << warning;
  EXPECT_EQ(plan.min_consistent_views.size(), 3u);
  EXPECT_EQ(plan.min_consistent_views.at(plan.problems[4].reference_image_id), 1);
}

TEST(PlanMinConsistentViewsTest, NoReferenceWithSourcesNeedsNoWord) {
  // Nothing gets a map: the photometric pass says so per view already.
  DensePlan plan = MakePlan(2, {{0, {}}, {1, {}}});
  EXPECT_EQ(PlanMinConsistentViews(2, true, &plan), "");
  EXPECT_EQ(PlanMinConsistentViews(2, false, &plan), "");
}

}  // namespace
}  // namespace dispmvs::dense
