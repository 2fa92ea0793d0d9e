// The .ari format: bit-exact round trips of real scans and of every field; corruption is
// always detected.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

RangeImage full_featured_image() {
  auto image = ply_to_range_image(read_ply(test::bunny_dir() / "bun000.ply"), "bun000");
  image.sensor.name = "vivid-1";
  image.sensor.timestamp_s = 1795000000.25;
  image.sensor.T_world_sensor = parse_transform("0.1 0.2 0.3 0 0 0.7071067811865476 0.7071067811865476");
  image.sensor.attributes["radiation_uSv_h"] = "3.5";
  CameraImage cam;
  cam.name = "color";
  cam.image = {8, 4, 3, std::vector<uint8_t>(8 * 4 * 3)};
  for (size_t i = 0; i < cam.image.pixels.size(); ++i) cam.image.pixels[i] = static_cast<uint8_t>(i * 7);
  cam.camera = PinholeCamera{8, 4, 10.0, 10.5, 3.5, 1.5};
  cam.T_sensor_camera = parse_transform("0.05 0 0 0 0 0 1");
  image.images.push_back(cam);
  image.images.push_back({"grey", {2, 2, 1, {1, 2, 3, 4}}, std::nullopt, Transform::Identity()});
  return image;
}

TEST(RangeImageFormat, EveryBunnyScanRoundTripsBitExactly) {
  for (const auto& name : test::bunny_scans()) {
    const auto image = ply_to_range_image(read_ply(test::bunny_dir() / (name + ".ply")), name);
    for (bool compress : {true, false}) {
      const auto blob = encode_range_image(image, {.compress = compress});
      EXPECT_TRUE(decode_range_image(blob, name) == image) << name;
    }
  }
}

TEST(RangeImageFormat, AllMetadataAndCameraImagesRoundTrip) {
  const auto image = full_featured_image();
  test::TempDir dir;
  write_range_image(image, dir / "x.ari");
  const auto back = read_range_image(dir / "x.ari");
  EXPECT_TRUE(back == image);
  ASSERT_TRUE(back.sensor.T_world_sensor.has_value());
  EXPECT_EQ(back.images[0].camera->fy, 10.5);
}

TEST(RangeImageFormat, CompressedBlobIsSmallerThanTheRawPly) {
  const auto path = test::bunny_dir() / "bun000.ply";
  const auto blob = encode_range_image(ply_to_range_image(read_ply(path), path));
  // Binary PLY of the scan: ~850 kB. The blob keeps only valid pixels and a bitmask.
  EXPECT_LT(blob.size(), std::filesystem::file_size(path));
}

TEST(RangeImageFormat, EveryFlippedBitAndEveryTruncationIsDetected) {
  // Method: a small image so that every bit position can be tried.
  auto image = RangeImage::empty_of_size(5, 4);
  for (int i = 0; i < 20; i += 3) {
    image.valid[i] = 1;
    image.points_sensor[i] = Eigen::Vector3f(i * 0.01f, 0.5f, 1.0f + i);
  }
  image.sensor.kind = "test";
  for (bool compress : {true, false}) {
    const auto blob = encode_range_image(image, {.compress = compress});
    for (size_t bit = 0; bit < blob.size() * 8; ++bit) {
      auto bad = blob;
      bad[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
      EXPECT_THROW(decode_range_image(bad, "flipped"), Error) << "bit " << bit << " compress " << compress;
    }
    for (size_t n = 0; n < blob.size(); ++n) {
      EXPECT_THROW(decode_range_image(std::span(blob.data(), n), "truncated"), Error) << n;
    }
  }
}

TEST(RangeImageFormat, ErrorsNameTheSource) {
  try {
    decode_range_image(std::vector<uint8_t>{'n', 'o', 'p', 'e', 0, 0, 0, 0, 0}, "object 42");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("object 42"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("bad magic"), std::string::npos);
  }
}

}  // namespace
}  // namespace artisan::io
