// Fuzz-style: truncated and bit-flipped copies of real files give an artisan::Error or a
// well-formed result, never a crash (also run under AddressSanitizer + UBSan:
// cmake -DARTISAN_SANITIZE=ON). Formats with a length or checksum must always throw.
#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/core/io/geometry_file.hpp"
#include "artisan/core/io/pcd.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

enum class Outcome { kError, kValid };

Outcome load(const std::filesystem::path& path) {
  try {
    const auto g = load_geometry(path);
    std::visit([](const auto& x) { x.validate(); }, g);
    return Outcome::kValid;
  } catch (const Error&) {
    return Outcome::kError;
  }
}

void write_bytes(const std::filesystem::path& path, const std::vector<uint8_t>& bytes, size_t n) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(n));
}

struct Case {
  std::string name;                 // file name in the temp folder (extension picks the reader)
  std::vector<uint8_t> bytes;
  bool truncation_always_fails;     // a length field or checksum covers the whole file
};

class CorruptFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto scan = test::bunny_dir() / "bun000.ply";
    const auto image = ply_to_range_image(read_ply(scan), scan);
    write_pcd(image, dir_ / "scan_binary.pcd", PcdFormat::kBinary);
    cases_ = {
        {"scan.ply", read_file_bytes(scan), true},
        {"scan_ascii.ply", read_file_bytes(test::bunny_dir() / "bun000_ascii.ply"), false},
        {"zipper.ply", read_file_bytes(test::bunny_dir() / "reconstruction" / "bun_zipper.ply"), true},
        {"scan.pcd", read_file_bytes(dir_ / "scan_binary.pcd"), true},
        {"scan.ari", encode_range_image(image), true},
        {"link.stl", read_file_bytes(test::data_dir() / "robots" / "ur5" / "base_collision.stl"), false},
        {"link.dae", read_file_bytes(test::data_dir() / "robots" / "ur5" / "base_visual.dae"), false},
    };
  }
  test::TempDir dir_;
  std::vector<Case> cases_;
};

TEST_F(CorruptFiles, TruncatedCopiesFailCleanly) {
  std::mt19937 rng(1234);
  for (const auto& c : cases_) {
    const auto path = dir_ / c.name;
    std::vector<size_t> cuts = {0, 1, 3, 10, c.bytes.size() / 2, c.bytes.size() - 1};
    for (int i = 0; i < 30; ++i) cuts.push_back(std::uniform_int_distribution<size_t>(0, c.bytes.size() - 1)(rng));
    for (size_t n : cuts) {
      write_bytes(path, c.bytes, n);
      const auto outcome = load(path);
      if (c.truncation_always_fails) {
        EXPECT_EQ(outcome, Outcome::kError) << c.name << " cut at " << n;
      }
    }
  }
}

TEST_F(CorruptFiles, BitFlippedCopiesNeverCrash) {
  std::mt19937 rng(5678);
  for (const auto& c : cases_) {
    // assimp's COLLADA reader can spend minutes on some bit-flipped files (seen: a memcpy-bound
    // loop inside its XML parser); COLLADA gets only the truncation test.
    if (c.name.ends_with(".dae")) continue;
    const auto path = dir_ / c.name;
    int errors = 0;
    for (int i = 0; i < 60; ++i) {
      auto bytes = c.bytes;
      // Flip bits in the header region half the time: that is where parsers are fragile.
      const size_t range = (i % 2 == 0) ? std::min<size_t>(bytes.size(), 1024) : bytes.size();
      for (int k = 0; k < 1 + i % 4; ++k) {
        const size_t bit = std::uniform_int_distribution<size_t>(0, range * 8 - 1)(rng);
        bytes[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
      }
      write_bytes(path, bytes, bytes.size());
      errors += load(path) == Outcome::kError;
    }
    if (c.name == "scan.ari") {
      EXPECT_EQ(errors, 60) << "the checksum must catch every flip";
    }
  }
}

TEST_F(CorruptFiles, WrongExtensionAndUnknownFormatsAreNamed) {
  write_bytes(dir_ / "fake.ply", {'h', 'e', 'l', 'l', 'o'}, 5);
  write_bytes(dir_ / "fake.xyz", {'h', 'e', 'l', 'l', 'o'}, 5);
  for (const std::string name : {"fake.ply", "fake.xyz", "missing.ply"}) {
    try {
      load_geometry(dir_ / name);
      ADD_FAILURE() << name;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace artisan::io
