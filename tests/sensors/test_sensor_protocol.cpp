// The sensor protocol's encoders and decoders: every message round-trips exactly, and the request
// decoder survives random and mutated input with a clean error.
#include <gtest/gtest.h>

#include <random>

#include "artisan/sensors/protocol.hpp"

namespace artisan::sensors {
namespace {

namespace pr = protocol;

std::vector<pr::Request> sample_requests() {
  pr::AcquireMessage a;
  a.sensor = "pioneer";
  a.request.pan_rad = 0.25;
  a.request.tilt_rad = -0.5;
  a.request.params = {{"seed", "17"}, {"file", "bun000.ply"}};
  a.compress = false;
  pr::AcquireMessage b;
  b.sensor = "vivid";
  return {pr::ListRequest{},     a, b, pr::PanTiltGetRequest{"pioneer"}, pr::PanTiltMoveRequest{"pioneer", {1.5, -0.25}},
          pr::ZoomGetRequest{"z"}, pr::ZoomSetRequest{"z", 0.4}, pr::CancelRequest{"vivid"}};
}

bool same(const pr::Request& x, const pr::Request& y) {
  if (x.index() != y.index()) return false;
  return pr::encode_request(x) == pr::encode_request(y);
}

// Method: encode each request kind, decode the frame, re-encode: identical bytes and fields.
TEST(SensorProtocol, RequestsRoundTrip) {
  for (const auto& r : sample_requests()) {
    const auto bytes = pr::encode_request(r);
    const auto back = pr::decode_request_frame(bytes, 65536);
    EXPECT_TRUE(same(r, back)) << static_cast<int>(pr::type_of(r));
  }
  const auto back = pr::decode_request_frame(pr::encode_request(sample_requests()[1]), 65536);
  const auto& a = std::get<pr::AcquireMessage>(back);
  EXPECT_EQ(a.sensor, "pioneer");
  EXPECT_EQ(*a.request.pan_rad, 0.25);
  EXPECT_EQ(*a.request.tilt_rad, -0.5);
  EXPECT_EQ(a.request.params.at("seed"), "17");
  EXPECT_FALSE(a.compress);
}

// Method: encode replies with every optional part present, decode the bodies, compare fields.
TEST(SensorProtocol, RepliesRoundTrip) {
  SensorDescription d;
  d.name = "pioneer";
  d.kind = "pioneer-trinocular";
  d.description = "head";
  d.range = d.environment = true;
  d.pan_tilt = PanTiltLimits{-2.775, 2.775, -0.82, 0.52, 1.0};
  d.zoom = ZoomLimits{0.2, 0.9};
  d.parameters = {{"seed", "integer", "0", "", "noise seed"}};
  const auto body = [](const std::vector<uint8_t>& f) { return std::span<const uint8_t>(f).subspan(pr::kHeaderSize); };
  const auto sensors = pr::decode_sensors(body(pr::encode_sensors({d, SensorDescription{}})));
  ASSERT_EQ(sensors.size(), 2u);
  EXPECT_EQ(sensors[0].name, "pioneer");
  EXPECT_EQ(sensors[0].pan_tilt->tilt_min_rad, -0.82);
  EXPECT_EQ(sensors[0].zoom->max_fov_rad, 0.9);
  EXPECT_EQ(sensors[0].parameters[0].description, "noise seed");
  EXPECT_FALSE(sensors[1].pan_tilt);

  pr::AcquisitionHeader h;
  h.has_range = true;
  h.range_size = 123456789;
  h.environment = EnvironmentReading{946684800.5, Transform(Eigen::Translation3d(1, 2, 3)), 4.5, 21.25, 55.0};
  h.pan_tilt = PanTiltState{0.3, -0.1};
  const auto back = pr::decode_acquisition_header(body(pr::encode_acquisition_header(h)));
  EXPECT_EQ(back.range_size, h.range_size);
  EXPECT_EQ(back.environment->dose_rate_uSv_per_h, 4.5);
  EXPECT_TRUE(back.environment->T_world_rig.isApprox(h.environment->T_world_rig, 0.0));
  EXPECT_EQ(back.pan_tilt->tilt_rad, -0.1);

  const auto e = pr::decode_error(body(pr::encode_error(ErrorCode::kOutOfLimits, "pan 3 rad is beyond the limits")));
  EXPECT_EQ(e.code(), ErrorCode::kOutOfLimits);
  EXPECT_STREQ(e.what(), "pan 3 rad is beyond the limits");
  EXPECT_EQ(pr::decode_cancelled(body(pr::encode_cancelled(3))), 3u);
  EXPECT_EQ(pr::decode_zoom(body(pr::encode_zoom({0.4, {0.2, 0.9}}))).fov_rad, 0.4);
  EXPECT_EQ(pr::decode_pan_tilt(body(pr::encode_pan_tilt({{0.1, 0.2}, {-1, 1, -0.5, 0.5, 1}}))).limits.tilt_max_rad, 0.5);
}

// Method: the server's judgements of a frame, one defect at a time.
TEST(SensorProtocol, FrameDefectsHaveTheirCodes) {
  auto good = pr::encode_request(pr::CancelRequest{"vivid"});
  const auto code_of = [](const std::vector<uint8_t>& bytes, size_t max) {
    try {
      pr::decode_request_frame(bytes, max);
    } catch (const SensorError& e) {
      return e.code();
    }
    return ErrorCode::kInternal;  // "no error"
  };
  EXPECT_EQ(code_of(good, 65536), ErrorCode::kInternal);
  EXPECT_EQ(code_of(good, 4), ErrorCode::kRequestTooLarge);
  auto v = good;
  v[4] = 9;
  EXPECT_EQ(code_of(v, 65536), ErrorCode::kUnsupportedVersion);
  v = good;
  v[0] = 'X';
  EXPECT_EQ(code_of(v, 65536), ErrorCode::kMalformedRequest);
  v = good;
  v[6] = 0x42;  // unknown type
  EXPECT_EQ(code_of(v, 65536), ErrorCode::kMalformedRequest);
  v = good;
  v.push_back(0);  // trailing byte, size field unchanged
  EXPECT_EQ(code_of(v, 65536), ErrorCode::kMalformedRequest);
  // An acquire with a non-finite pan, and one with too many parameters.
  pr::AcquireMessage a;
  a.sensor = "x";
  a.request.pan_rad = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(code_of(pr::encode_request(a), 65536), ErrorCode::kMalformedRequest);
  a.request.pan_rad.reset();
  for (int i = 0; i < 65; ++i) a.request.params["p" + std::to_string(i)] = "1";
  EXPECT_EQ(code_of(pr::encode_request(a), 65536), ErrorCode::kMalformedRequest);
}

// Method: fuzz. 200 000 inputs: random bytes (with and without a valid header in front) and
// mutations of valid requests (bit flips, byte overwrites, truncations, insertions, length-field
// changes). Each must decode or throw SensorError with a framing code -- no other exception, no
// crash (run under ASan/UBSan in the sanitizer build).
TEST(SensorProtocol, DecoderFuzz) {
  std::mt19937_64 rng(20240601);
  const auto valid = sample_requests();
  size_t decoded = 0, rejected = 0;
  for (int iter = 0; iter < 200000; ++iter) {
    std::vector<uint8_t> bytes;
    const int mode = static_cast<int>(rng() % 6);
    if (mode == 0) {
      bytes.resize(rng() % 64);
      for (auto& b : bytes) b = static_cast<uint8_t>(rng());
    } else if (mode == 1) {
      std::vector<uint8_t> body(rng() % 96);
      for (auto& b : body) b = static_cast<uint8_t>(rng());
      const auto h = pr::encode_header(static_cast<pr::MessageType>(1 + rng() % 8), static_cast<uint32_t>(body.size()));
      bytes.assign(h.begin(), h.end());
      bytes.insert(bytes.end(), body.begin(), body.end());
    } else {
      bytes = pr::encode_request(valid[rng() % valid.size()]);
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits && !bytes.empty(); ++e) {
        const size_t at = rng() % bytes.size();
        switch (mode) {
          case 2: bytes[at] ^= static_cast<uint8_t>(1u << (rng() % 8)); break;
          case 3: bytes[at] = static_cast<uint8_t>(rng()); break;
          case 4: bytes.resize(at); break;
          default: bytes.insert(bytes.begin() + static_cast<std::ptrdiff_t>(at), static_cast<uint8_t>(rng())); break;
        }
      }
      if (mode == 5 && bytes.size() >= pr::kHeaderSize && rng() % 2) {  // keep the size field consistent
        const uint32_t n = static_cast<uint32_t>(bytes.size() - pr::kHeaderSize);
        std::memcpy(bytes.data() + 8, &n, 4);
      }
    }
    try {
      pr::decode_request_frame(bytes, 65536);
      ++decoded;
    } catch (const SensorError& e) {
      ++rejected;
      const auto c = e.code();
      ASSERT_TRUE(c == ErrorCode::kMalformedRequest || c == ErrorCode::kUnsupportedVersion || c == ErrorCode::kRequestTooLarge)
          << to_string(c) << ": " << e.what();
      ASSERT_GT(std::strlen(e.what()), 0u);
    }
  }
  EXPECT_GT(decoded, 1000u);   // mutations that stay valid (e.g. a changed character in a name)
  EXPECT_GT(rejected, 100000u);
}

// Method: the client's reply decoders get random bodies and mutated valid ones (100 000 in all);
// each decodes or throws SensorError(kConnection), nothing else.
TEST(SensorProtocol, ReplyDecoderFuzz) {
  std::mt19937_64 rng(77);
  SensorDescription d;
  d.name = "pioneer";
  d.pan_tilt = PanTiltLimits{-1, 1, -0.5, 0.5, 1};
  d.parameters = {{"seed", "integer", "0", "", "noise seed"}};
  pr::AcquisitionHeader h;
  h.has_range = true;
  h.range_size = 10;
  h.environment = EnvironmentReading{};
  const std::vector<std::vector<uint8_t>> valid = {pr::encode_sensors({d, d}), pr::encode_acquisition_header(h),
                                                   pr::encode_error(ErrorCode::kBusy, "busy"), pr::encode_pan_tilt({}),
                                                   pr::encode_zoom({}), pr::encode_cancelled(2)};
  for (int iter = 0; iter < 100000; ++iter) {
    const size_t which = rng() % valid.size();
    std::vector<uint8_t> body(valid[which].begin() + pr::kHeaderSize, valid[which].end());
    if (rng() % 4 == 0) {
      body.resize(rng() % 200);
      for (auto& b : body) b = static_cast<uint8_t>(rng());
    } else {
      for (int e = 0, n = 1 + static_cast<int>(rng() % 3); e < n && !body.empty(); ++e) {
        const size_t at = rng() % body.size();
        if (rng() % 3 == 0) body.resize(at);
        else body[at] = static_cast<uint8_t>(rng());
      }
    }
    try {
      switch (which) {
        case 0: pr::decode_sensors(body); break;
        case 1: pr::decode_acquisition_header(body); break;
        case 2: pr::decode_error(body); break;
        case 3: pr::decode_pan_tilt(body); break;
        case 4: pr::decode_zoom(body); break;
        default: pr::decode_cancelled(body); break;
      }
    } catch (const SensorError& e) {
      ASSERT_EQ(e.code(), ErrorCode::kConnection) << e.what();
    }
  }
}

}  // namespace
}  // namespace artisan::sensors
