// PCD: organized clouds as range images, in ascii, binary and binary_compressed (LZF).
#include <gtest/gtest.h>

#include <fstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/pcd.hpp"
#include "artisan/core/io/ply.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

std::vector<uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

TEST(Pcd, RealScanRoundTripsAsOrganizedPcdInBothEncodings) {
  test::TempDir dir;
  const auto image = ply_to_range_image(read_ply(test::bunny_dir() / "bun045.ply"), "bun045");
  for (auto format : {PcdFormat::kAscii, PcdFormat::kBinary}) {
    write_pcd(image, dir / "scan.pcd", format);
    const auto back = std::get<RangeImage>(read_pcd(dir / "scan.pcd"));
    EXPECT_EQ(back.width, 512);
    EXPECT_EQ(back.height, 400);
    EXPECT_EQ(back.valid_count(), 40097u);
    EXPECT_EQ(back.points_sensor, image.points_sensor);
    EXPECT_EQ(back.valid, image.valid);
  }
}

TEST(Pcd, RgbBecomesAColourImageOfTheSameSize) {
  auto image = RangeImage::empty_of_size(3, 2);
  image.valid[4] = 1;
  image.points_sensor[4] = {0.1f, 0.2f, 0.9f};
  CameraImage cam{"color", {3, 2, 3, std::vector<uint8_t>(18, 0)}, std::nullopt, Transform::Identity()};
  cam.image.pixels[4 * 3 + 0] = 200;
  cam.image.pixels[4 * 3 + 2] = 17;
  image.images.push_back(cam);
  test::TempDir dir;
  for (auto format : {PcdFormat::kAscii, PcdFormat::kBinary}) {
    write_pcd(image, dir / "c.pcd", format);
    const auto back = std::get<RangeImage>(read_pcd(dir / "c.pcd"));
    ASSERT_EQ(back.images.size(), 1u);
    EXPECT_EQ(back.images[0].image.pixels[4 * 3 + 0], 200);
    EXPECT_EQ(back.images[0].image.pixels[4 * 3 + 2], 17);
    EXPECT_EQ(back.valid_count(), 1u);
  }
}

TEST(Pcd, BinaryCompressedIsDecoded) {
  // 2 x 2 organized cloud, fields x y z (F4), structure-of-arrays, LZF-compressed as
  // literal runs (a valid LZF stream: control byte n-1 then n literal bytes).
  std::vector<float> soa = {0, 1, 0, 1, /*y*/ 0, 0, 1, 1, /*z*/ 2, 2, 2, NAN};
  std::vector<uint8_t> raw(reinterpret_cast<uint8_t*>(soa.data()), reinterpret_cast<uint8_t*>(soa.data()) + 48);
  std::vector<uint8_t> lzf;
  for (size_t i = 0; i < raw.size(); i += 16) {
    lzf.push_back(15);
    lzf.insert(lzf.end(), raw.begin() + i, raw.begin() + i + 16);
  }
  std::string header = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary_compressed\n";
  auto bytes = bytes_of(header);
  const uint32_t sizes[2] = {static_cast<uint32_t>(lzf.size()), 48};
  bytes.insert(bytes.end(), reinterpret_cast<const uint8_t*>(sizes), reinterpret_cast<const uint8_t*>(sizes) + 8);
  bytes.insert(bytes.end(), lzf.begin(), lzf.end());
  const auto image = std::get<RangeImage>(parse_pcd(bytes, "c.pcd"));
  EXPECT_EQ(image.valid_count(), 3u);
  EXPECT_EQ(image.points_sensor[2], Eigen::Vector3f(0, 1, 2));
  EXPECT_EQ(image.valid[3], 0);
  // A back reference before the start of the output is corruption.
  auto bad = bytes;
  bad[header.size() + 8] = 0xE0;
  EXPECT_THROW(parse_pcd(bad, "c.pcd"), FileError);
}

TEST(Pcd, UnorganizedCloudIsAPointCloud) {
  const std::string text = "VERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\nTYPE F F F F F F\nCOUNT 1 1 1 1 1 1\n"
                           "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3 0 0 1\nnan nan nan 0 0 1\n";
  const auto cloud = std::get<PointCloud>(parse_pcd(bytes_of(text), "u.pcd"));
  ASSERT_EQ(cloud.points.size(), 1u);  // the NaN point is "no return"
  EXPECT_EQ(cloud.normals[0], Eigen::Vector3f(0, 0, 1));
}

TEST(Pcd, MalformedFilesThrow) {
  const std::string fields = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  for (const auto& [text, fragment] : std::vector<std::pair<std::string, std::string>>{
           {"", "empty file"},
           {"hello world\n", "malformed header"},
           {fields + "WIDTH 2\nHEIGHT 2\nPOINTS 4\n", "no DATA line"},
           {fields + "WIDTH 2\nHEIGHT 2\nPOINTS 5\nDATA ascii\n", "is not WIDTH x HEIGHT"},
           {fields + "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n", "truncated"},
           {fields + "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n0123456789", "truncated"},
           {fields + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 inf\n", "infinite"},
           {fields + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 x\n", "not a number"},
           {"FIELDS a b\nSIZE 4 4\nTYPE F F\nWIDTH 1\nHEIGHT 1\nDATA ascii\n1 2\n", "no x, y, z"},
       }) {
    try {
      parse_pcd(bytes_of(text), "bad.pcd");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace artisan::io
