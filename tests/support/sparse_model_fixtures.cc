#include "tests/support/sparse_model_fixtures.h"

#include <gtest/gtest.h>

#include <cstring>
#include <utility>

namespace dispmvs::testing {

using colmap_io::Camera;
using colmap_io::Image;
using colmap_io::Point3D;
using colmap_io::SparseModel;

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

void ExpectSameDoubles(const double* expected, const double* actual, size_t n,
                       const std::string& what) {
  for (size_t i = 0; i < n; ++i) {
    EXPECT_TRUE(SameBits(expected[i], actual[i]))
        << what << "[" << i << "]: expected " << expected[i] << ", got " << actual[i];
  }
}

void ExpectIdenticalModels(const SparseModel& expected, const SparseModel& actual) {
  ASSERT_EQ(expected.cameras.size(), actual.cameras.size());
  for (const auto& [id, cam] : expected.cameras) {
    ASSERT_EQ(actual.cameras.count(id), 1u) << "camera " << id;
    const Camera& got = actual.cameras.at(id);
    EXPECT_EQ(got.camera_id, cam.camera_id) << "camera " << id;
    EXPECT_EQ(got.model_id, cam.model_id) << "camera " << id;
    EXPECT_EQ(got.width, cam.width) << "camera " << id;
    EXPECT_EQ(got.height, cam.height) << "camera " << id;
    ASSERT_EQ(got.params.size(), cam.params.size()) << "camera " << id;
    ExpectSameDoubles(cam.params.data(), got.params.data(), cam.params.size(),
                      "camera " + std::to_string(id) + " params");
  }
  ASSERT_EQ(expected.images.size(), actual.images.size());
  for (const auto& [id, img] : expected.images) {
    ASSERT_EQ(actual.images.count(id), 1u) << "image " << id;
    const Image& got = actual.images.at(id);
    const std::string what = "image " + std::to_string(id);
    EXPECT_EQ(got.image_id, img.image_id) << what;
    EXPECT_EQ(got.name, img.name) << what;
    EXPECT_EQ(got.camera_id, img.camera_id) << what;
    ExpectSameDoubles(img.qvec.data(), got.qvec.data(), 4, what + " qvec");
    ExpectSameDoubles(img.tvec.data(), got.tvec.data(), 3, what + " tvec");
    ASSERT_EQ(got.points2D.size(), img.points2D.size()) << what;
    for (size_t i = 0; i < img.points2D.size(); ++i) {
      ExpectSameDoubles(img.points2D[i].xy.data(), got.points2D[i].xy.data(), 2,
                        what + " point2D " + std::to_string(i));
      EXPECT_EQ(got.points2D[i].point3D_id, img.points2D[i].point3D_id) << what << " " << i;
    }
  }
  ASSERT_EQ(expected.points3D.size(), actual.points3D.size());
  for (const auto& [id, pt] : expected.points3D) {
    ASSERT_EQ(actual.points3D.count(id), 1u) << "point3D " << id;
    const Point3D& got = actual.points3D.at(id);
    const std::string what = "point3D " + std::to_string(id);
    EXPECT_EQ(got.point3D_id, pt.point3D_id) << what;
    ExpectSameDoubles(pt.xyz.data(), got.xyz.data(), 3, what + " xyz");
    EXPECT_EQ(got.rgb, pt.rgb) << what;
    EXPECT_TRUE(SameBits(got.error, pt.error)) << what << ": " << got.error << " vs " << pt.error;
    ASSERT_EQ(got.track.size(), pt.track.size()) << what;
    for (size_t e = 0; e < pt.track.size(); ++e) {
      EXPECT_EQ(got.track[e].image_id, pt.track[e].image_id) << what << " track " << e;
      EXPECT_EQ(got.track[e].point2D_idx, pt.track[e].point2D_idx) << what << " track " << e;
    }
  }
}

Camera MakeCamera(colmap_io::camera_t id, int model_id, uint64_t width, uint64_t height,
                  std::vector<double> params) {
  Camera c;
  c.camera_id = id;
  c.model_id = model_id;
  c.width = width;
  c.height = height;
  c.params = std::move(params);
  return c;
}

Image MakeImage(colmap_io::image_t id, colmap_io::camera_t camera_id, const std::string& name,
                const Eigen::Vector4d& qvec, const Eigen::Vector3d& tvec) {
  Image image;
  image.image_id = id;
  image.camera_id = camera_id;
  image.name = name;
  image.qvec = qvec;
  image.tvec = tvec;
  return image;
}

}  // namespace dispmvs::testing
