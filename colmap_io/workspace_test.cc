#include "colmap_io/workspace.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model_io.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

namespace fs = std::filesystem;
using dispmvs::testing::TempDir;
using dispmvs::testing::WriteFileBytes;

// The minimal layout a Workspace accepts: ROOT/images and ROOT/sparse.
fs::path MakeWorkspaceLayout(const TempDir& dir) {
  const fs::path root = dir.path() / "ws";
  fs::create_directories(root / "images");
  fs::create_directories(root / "sparse");
  return root;
}

// Expects constructing a Workspace on `root` to throw IoError naming `culprit`.
void ExpectOpenError(const fs::path& root, const fs::path& culprit) {
  try {
    Workspace workspace(root);
    FAIL() << "opened " << root;
  } catch (const IoError& error) {
    EXPECT_EQ(error.path(), culprit.string()) << error.what();
  }
}

TEST(WorkspaceTest, OpensAValidLayoutAndNamesItsFolders) {
  TempDir dir;
  const fs::path root = MakeWorkspaceLayout(dir);
  const Workspace workspace(root);
  EXPECT_EQ(workspace.root(), root);
  EXPECT_EQ(workspace.ImagesDir(), root / "images");
  EXPECT_EQ(workspace.SparseDir(), root / "sparse");
  EXPECT_EQ(workspace.StereoDir(), root / "stereo");
  EXPECT_EQ(workspace.PatchMatchConfigPath(), root / "stereo" / "patch-match.cfg");
  EXPECT_EQ(workspace.FusionConfigPath(), root / "stereo" / "fusion.cfg");
}

TEST(WorkspaceTest, MissingOrWrongFoldersAreIoErrors) {
  TempDir dir;
  ExpectOpenError(dir.path() / "absent", dir.path() / "absent");

  WriteFileBytes(dir.path() / "plain_file", "x");
  ExpectOpenError(dir.path() / "plain_file", dir.path() / "plain_file");

  const fs::path no_images = dir.path() / "no_images";
  fs::create_directories(no_images / "sparse");
  ExpectOpenError(no_images, no_images / "images");

  const fs::path no_sparse = dir.path() / "no_sparse";
  fs::create_directories(no_sparse / "images");
  ExpectOpenError(no_sparse, no_sparse / "sparse");

  const fs::path sparse_is_file = dir.path() / "sparse_is_file";
  fs::create_directories(sparse_is_file / "images");
  WriteFileBytes(sparse_is_file / "sparse", "not a folder");
  ExpectOpenError(sparse_is_file, sparse_is_file / "sparse");
}

TEST(WorkspaceTest, PerImagePathsFollowColmapNaming) {
  TempDir dir;
  const fs::path root = MakeWorkspaceLayout(dir);
  const Workspace workspace(root);
  EXPECT_EQ(workspace.ImagePath("sub/dir/a.jpg"), root / "images" / "sub" / "dir" / "a.jpg");
  EXPECT_EQ(workspace.DepthMapPath("a.jpg", "geometric"),
            root / "stereo" / "depth_maps" / "a.jpg.geometric.bin");
  EXPECT_EQ(workspace.NormalMapPath("sub/a.png", "photometric"),
            root / "stereo" / "normal_maps" / "sub" / "a.png.photometric.bin");
  EXPECT_EQ(workspace.ConfidenceMapPath("a.jpg", "dispmvs.photometric"),
            root / "stereo" / "confidence_maps" / "a.jpg.dispmvs.photometric.bin");
  EXPECT_EQ(workspace.ConsistencyGraphPath("x/y.jpg", "dispmvs.geometric"),
            root / "stereo" / "consistency_graphs" / "x" / "y.jpg.dispmvs.geometric.bin");
}

TEST(WorkspaceTest, NamesThatEscapeTheWorkspaceAreRejected) {
  TempDir dir;
  const fs::path root = MakeWorkspaceLayout(dir);
  const Workspace workspace(root);
  const std::vector<std::string> unsafe_names = {
      "", "../outside.jpg", "a/../../outside.jpg", "/etc/passwd", "./a.jpg", "a\\b.jpg", "sub/",
      std::string("a\0b.jpg", 7)};
  for (const std::string& name : unsafe_names) {
    EXPECT_THROW(workspace.ImagePath(name), IoError) << name;
    EXPECT_THROW(workspace.DepthMapPath(name, "geometric"), IoError) << name;
  }
  // Dots inside a component are fine.
  EXPECT_EQ(workspace.ImagePath("a..b/c...jpg"), root / "images" / "a..b" / "c...jpg");
}

TEST(WorkspaceTest, BadMapTypesAreRejected) {
  TempDir dir;
  const Workspace workspace(MakeWorkspaceLayout(dir));
  EXPECT_THROW(workspace.DepthMapPath("a.jpg", ""), IoError);
  EXPECT_THROW(workspace.NormalMapPath("a.jpg", "x/geometric"), IoError);
  EXPECT_THROW(workspace.ConfidenceMapPath("a.jpg", "x\\y"), IoError);
}

TEST(WorkspaceTest, CreateStereoFoldersIsIdempotent) {
  TempDir dir;
  const fs::path root = MakeWorkspaceLayout(dir);
  const Workspace workspace(root);
  workspace.CreateStereoFolders();
  for (const char* folder : {"depth_maps", "normal_maps", "confidence_maps",
                             "consistency_graphs"}) {
    EXPECT_TRUE(fs::is_directory(root / "stereo" / folder)) << folder;
  }
  WriteFileBytes(root / "stereo" / "depth_maps" / "keep.bin", "x");
  workspace.CreateStereoFolders();
  EXPECT_TRUE(fs::exists(root / "stereo" / "depth_maps" / "keep.bin"));
}

TEST(WorkspaceTest, CreateStereoFoldersReportsAFileInTheWay) {
  TempDir dir;
  const fs::path root = MakeWorkspaceLayout(dir);
  WriteFileBytes(root / "stereo" / "normal_maps", "a file, not a folder");
  const Workspace workspace(root);
  EXPECT_THROW(workspace.CreateStereoFolders(), IoError);
}

TEST(WorkspaceTest, WritingAMapCreatesTheSubFoldersOfItsName) {
  TempDir dir;
  const Workspace workspace(MakeWorkspaceLayout(dir));
  const fs::path path = workspace.DepthMapPath("day1/cam2/a.jpg", "dispmvs.photometric");
  DenseArray depth(4, 3, 1, 2.5f);
  WriteDenseArray(depth, path);
  EXPECT_TRUE(fs::is_directory(workspace.DepthMapsDir() / "day1" / "cam2"));
  EXPECT_EQ(ReadDenseArray(path).at(2, 3), 2.5f);
}

TEST(WorkspaceTest, ReadsTheSparseModelInEitherFormat) {
  SparseModel model;
  Camera camera;
  camera.camera_id = 3;
  camera.model_id = 0;  // SIMPLE_PINHOLE
  camera.width = 64;
  camera.height = 48;
  camera.params = {50.0, 32.0, 24.0};
  model.cameras[3] = camera;
  Image image;
  image.image_id = 7;
  image.camera_id = 3;
  image.name = "sub/a.jpg";
  model.images[7] = image;

  TempDir dir;
  const fs::path binary_root = dir.path() / "binary";
  fs::create_directories(binary_root / "images");
  WriteSparseModelBinary(model, binary_root / "sparse");
  const SparseModel from_binary = Workspace(binary_root).ReadModel();
  ASSERT_EQ(from_binary.images.size(), 1u);
  EXPECT_EQ(from_binary.images.at(7).name, "sub/a.jpg");
  EXPECT_EQ(from_binary.cameras.at(3).width, 64u);

  const fs::path text_root = dir.path() / "text";
  fs::create_directories(text_root / "images");
  WriteSparseModelText(model, text_root / "sparse");
  const SparseModel from_text = Workspace(text_root).ReadModel();
  ASSERT_EQ(from_text.images.size(), 1u);
  EXPECT_EQ(from_text.images.at(7).name, "sub/a.jpg");
}

TEST(WorkspaceTest, EmptySparseFolderIsAnIoErrorWhenReading) {
  TempDir dir;
  const Workspace workspace(MakeWorkspaceLayout(dir));
  EXPECT_THROW(workspace.ReadModel(), IoError);
}

}  // namespace
}  // namespace dispmvs::colmap_io
