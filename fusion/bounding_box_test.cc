#include "fusion/bounding_box.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "colmap_io/error.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::fusion {
namespace {

std::filesystem::path Write(const testing::TempDir& dir, const std::string& text) {
  const std::filesystem::path path = dir.path() / "bbox.txt";
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

TEST(BoundingBoxTest, ReadsColmapsSixNumbers) {
  testing::TempDir dir;
  // COLMAP reads the two corners with operator>>: any white space, any
  // line layout.
  const BoundingBox box = ReadBoundingBox(Write(dir, "-1 -2.5 0\n 3 4e0\t5.25\n"));
  EXPECT_EQ(box.min, Eigen::Vector3d(-1, -2.5, 0));
  EXPECT_EQ(box.max, Eigen::Vector3d(3, 4, 5.25));
  EXPECT_TRUE(box.Contains(Eigen::Vector3d(0, 0, 1)));
  EXPECT_TRUE(box.Contains(Eigen::Vector3d(-1, 4, 5.25)));  // faces are inside
  EXPECT_FALSE(box.Contains(Eigen::Vector3d(-1.0001, 0, 1)));
  EXPECT_FALSE(box.Contains(Eigen::Vector3d(0, 0, 5.2501)));
}

TEST(BoundingBoxTest, RefusesWhatIsNotABox) {
  testing::TempDir dir;
  for (const std::string& text :
       {std::string(""), std::string("0 0 0 1 1"), std::string("0 0 0 1 1 1 1"),
        std::string("0 0 0 1 nan 1"), std::string("0 0 0 1 inf 1"), std::string("0 0 0 1 1x 1"),
        std::string("0 0 2 1 1 1"), std::string(5000, ' ') + "0 0 0 1 1 1"}) {
    EXPECT_THROW(ReadBoundingBox(Write(dir, text)), colmap_io::IoError) << "'" << text << "'";
  }
  EXPECT_THROW(ReadBoundingBox(dir.path() / "missing.txt"), colmap_io::IoError);
  EXPECT_THROW(ReadBoundingBox(dir.path()), colmap_io::IoError);
  try {
    ReadBoundingBox(Write(dir, "0 0 2 1 1 1"));
  } catch (const colmap_io::IoError& error) {
    EXPECT_NE(std::string(error.what()).find("min z 2.000000 is above max 1.000000"), std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace dispmvs::fusion
