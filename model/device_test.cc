#include "model/device.h"

#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <torch/cuda.h>

namespace dispmvs::model {
namespace {

TEST(DeviceTest, ParsesCpuAndCudaWithOrWithoutAnIndex) {
  EXPECT_TRUE(ParseDevice("cpu").is_cpu());
  const torch::Device cuda = ParseDevice("cuda");
  EXPECT_TRUE(cuda.is_cuda());
  EXPECT_FALSE(cuda.has_index());
  const torch::Device second = ParseDevice("cuda:1");
  EXPECT_TRUE(second.is_cuda());
  EXPECT_EQ(second.index(), 1);
}

TEST(DeviceTest, RejectsOtherTextNamingIt) {
  for (const std::string text : {"gpu", "cuda:x", "", "cuda:-1", "meta", "cuda:"}) {
    SCOPED_TRACE("'" + text + "'");
    try {
      ParseDevice(text, "--device");
      ADD_FAILURE() << "accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()), "--device must be cpu, cuda or cuda:<index>, got '" + text + "'");
    }
  }
}

TEST(DeviceTest, UsableDeviceNeedsCudaToBeThere) {
  EXPECT_TRUE(ParseUsableDevice("cpu").is_cpu());
  EXPECT_THROW(ParseUsableDevice("gpu"), std::invalid_argument);
  if (torch::cuda::is_available()) {
    EXPECT_TRUE(ParseUsableDevice("cuda").is_cuda());
    const std::string beyond = "cuda:" + std::to_string(torch::cuda::device_count());
    EXPECT_THROW(ParseUsableDevice(beyond), std::invalid_argument);
  } else {
    try {
      ParseUsableDevice("cuda:0", "--device");
      ADD_FAILURE() << "accepted cuda:0 without CUDA";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("--device cuda:0: CUDA is not available"), std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace dispmvs::model
