#pragma once
// Block storage for sparse voxel grids (perception/integration): a grid is cut into cubic
// blocks of voxels, and a BlockStore keeps each block's bytes under its integer key. The bytes
// are opaque to the store (OccupancyGrid encodes and decodes them, versioned, without a
// checksum: a store that needs one seals the blobs itself). The workspace (worldmodel/) keeps
// blocks in SQLite; InMemoryBlockStore is the unlimited store for tests and one-shot merges.
#include <compare>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <vector>

namespace artisan {

/// Integer coordinates of a block: block (x, y, z) holds voxels [x*B, (x+1)*B) along x (and so
/// on), B = GridDefinition::block_edge_voxels.
struct BlockKey {
  int32_t x = 0;
  int32_t y = 0;
  int32_t z = 0;
  auto operator<=>(const BlockKey&) const = default;
};

struct BlockKeyHash {
  size_t operator()(const BlockKey& k) const noexcept {
    uint64_t h = static_cast<uint32_t>(k.x);
    h = h * 0x9E3779B97F4A7C15ull ^ static_cast<uint32_t>(k.y);
    h = h * 0x9E3779B97F4A7C15ull ^ static_cast<uint32_t>(k.z);
    return static_cast<size_t>(h ^ (h >> 29));
  }
};

/// Where a grid's blocks live. OccupancyGrid calls it from one thread at a time; an
/// implementation need not be thread-safe. Errors (I/O, corruption) are thrown.
class BlockStore {
 public:
  virtual ~BlockStore() = default;
  /// The bytes last stored under `key`, or nullopt when there are none.
  virtual std::optional<std::vector<uint8_t>> load(const BlockKey& key) = 0;
  /// Stores (inserts or replaces) the bytes of one block.
  virtual void store(const BlockKey& key, const std::vector<uint8_t>& bytes) = 0;
  /// Every key that has bytes, in any order.
  virtual std::vector<BlockKey> keys() = 0;
};

/// Keeps every block in memory, without limit (tests, one-shot merges).
class InMemoryBlockStore final : public BlockStore {
 public:
  std::optional<std::vector<uint8_t>> load(const BlockKey& key) override;
  void store(const BlockKey& key, const std::vector<uint8_t>& bytes) override;
  std::vector<BlockKey> keys() override;
  /// Total bytes held [bytes].
  size_t bytes() const { return bytes_; }
  size_t size() const { return blocks_.size(); }

 private:
  std::map<BlockKey, std::vector<uint8_t>> blocks_;
  size_t bytes_ = 0;
};

}  // namespace artisan
