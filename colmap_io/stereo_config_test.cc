#include "colmap_io/stereo_config.h"

#include <gtest/gtest.h>

#include <Eigen/Core>

#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using dispmvs::testing::ReadFileBytes;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

std::vector<PatchMatchEntry> ParsePatchMatch(const std::string& text) {
  std::istringstream in(text);
  return ParsePatchMatchConfig(in, "patch-match.cfg");
}

// Expects parsing `text` to fail with an IoError naming patch-match.cfg whose
// message contains every fragment (typically the line number and the reason).
void ExpectPatchMatchError(const std::string& text, const std::vector<std::string>& fragments) {
  try {
    ParsePatchMatch(text);
    FAIL() << "no error for:\n" << text;
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), "patch-match.cfg");
    const std::string message = error.what();
    for (const std::string& fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos)
          << "message \"" << message << "\" lacks \"" << fragment << "\"";
    }
  }
}

// --- A small scene for resolving specs --------------------------------------
//
// Five images looking down +z (identity rotation), centres on the x axis, and
// points at z = 10 seen by chosen images. Shared points with image 1:
//   image 2 (x = 1): 3 points      image 3 (x = -1): 1 point
//   image 4 (x = 2): none          image 5 (x = 0, same centre as 1): 5 points
// Image 5 shares the most points but its triangulation angle with image 1 is
// 0, so view selection must skip it; the angle with 2 or 3 is ~5.7 degrees,
// far above the 1 degree default.

void AddImage(SparseModel* model, image_t id, const std::string& name, double center_x) {
  Image image;
  image.image_id = id;
  image.camera_id = 1;
  image.name = name;
  image.tvec = Eigen::Vector3d(-center_x, 0, 0);  // R = I, so t = -centre
  model->images[id] = image;
}

void AddPoint(SparseModel* model, point3D_t id, double x, const std::vector<image_t>& observers) {
  Point3D point;
  point.point3D_id = id;
  point.xyz = Eigen::Vector3d(x, 0.1 * static_cast<double>(id), 10.0);
  point.error = 0.5;
  for (image_t image_id : observers) {
    Image& image = model->images.at(image_id);
    Point2D observation;
    observation.xy = Eigen::Vector2d(50, 50);
    observation.point3D_id = id;
    point.track.push_back({image_id, static_cast<uint32_t>(image.points2D.size())});
    image.points2D.push_back(observation);
  }
  model->points3D[id] = point;
}

SparseModel MakeScene() {
  SparseModel model;
  Camera camera;
  camera.camera_id = 1;
  camera.model_id = 1;  // PINHOLE
  camera.width = 100;
  camera.height = 100;
  camera.params = {100, 100, 50, 50};
  model.cameras[1] = camera;
  AddImage(&model, 1, "ref.jpg", 0.0);
  AddImage(&model, 2, "right.jpg", 1.0);
  AddImage(&model, 3, "left.jpg", -1.0);
  AddImage(&model, 4, "far/away.jpg", 2.0);
  AddImage(&model, 5, "twin.jpg", 0.0);
  AddPoint(&model, 1, 0.0, {1, 2, 5});
  AddPoint(&model, 2, 0.5, {1, 2, 5});
  AddPoint(&model, 3, -0.5, {1, 2, 3, 5});
  AddPoint(&model, 4, 0.2, {1, 5});
  AddPoint(&model, 5, -0.2, {1, 5});
  AddPoint(&model, 6, 3.0, {2, 4});
  return model;
}

// --- patch-match.cfg parsing ------------------------------------------------

TEST(StereoConfigTest, ParsesAllThreeSourceKinds) {
  const auto entries = ParsePatchMatch(
      "# written by hand\n"
      "a.jpg\n"
      "__auto__, 20\n"
      "\n"
      "sub/b.jpg\n"
      "__all__\n"
      "c.jpg\n"
      "a.jpg, sub/b.jpg,d.jpg\n");
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[0].reference, "a.jpg");
  EXPECT_EQ(entries[0].sources, SourceSpec::Auto(20));
  EXPECT_EQ(entries[0].sources.kind, SourceSpec::Kind::kAuto);
  EXPECT_EQ(entries[0].sources.max_num_sources, 20u);
  EXPECT_EQ(entries[1].reference, "sub/b.jpg");
  EXPECT_EQ(entries[1].sources.kind, SourceSpec::Kind::kAll);
  EXPECT_EQ(entries[2].reference, "c.jpg");
  EXPECT_EQ(entries[2].sources.kind, SourceSpec::Kind::kExplicit);
  EXPECT_EQ(entries[2].sources.names, (std::vector<std::string>{"a.jpg", "sub/b.jpg", "d.jpg"}));
}

TEST(StereoConfigTest, ToleratesWindowsLineEndingsPaddingCommentsAndBom) {
  const auto entries = ParsePatchMatch(
      "\xEF\xBB\xBF"
      "  a.jpg \r\n"
      "   # a comment between the lines of a pair\r\n"
      "\t\r\n"
      "__auto__ ,  3 \r\n"
      "my image.jpg\r\n"
      " a.jpg ,\tother.jpg \r\n");
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].reference, "a.jpg");
  EXPECT_EQ(entries[0].sources, SourceSpec::Auto(3));
  // Inner spaces belong to the name.
  EXPECT_EQ(entries[1].reference, "my image.jpg");
  EXPECT_EQ(entries[1].sources, SourceSpec::Explicit({"a.jpg", "other.jpg"}));
}

TEST(StereoConfigTest, EmptyFileHasNoEntries) {
  EXPECT_TRUE(ParsePatchMatch("").empty());
  EXPECT_TRUE(ParsePatchMatch("# only a comment\n\n").empty());
}

TEST(StereoConfigTest, LastLineWithoutNewlineIsRead) {
  const auto entries = ParsePatchMatch("a.jpg\n__all__");
  ASSERT_EQ(entries.size(), 1u);
  EXPECT_EQ(entries[0].sources, SourceSpec::All());
}

TEST(StereoConfigTest, ReferenceWithoutSourcesLine) {
  ExpectPatchMatchError("a.jpg\n__auto__, 5\nb.jpg\n", {"line 3", "b.jpg", "no sources line"});
  ExpectPatchMatchError("a.jpg\n# nothing follows\n\n", {"line 1", "no sources line"});
}

TEST(StereoConfigTest, AutoCountMustBeAPositiveInteger) {
  ExpectPatchMatchError("a.jpg\n__auto__, abc\n", {"line 2", "abc", "not a number"});
  ExpectPatchMatchError("a.jpg\n__auto__, 2.5\n", {"line 2", "not a number"});
  ExpectPatchMatchError("a.jpg\n__auto__, -3\n", {"line 2", "not a number"});
  ExpectPatchMatchError("a.jpg\n__auto__, +3\n", {"line 2", "not a number"});
  ExpectPatchMatchError("a.jpg\n__auto__, 0\n", {"line 2", "at least 1"});
  ExpectPatchMatchError("a.jpg\n__auto__, 000\n", {"line 2", "at least 1"});
  ExpectPatchMatchError("a.jpg\n__auto__, \n", {"line 2", "not a number"});
  ExpectPatchMatchError("a.jpg\n__auto__\n", {"line 2", "__auto__, N"});
  ExpectPatchMatchError("a.jpg\n__auto__, 3, 4\n", {"line 2", "__auto__, N"});
  ExpectPatchMatchError("a.jpg\n__auto__, 99999999999999999999999\n", {"line 2", "too large"});
  EXPECT_EQ(ParsePatchMatch("a.jpg\n__auto__, 100000\n")[0].sources, SourceSpec::Auto(100000));
  ExpectPatchMatchError("a.jpg\n__auto__, 100001\n", {"too large"});
}

TEST(StereoConfigTest, KeywordsMustStandAlone) {
  ExpectPatchMatchError("a.jpg\n__all__, b.jpg\n", {"line 2", "__all__"});
  ExpectPatchMatchError("a.jpg\nb.jpg, __all__\n", {"line 2", "__all__"});
  ExpectPatchMatchError("a.jpg\nb.jpg, __auto__\n", {"line 2", "__auto__"});
}

TEST(StereoConfigTest, MissingReferenceLineShiftingThePairsIsCaught) {
  // The reference line of the second pair is missing: the parser would
  // otherwise take "__auto__, 20" as a reference image name.
  ExpectPatchMatchError("a.jpg\n__auto__, 20\n__auto__, 20\nc.jpg\n__all__\n",
                        {"line 3", "expected a reference image name"});
  ExpectPatchMatchError("__all__\nb.jpg\n", {"line 1", "expected a reference image name"});
  ExpectPatchMatchError("a.jpg\nb.jpg, c.jpg\nb.jpg, c.jpg\nd.jpg\n",
                        {"line 3", "expected a reference image name"});
}

TEST(StereoConfigTest, BadSourceLists) {
  ExpectPatchMatchError("a.jpg\nb.jpg, , c.jpg\n", {"line 2", "empty image name"});
  ExpectPatchMatchError("a.jpg\nb.jpg,\n", {"line 2", "empty image name"});
  ExpectPatchMatchError("a.jpg\n, b.jpg\n", {"line 2", "empty image name"});
  ExpectPatchMatchError("a.jpg\nb.jpg, a.jpg\n", {"line 2", "lists itself"});
  ExpectPatchMatchError("a.jpg\nb.jpg, c.jpg, b.jpg\n", {"line 2", "b.jpg", "twice"});
}

TEST(StereoConfigTest, DuplicatedReference) {
  ExpectPatchMatchError("a.jpg\n__all__\nb.jpg\n__all__\n\na.jpg\n__auto__, 2\n",
                        {"line 6", "a.jpg", "line 1"});
}

TEST(StereoConfigTest, ReadingAMissingFileIsAnIoError) {
  TempDir dir;
  const auto path = dir.path() / "patch-match.cfg";
  try {
    ReadPatchMatchConfig(path);
    FAIL();
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), path.string());
  }
  EXPECT_THROW(ReadFusionConfig(dir.path() / "fusion.cfg"), IoError);
  // A directory must not read as an empty config.
  EXPECT_THROW(ReadPatchMatchConfig(dir.path()), IoError);
  EXPECT_THROW(ReadFusionConfig(dir.path()), IoError);
}

TEST(StereoConfigTest, FileErrorsNameTheFile) {
  TempDir dir;
  const auto path = dir.Make("stereo/patch-match.cfg");
  WriteFileBytes(path, "a.jpg\n__auto__, x\n");
  try {
    ReadPatchMatchConfig(path);
    FAIL();
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), path.string());
    EXPECT_NE(std::string(error.what()).find("line 2"), std::string::npos);
  }
}

// --- patch-match.cfg writing ------------------------------------------------

TEST(StereoConfigTest, WritesColmapFormat) {
  TempDir dir;
  const auto path = dir.path() / "stereo" / "patch-match.cfg";
  WritePatchMatchConfig({{"a.jpg", SourceSpec::Auto(20)},
                         {"sub/b.jpg", SourceSpec::All()},
                         {"c.jpg", SourceSpec::Explicit({"a.jpg", "sub/b.jpg"})}},
                        path);
  EXPECT_EQ(ReadFileBytes(path),
            "a.jpg\n__auto__, 20\nsub/b.jpg\n__all__\nc.jpg\na.jpg, sub/b.jpg\n");
}

TEST(StereoConfigTest, WriteThenReadRoundTrips) {
  const std::vector<PatchMatchEntry> entries = {
      {"x y.png", SourceSpec::Explicit({"z.png"})},
      {"z.png", SourceSpec::Auto(1)},
      {"deep/er/w.png", SourceSpec::All()},
  };
  TempDir dir;
  const auto path = dir.path() / "patch-match.cfg";
  WritePatchMatchConfig(entries, path);
  EXPECT_EQ(ReadPatchMatchConfig(path), entries);
}

TEST(StereoConfigTest, WriterRejectsUnrepresentableEntries) {
  TempDir dir;
  const auto path = dir.path() / "patch-match.cfg";
  const std::vector<std::vector<PatchMatchEntry>> bad = {
      {{"", SourceSpec::All()}},
      {{"a,b.jpg", SourceSpec::All()}},
      {{"a.jpg", SourceSpec::Explicit({"b.jpg", "c,d.jpg"})}},
      {{"a.jpg", SourceSpec::Explicit({})}},
      {{"a.jpg", SourceSpec::Auto(0)}},
      {{"a.jpg", SourceSpec::All()}, {"a.jpg", SourceSpec::Auto(2)}},
      {{" a.jpg", SourceSpec::All()}},
      {{"#a.jpg", SourceSpec::All()}},
      {{"a\nb.jpg", SourceSpec::All()}},
      {{"__all__", SourceSpec::Auto(2)}},
  };
  for (const auto& entries : bad) {
    EXPECT_THROW(WritePatchMatchConfig(entries, path), IoError) << entries[0].reference;
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

// --- fusion.cfg ---------------------------------------------------------------

TEST(StereoConfigTest, ParsesFusionConfig) {
  std::istringstream in("# images to fuse\r\na.jpg\r\n\r\n  sub/b c.jpg  \nd,e.jpg");
  EXPECT_EQ(ParseFusionConfig(in, "fusion.cfg"),
            (std::vector<std::string>{"a.jpg", "sub/b c.jpg", "d,e.jpg"}));
}

TEST(StereoConfigTest, FusionConfigRejectsDuplicates) {
  std::istringstream in("a.jpg\nb.jpg\na.jpg\n");
  try {
    ParseFusionConfig(in, "fusion.cfg");
    FAIL();
  } catch (const IoError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("line 3"), std::string::npos) << message;
    EXPECT_NE(message.find("line 1"), std::string::npos) << message;
  }
}

TEST(StereoConfigTest, FusionConfigWriteAndRoundTrip) {
  TempDir dir;
  const auto path = dir.path() / "fusion.cfg";
  const std::vector<std::string> names = {"a.jpg", "sub/b.jpg", "c d.jpg"};
  WriteFusionConfig(names, path);
  EXPECT_EQ(ReadFileBytes(path), "a.jpg\nsub/b.jpg\nc d.jpg\n");
  EXPECT_EQ(ReadFusionConfig(path), names);
  EXPECT_THROW(WriteFusionConfig({"a.jpg", ""}, path), IoError);
  EXPECT_THROW(WriteFusionConfig({"a.jpg", "a.jpg"}, path), IoError);
  EXPECT_THROW(WriteFusionConfig({"a.jpg\r"}, path), IoError);
  EXPECT_EQ(ReadFusionConfig(path), names);  // failed writes left it alone
}

// The readers drop a byte order mark from the start of the file, so a name
// beginning with one cannot be written first: it would read back without the
// mark (here "# a.jpg", a comment, and the entry would be lost). Such a name
// can be read (the mark is only dropped at the very start), but the writers
// refuse it instead of writing a file that reads back differently.
TEST(StereoConfigTest, WritersRefuseANameStartingWithAByteOrderMark) {
  TempDir dir;
  const std::string marked = "\xEF\xBB\xBF# a.jpg";
  std::istringstream fusion_in(" " + marked + "\nb.jpg\n");
  const std::vector<std::string> names = ParseFusionConfig(fusion_in, "fusion.cfg");
  ASSERT_EQ(names, (std::vector<std::string>{marked, "b.jpg"}));
  const auto fusion_path = dir.path() / "fusion.cfg";
  EXPECT_THROW(WriteFusionConfig(names, fusion_path), IoError);
  EXPECT_FALSE(std::filesystem::exists(fusion_path));

  const auto path = dir.path() / "patch-match.cfg";
  EXPECT_THROW(WritePatchMatchConfig({{marked, SourceSpec::All()}}, path), IoError);
  EXPECT_THROW(WritePatchMatchConfig({{"b.jpg", SourceSpec::Explicit({"c.jpg", marked})}}, path),
               IoError);
  EXPECT_FALSE(std::filesystem::exists(path));
  // Elsewhere in a name the bytes are ordinary.
  WriteFusionConfig({"b\xEF\xBB\xBF.jpg"}, fusion_path);
  EXPECT_EQ(ReadFusionConfig(fusion_path), (std::vector<std::string>{"b\xEF\xBB\xBF.jpg"}));
}

// --- Resolving against a sparse model ----------------------------------------

TEST(StereoConfigTest, ResolvesExplicitSourcesInListedOrder) {
  const SparseModel model = MakeScene();
  EXPECT_EQ(ResolveSourceImages(SourceSpec::Explicit({"far/away.jpg", "right.jpg"}), 1, model, {},
                                "patch-match.cfg"),
            (std::vector<image_t>{4, 2}));
}

TEST(StereoConfigTest, ExplicitSourceMissingFromModelNamesConfigAndImage) {
  const SparseModel model = MakeScene();
  try {
    ResolveSourceImages(SourceSpec::Explicit({"right.jpg", "ghost.jpg"}), 1, model, {},
                        "ws/stereo/patch-match.cfg");
    FAIL();
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), "ws/stereo/patch-match.cfg");
    EXPECT_NE(std::string(error.what()).find("ghost.jpg"), std::string::npos);
  }
  EXPECT_THROW(ResolveSourceImages(SourceSpec::Explicit({"ref.jpg"}), 1, model, {}, "cfg"),
               IoError);
  EXPECT_THROW(ResolveSourceImages(SourceSpec::All(), 99, model, {}, "cfg"),
               std::invalid_argument);
}

TEST(StereoConfigTest, ResolvesAllAsEveryOtherImage) {
  const SparseModel model = MakeScene();
  EXPECT_EQ(ResolveSourceImages(SourceSpec::All(), 3, model, {}, "cfg"),
            (std::vector<image_t>{1, 2, 4, 5}));
}

TEST(StereoConfigTest, ResolvesAutoThroughViewSelection) {
  const SparseModel model = MakeScene();
  // See MakeScene: 5 is excluded (angle 0), 4 shares nothing, 2 beats 3.
  EXPECT_EQ(ResolveSourceImages(SourceSpec::Auto(20), 1, model, {}, "cfg"),
            (std::vector<image_t>{2, 3}));
  EXPECT_EQ(ResolveSourceImages(SourceSpec::Auto(1), 1, model, {}, "cfg"),
            (std::vector<image_t>{2}));
  // A triangulation angle requirement above ~5.7 degrees leaves nothing.
  ViewSelectionOptions strict;
  strict.min_triangulation_angle_deg = 10.0;
  EXPECT_TRUE(ResolveSourceImages(SourceSpec::Auto(20), 1, model, strict, "cfg").empty());
}

TEST(StereoConfigTest, ResolvesAWholeConfig) {
  const SparseModel model = MakeScene();
  const auto problems = ResolvePatchMatchConfig(
      ParsePatchMatch("left.jpg\nref.jpg\nref.jpg\n__auto__, 5\n"), model, {}, "cfg");
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_EQ(problems[0].reference_image_id, 3u);
  EXPECT_EQ(problems[0].source_image_ids, (std::vector<image_t>{1}));
  EXPECT_EQ(problems[1].reference_image_id, 1u);
  EXPECT_EQ(problems[1].source_image_ids, (std::vector<image_t>{2, 3}));

  try {
    ResolvePatchMatchConfig(ParsePatchMatch("nobody.jpg\n__all__\n"), model, {}, "my.cfg");
    FAIL();
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), "my.cfg");
    EXPECT_NE(std::string(error.what()).find("nobody.jpg"), std::string::npos);
  }
}

TEST(StereoConfigTest, AutoConfigCoversEveryImageInIdOrder) {
  const SparseModel model = MakeScene();
  const auto entries = AutoPatchMatchConfig(model, 7);
  ASSERT_EQ(entries.size(), 5u);
  const std::vector<std::string> expected_names = {"ref.jpg", "right.jpg", "left.jpg",
                                                   "far/away.jpg", "twin.jpg"};
  for (std::size_t i = 0; i < entries.size(); ++i) {
    EXPECT_EQ(entries[i].reference, expected_names[i]);
    EXPECT_EQ(entries[i].sources, SourceSpec::Auto(7));
  }
  EXPECT_THROW(AutoPatchMatchConfig(model, 0), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::colmap_io
