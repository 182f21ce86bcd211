// `evio simulate`'s .npy writer (ground-truth maps): header and layout.
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "evio_test/temp_dir.h"
#include "simulate_command.h"

namespace evio::apps {
namespace {

TEST(SimulateCommand, NpyWriterLayout) {
  evio_test::TempDir dir;
  cv::Mat a(3, 5, CV_32F);
  for (int i = 0; i < 15; ++i) a.at<float>(i / 5, i % 5) = static_cast<float>(i) * 0.5f;
  write_npy_float32(dir.file("a.npy"), a);
  cv::Mat b(2, 3, CV_32FC2, cv::Scalar(1.5f, -2.0f));
  write_npy_float32(dir.file("b.npy"), b);
  for (const auto& [name, shape, count] :
       std::vector<std::tuple<std::string, std::string, size_t>>{{"a.npy", "(3, 5)", 15}, {"b.npy", "(2, 3, 2)", 12}}) {
    std::ifstream in(dir.file(name), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GE(bytes.size(), 10u);
    EXPECT_EQ(bytes.substr(0, 6), "\x93NUMPY");
    const size_t header_len = static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
    EXPECT_EQ((10 + header_len) % 64, 0u);
    const std::string header = bytes.substr(10, header_len);
    EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos) << header;
    EXPECT_NE(header.find("'shape': " + shape), std::string::npos) << header;
    EXPECT_EQ(header.back(), '\n');
    EXPECT_EQ(bytes.size(), 10 + header_len + count * 4);
    float v[2];
    std::memcpy(v, bytes.data() + 10 + header_len + 4, 8);
    if (name == "a.npy") {
      EXPECT_EQ(v[0], 0.5f);
      EXPECT_EQ(v[1], 1.0f);
    } else {
      EXPECT_EQ(v[0], -2.0f);  // second float: channel 1 of pixel (0, 0)
      EXPECT_EQ(v[1], 1.5f);
    }
  }
}

}  // namespace
}  // namespace evio::apps
