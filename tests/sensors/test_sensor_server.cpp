// The sensor server end to end over 127.0.0.1, in process: every driver through the server
// against a direct driver call (bit for bit), faults, several clients at once, shutdown.
#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <thread>

#include "artisan/core/io/geometry_file.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sensors/client.hpp"
#include "artisan/sensors/replay.hpp"
#include "artisan/sensors/server.hpp"
#include "artisan/sensors/simulated.hpp"
#include "sensors/sensor_test_support.hpp"
#include "test_support.hpp"

namespace artisan::sensors {
namespace {

namespace pr = protocol;
using test::FaultySensor;
using test::RawConnection;

const std::filesystem::path kCell = artisan::test::data_dir() / "workcells" / "pipework.json";

std::string local(const SensorServer& s) { return "127.0.0.1:" + std::to_string(s.port()); }

ServerConfig ephemeral() {
  ServerConfig c;
  c.port = 0;
  return c;
}

/// A server with the test driver and a replay folder of synthetic images (no simulator: fast).
struct LightServer {
  artisan::test::TempDir dir;
  std::unique_ptr<SensorServer> server;
  explicit LightServer(ServerConfig config = ephemeral()) {
    io::write_range_image(test::synthetic_range_image(640, 480, 3, 1), dir / "big.ari");
    io::write_range_image(test::synthetic_range_image(200, 200, 1, 2, 400, 400), dir / "vivid_sized.ari");
    DriverRegistry registry = builtin_drivers();
    registry.add("test-faulty", [](const DriverConfig& c) { return std::make_unique<FaultySensor>(c.name); });  // one line
    SensorSet set;
    set.add(registry.create({"faulty", "test-faulty", nullptr, {}}));
    set.add(registry.create({"files", "replay", nullptr, dir.path()}));
    server = std::make_unique<SensorServer>(std::move(set), config);
  }
};

ErrorCode code_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const SensorError& e) {
    return e.code();
  }
  return ErrorCode::kInternal;  // stands for "no error" here
}

// Method: one server serves the pipework workcell's three simulated sensors and two replay
// folders (the real Stanford bunny PLY range grids; .ari files). A second, fresh simulator
// takes the same sequence of acquisitions through direct driver calls; the .ari bytes that
// crossed the socket equal encode_range_image() of the direct result exactly, and so do the
// environmental readings and pan/tilt states. A replayed .ari arrives as the file's bytes.
TEST(SensorServer, EveryDriverMatchesADirectCallBitForBit) {
  artisan::test::TempDir dir;
  const auto bunny = io::load_geometry(artisan::test::bunny_dir() / "bun045.ply");
  io::write_range_image(std::get<RangeImage>(bunny), dir / "bun045.ari");

  const DriverRegistry registry = builtin_drivers();
  SensorSet set;
  auto served_cell = std::make_shared<SimulatedWorkcell>(kCell);
  add_workcell_sensors(set, registry, served_cell);
  set.add(registry.create({"bunny", "replay", nullptr, artisan::test::bunny_dir()}));
  set.add(registry.create({"ari", "replay", nullptr, dir.path()}));
  SensorServer server(std::move(set), ephemeral());
  SensorClient client(local(server));

  auto direct_cell = std::make_shared<SimulatedWorkcell>(kCell);
  SensorSet direct;
  add_workcell_sensors(direct, registry, direct_cell);
  direct.add(registry.create({"bunny", "replay", nullptr, artisan::test::bunny_dir()}));

  struct Step {
    std::string sensor;
    AcquireRequest request;
  };
  AcquireRequest vivid, pioneer, env, bun;
  vivid.params["seed"] = "5";
  pioneer.params["seed"] = "2";
  pioneer.pan_rad = 0.4;
  pioneer.tilt_rad = -0.3;
  env.params["seed"] = "3";
  bun.params["file"] = "bun045";
  const std::vector<Step> steps = {{"vivid", vivid}, {"pioneer", pioneer}, {"rig_environment", env}, {"bunny", bun}, {"vivid", vivid}};
  for (const auto& step : steps) {
    SCOPED_TRACE(step.sensor);
    const auto remote = client.acquire_encoded(step.sensor, step.request);
    const auto local_acq = direct.get(step.sensor).acquire(step.request);
    ASSERT_EQ(remote.has_range, local_acq.range.has_value());
    if (local_acq.range) {
      const auto expected = io::encode_range_image(*local_acq.range);
      EXPECT_EQ(remote.range_ari.size(), expected.size());
      EXPECT_TRUE(remote.range_ari == expected);
      EXPECT_GT(local_acq.range->valid_count(), 1000u);
    }
    ASSERT_EQ(remote.environment.has_value(), local_acq.environment.has_value());
    if (local_acq.environment) {
      EXPECT_EQ(remote.environment->time_s, local_acq.environment->time_s);
      EXPECT_EQ(remote.environment->dose_rate_uSv_per_h, local_acq.environment->dose_rate_uSv_per_h);
      EXPECT_EQ(remote.environment->temperature_C, local_acq.environment->temperature_C);
      EXPECT_EQ(remote.environment->humidity_percent, local_acq.environment->humidity_percent);
      EXPECT_TRUE(remote.environment->T_world_rig.matrix() == local_acq.environment->T_world_rig.matrix());
    }
    ASSERT_EQ(remote.pan_tilt.has_value(), local_acq.pan_tilt.has_value());
    if (local_acq.pan_tilt) {
      EXPECT_EQ(remote.pan_tilt->pan_rad, 0.4);
      EXPECT_EQ(remote.pan_tilt->tilt_rad, -0.3);
    }
  }
  // The pan/tilt unit stays where it was sent; the sensors list shows its limits (PTU-D46).
  const auto ptu = client.pan_tilt("pioneer");
  EXPECT_EQ(ptu.state.pan_rad, 0.4);
  EXPECT_EQ(ptu.limits.pan_max_rad, 2.775);
  const auto list = client.list();
  ASSERT_EQ(list.size(), 5u);
  EXPECT_TRUE(list[1].pan_tilt && list[1].range && list[1].environment);
  EXPECT_TRUE(list[2].environment && !list[2].range);

  // A replayed .ari travels as the file's own bytes; uncompressed it decodes to the same image.
  AcquireRequest one;
  one.params["file"] = "bun045.ari";
  EXPECT_TRUE(client.acquire_encoded("ari", one).range_ari == io::encode_range_image(io::read_range_image(dir / "bun045.ari")));
  ClientConfig raw;
  raw.compress = false;
  SensorClient uncompressed(local(server), raw);
  const auto plain = uncompressed.acquire("ari", one);
  EXPECT_TRUE(*plain.range == io::read_range_image(dir / "bun045.ari"));
}

// Method: requests the server must refuse, each on its own connection, with the code the
// protocol promises; refusals of the stream (garbage, oversized, wrong version) close the
// connection, refusals of the request keep it usable.
TEST(SensorServer, FaultsGiveErrorsWithCodes) {
  ServerConfig cfg = ephemeral();
  cfg.acquire_timeout_s = 0.3;
  LightServer s(cfg);
  const uint16_t port = s.server->port();

  {  // garbage bytes
    RawConnection c(port);
    c.send({'G', 'E', 'T', ' ', '/', ' ', 'H', 'T', 'T', 'P', '/', '1', '.', '1', '\r', '\n', '\r', '\n'});
    const auto f = c.frame();
    ASSERT_TRUE(f);
    ASSERT_EQ(f->type, static_cast<uint16_t>(pr::MessageType::kError));
    EXPECT_EQ(pr::decode_error(f->body).code(), ErrorCode::kMalformedRequest);
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // oversized: a header announcing 100 MB; the server answers without reading the body
    RawConnection c(port);
    const auto h = pr::encode_header(pr::MessageType::kAcquire, 100u << 20);
    c.send({h.begin(), h.end()});
    const auto f = c.frame();
    ASSERT_TRUE(f);
    const auto e = pr::decode_error(f->body);
    EXPECT_EQ(e.code(), ErrorCode::kRequestTooLarge);
    EXPECT_NE(std::string(e.what()).find("104857600"), std::string::npos) << e.what();
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // a newer protocol version
    RawConnection c(port);
    auto bytes = pr::encode_request(pr::ListRequest{});
    bytes[4] = 2;
    c.send(bytes);
    const auto f = c.frame();
    ASSERT_TRUE(f);
    EXPECT_EQ(pr::decode_error(f->body).code(), ErrorCode::kUnsupportedVersion);
    EXPECT_TRUE(c.closed_by_peer());
  }
  SensorClient client(local(*s.server));
  EXPECT_EQ(code_of([&] { client.acquire("kinect", {}); }), ErrorCode::kUnknownSensor);
  AcquireRequest bad;
  bad.params["colour"] = "red";
  EXPECT_EQ(code_of([&] { client.acquire("faulty", bad); }), ErrorCode::kBadParameter);
  AcquireRequest fails;
  fails.params["mode"] = "throw";
  try {
    client.acquire("faulty", fails);
    ADD_FAILURE() << "no error";
  } catch (const SensorError& e) {
    EXPECT_EQ(e.code(), ErrorCode::kSensorFailure);
    EXPECT_NE(std::string(e.what()).find("laser interlock open"), std::string::npos) << e.what();
  }
  AcquireRequest slow;
  slow.params["mode"] = "slow";
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(code_of([&] { client.acquire("faulty", slow); }), ErrorCode::kTimeout);  // the server's deadline, 0.3 s
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
  EXPECT_EQ(code_of([&] { client.pan_tilt("faulty"); }), ErrorCode::kNotSupported);
  AcquireRequest moved;
  moved.pan_rad = 0.1;
  EXPECT_EQ(code_of([&] { client.acquire("files", moved); }), ErrorCode::kNotSupported);
  EXPECT_EQ(code_of([&] { client.set_zoom("faulty", 2.0); }), ErrorCode::kOutOfLimits);
  EXPECT_EQ(client.set_zoom("faulty", 0.3).fov_rad, 0.3);
  EXPECT_EQ(client.zoom("faulty").limits.max_fov_rad, 0.9);
  // Still the same connection, still served.
  EXPECT_EQ(client.list().size(), 2u);
  EXPECT_TRUE(client.acquire("faulty", {}).range);
}

// Method: the simulated Pioneer refuses pan/tilt beyond the PTU-D46 limits, with the value and
// the limits in the message, both as a move and as part of an acquisition; the head stays put.
TEST(SensorServer, PanBeyondLimitsIsRefused) {
  auto cell = std::make_shared<SimulatedWorkcell>(kCell);
  SensorSet set;
  add_workcell_sensors(set, builtin_drivers(), cell);
  SensorServer server(std::move(set), ephemeral());
  SensorClient client(local(server));
  const auto before = client.pan_tilt("pioneer").state;
  try {
    client.move_pan_tilt("pioneer", {2.9, 0.0});
    ADD_FAILURE() << "no error";
  } catch (const SensorError& e) {
    EXPECT_EQ(e.code(), ErrorCode::kOutOfLimits);
    EXPECT_NE(std::string(e.what()).find("2.775"), std::string::npos) << e.what();
  }
  AcquireRequest r;
  r.tilt_rad = -1.0;
  EXPECT_EQ(code_of([&] { client.acquire("pioneer", r); }), ErrorCode::kOutOfLimits);
  EXPECT_EQ(code_of([&] { client.move_pan_tilt("vivid", {0, 0}); }), ErrorCode::kNotSupported);
  const auto after = client.pan_tilt("pioneer").state;
  EXPECT_EQ(after.pan_rad, before.pan_rad);
  EXPECT_EQ(after.tilt_rad, before.tilt_rad);
  EXPECT_EQ(client.move_pan_tilt("pioneer", {-1.0, 0.5}).state.tilt_rad, 0.5);
}

// Method: the simulated Vivid's zoom through the server. The description offers it (the Pioneer's
// does not); zooming in from the default to the narrowest field of view scales the colour
// camera's focal length as a pinhole's, fx ~ 1 / tan(fov / 2), and narrows the range image's
// angular extent alike; a setting outside the range is refused naming the range and leaves the
// zoom as it was.
TEST(SensorServer, TheVividZoomsWithinItsRange) {
  auto cell = std::make_shared<SimulatedWorkcell>(kCell);
  SensorSet set;
  add_workcell_sensors(set, builtin_drivers(), cell);
  SensorServer server(std::move(set), ephemeral());
  SensorClient client(local(server));
  std::optional<ZoomLimits> limits;
  for (const auto& d : client.list()) {
    if (d.name == "vivid") limits = d.zoom;
    if (d.name == "pioneer") {
      EXPECT_FALSE(d.zoom);
    }
  }
  ASSERT_TRUE(limits);
  EXPECT_LT(limits->min_fov_rad, limits->max_fov_rad);
  const auto wide = client.acquire("vivid", {});
  ASSERT_TRUE(wide.range);
  const double fov0 = client.zoom("vivid").fov_rad;
  EXPECT_EQ(client.set_zoom("vivid", limits->min_fov_rad).fov_rad, limits->min_fov_rad);
  const auto narrow = client.acquire("vivid", {});
  ASSERT_TRUE(narrow.range);
  ASSERT_FALSE(wide.range->images.empty());
  ASSERT_TRUE(wide.range->images[0].camera && narrow.range->images[0].camera);
  const double ratio = narrow.range->images[0].camera->fx / wide.range->images[0].camera->fx;
  EXPECT_NEAR(ratio, std::tan(0.5 * fov0) / std::tan(0.5 * limits->min_fov_rad), 1e-6);
  // The range image: no valid pixel outside the narrow field of view (the wide one has some).
  auto widest = [](const RangeImage& r) {
    double w = 0;
    for (size_t i = 0; i < r.valid.size(); ++i)
      if (r.valid[i]) w = std::max(w, std::abs(double(r.points_sensor[i].x() / r.points_sensor[i].z())));
    return w;
  };
  EXPECT_LE(widest(*narrow.range), std::tan(0.5 * limits->min_fov_rad) * 1.01);
  EXPECT_GT(widest(*wide.range), std::tan(0.5 * limits->min_fov_rad) * 1.1);
  try {
    client.set_zoom("vivid", limits->max_fov_rad + 0.1);
    ADD_FAILURE() << "no error";
  } catch (const SensorError& e) {
    EXPECT_EQ(e.code(), ErrorCode::kOutOfLimits);
    EXPECT_NE(std::string(e.what()).find("zoom range"), std::string::npos) << e.what();
  }
  EXPECT_EQ(client.zoom("vivid").fov_rad, limits->min_fov_rad);
  EXPECT_EQ(code_of([&] { client.zoom("pioneer"); }), ErrorCode::kNotSupported);
}

// Method: a client asks for a 640 x 480 acquisition (about 9 MB uncompressed, sent in 64 KiB
// chunks), reads the header and a little data, then vanishes with a TCP reset; another stalls
// without reading. Meanwhile four clients each take 8 acquisitions of both sizes and compare
// the bytes with the files. Everything they get is exact, the server's counters show the
// abandoned transfers did not count, and afterwards new clients are still served.
TEST(SensorServer, ClientsDyingMidTransferDoNotDisturbOthers) {
  ServerConfig cfg = ephemeral();
  cfg.chunk_bytes = 64 << 10;
  cfg.io_timeout_s = 1.0;  // the stalled client is dropped after this
  LightServer s(cfg);
  const auto big = io::read_range_image(s.dir / "big.ari");
  const auto small = io::read_range_image(s.dir / "vivid_sized.ari");
  const auto big_plain = io::encode_range_image(big, {false});
  const auto small_plain = io::encode_range_image(small, {false});

  std::atomic<int> good{0}, bad{0};
  std::vector<std::thread> clients;
  for (int t = 0; t < 4; ++t)
    clients.emplace_back([&, t] {
      ClientConfig cc;
      cc.compress = false;
      SensorClient c(local(*s.server), cc);
      for (int i = 0; i < 8; ++i) {
        AcquireRequest r;
        r.params["file"] = (i + t) % 2 ? "big" : "vivid_sized";
        const auto got = c.acquire_encoded("files", r);
        ((i + t) % 2 ? got.range_ari == big_plain : got.range_ari == small_plain) ? ++good : ++bad;
      }
    });
  for (int k = 0; k < 3; ++k) {
    RawConnection dying(s.server->port());
    pr::AcquireMessage m;
    m.sensor = "files";
    m.request.params["file"] = "big";
    m.compress = false;
    dying.send(pr::encode_request(m));
    const auto header = dying.frame();
    ASSERT_TRUE(header);
    ASSERT_EQ(header->type, static_cast<uint16_t>(pr::MessageType::kAcquisition));
    std::vector<uint8_t> some(100000);
    ASSERT_TRUE(dying.read(some.data(), some.size()));
    dying.reset();
  }
  RawConnection stalled(s.server->port());
  {
    pr::AcquireMessage m;
    m.sensor = "files";
    m.request.params["file"] = "big";
    m.compress = false;
    stalled.send(pr::encode_request(m));
  }
  for (auto& t : clients) t.join();
  EXPECT_EQ(good, 32);
  EXPECT_EQ(bad, 0);
  // The stalled client was dropped by the server's 1 s I/O timeout: what it can still read ends
  // early with EOF.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  size_t drained = 0;
  bool eof = false;
  std::vector<uint8_t> buf(1 << 16);
  for (;;) {
    pollfd p{stalled.fd(), POLLIN, 0};
    if (::poll(&p, 1, 3000) <= 0) break;
    const ssize_t n = ::recv(stalled.fd(), buf.data(), buf.size(), 0);
    if (n <= 0) {
      eof = n == 0 || errno == ECONNRESET;
      break;
    }
    drained += static_cast<size_t>(n);
  }
  EXPECT_TRUE(eof);
  EXPECT_LT(drained, big_plain.size());
  SensorClient after(local(*s.server));
  EXPECT_TRUE(after.acquire("files", {}).range);
  const auto st = s.server->stats();
  EXPECT_EQ(st.acquisitions, 33u);  // 32 + 1: none of the abandoned ones
}

// Method: several clients at once against the simulator, which serialises them: four clients
// each take a Vivid acquisition with their own seed; each result equals a direct call on the same
// seed, whatever the order (the Vivid's clock does not enter its range data -- only the
// timestamp, which is compared apart).
TEST(SensorServer, SeveralClientsAtOnceOnTheSimulator) {
  auto cell = std::make_shared<SimulatedWorkcell>(kCell);
  SensorSet set;
  add_workcell_sensors(set, builtin_drivers(), cell);
  SensorServer server(std::move(set), ephemeral());
  std::vector<std::optional<Acquisition>> got(4);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      SensorClient c(local(server));
      AcquireRequest r;
      r.params["seed"] = std::to_string(10 + t);
      got[t] = c.acquire("vivid", r);
    });
  for (auto& t : threads) t.join();
  auto direct_cell = std::make_shared<SimulatedWorkcell>(kCell);
  SimulatedRangeSensor direct_vivid(direct_cell, "vivid");
  std::set<double> times;
  for (int t = 0; t < 4; ++t) {
    ASSERT_TRUE(got[t] && got[t]->range);
    AcquireRequest r;
    r.params["seed"] = std::to_string(10 + t);
    const RangeImage direct = *direct_vivid.acquire(r).range;
    times.insert(got[t]->range->sensor.timestamp_s);
    got[t]->range->sensor.timestamp_s = direct.sensor.timestamp_s;
    // (Compared encoded: the format keeps uv of valid pixels only.)
    EXPECT_TRUE(io::encode_range_image(*got[t]->range) == io::encode_range_image(direct)) << t;
  }
  EXPECT_EQ(times.size(), 4u);  // one after the other on the simulated clock
}

// Method: a slow acquisition is abandoned by cancel() from another client (kCancelled), by the
// client's own reply timeout (kConnection), and by shutdown (kShuttingDown, stop() prompt); a
// server at its client limit refuses the next connection with kBusy.
TEST(SensorServer, CancelTimeoutsBusyAndShutdown) {
  ServerConfig cfg = ephemeral();
  cfg.max_clients = 3;
  LightServer s(cfg);
  AcquireRequest slow;
  slow.params["mode"] = "slow";
  {
    std::atomic<int> code{0};
    std::thread a([&] { code = static_cast<int>(code_of([&] { SensorClient(local(*s.server)).acquire("faulty", slow); })); });
    SensorClient b(local(*s.server));
    uint32_t n = 0;
    for (int i = 0; i < 200 && n == 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      n = b.cancel("faulty");
    }
    a.join();
    EXPECT_EQ(n, 1u);
    EXPECT_EQ(code, static_cast<int>(ErrorCode::kCancelled));
  }
  {
    ClientConfig impatient;
    impatient.reply_timeout_s = 0.3;
    SensorClient c(local(*s.server), impatient);
    try {
      c.acquire("faulty", slow);
      ADD_FAILURE() << "no error";
    } catch (const SensorError& e) {
      EXPECT_EQ(e.code(), ErrorCode::kConnection);
      EXPECT_NE(std::string(e.what()).find("timeout"), std::string::npos) << e.what();
    }
  }
  // The impatient client's connection is gone; the server notices and cancels its acquisition.
  for (int i = 0; i < 200 && s.server->stats().active > 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(s.server->stats().active, 0);
  {
    SensorClient one(local(*s.server)), two(local(*s.server)), three(local(*s.server));
    one.list();
    two.list();
    three.list();
    RawConnection fourth(s.server->port());
    const auto f = fourth.frame();
    ASSERT_TRUE(f);
    EXPECT_EQ(pr::decode_error(f->body).code(), ErrorCode::kBusy);
  }
  for (int i = 0; i < 200 && s.server->stats().active > 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  std::atomic<int> code{0};
  std::thread a([&] { code = static_cast<int>(code_of([&] { SensorClient(local(*s.server)).acquire("faulty", slow); })); });
  SensorClient idle(local(*s.server));
  idle.list();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const auto t0 = std::chrono::steady_clock::now();
  s.server->stop();
  a.join();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
  EXPECT_EQ(code, static_cast<int>(ErrorCode::kShuttingDown));
  EXPECT_EQ(code_of([&] { idle.list(); }), ErrorCode::kConnection);
  EXPECT_EQ(code_of([&] { SensorClient(local(*s.server)); }), ErrorCode::kConnection);
}

}  // namespace
}  // namespace artisan::sensors
