// Occupancy-grid integration (Johnson & Kang surface synthesis) with a paged block cache. The
// model and the extraction rule are described in integration.hpp; this file has the details:
//
// Fixed point. One mesh's contributions to one block are summed in floats, always by one thread
// in the same order, then rounded once per voxel and field to integers (scale 2^16) and added to
// the block's integers modulo 2^32 (unsigned arithmetic). Those integer sums are exact and
// commutative: the grid does not depend on the order of the meshes, on the threads, or on when
// blocks were evicted and reloaded. One voxel saturates after the equivalent of ~30000 head-on
// views (L is stored as a 32-bit integer of scale 2^16).
//
// Units inside: positions in voxels (voxel i's centre at i + 0.5, grid frame), so the inverse
// covariances and gradients are per voxel.
//
// Storage: a block's voxels are kept in bricks of 2^3 voxels, and only the bricks that received
// evidence have memory (a surface sheet fills about a fifth of the voxels of the blocks it
// crosses; dense blocks were mostly zeros, and fresh memory is slow to come by). The bytes in a
// store are the same either way: a mask of the non-zero voxels and their fields.
//
// Distribution: vertices become splats (centre, inverse covariance, weight, normal, colour, the
// box of voxels within support_sigmas); splats are binned by the blocks their box touches and the
// blocks are processed (those already in the cache first, then in key order) in batches that fit
// the memory budget, one block per thread, through a per-thread float accumulator
// (BlockAccumulator): per splat, the rows of voxels along x inside its support, then the Gaussian
// on all of them at once, then the 16 sums per voxel as two 8-float vectors.
//
// Extraction: blocks in key order, in batches that fit the budget with their +x/+y/+z
// neighbours (a cell's far corners lie in them); per block the derived samples (L, f, oriented
// consensus normal, colour) on (B+1)^3 voxels, then Marching Cubes on its B^3 cells. Vertices
// are keyed by their grid edge, so neighbouring blocks share them; blocks are merged in key order.
#include "artisan/perception/integration.hpp"

#include <omp.h>

#if defined(__x86_64__)
#include <immintrin.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <exception>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <list>
#include <map>
#include <unordered_map>
#include <unordered_set>
#include <mutex>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/io/bytes.hpp"
#include "marching_cubes.hpp"

namespace artisan {
namespace {

constexpr int kSurfaceFields = 13;  // L, grad L (3), T (xx xy xz yy yz zz), N (3)
constexpr int kChannelFields = 4;   // sum g, sum g r, sum g g, sum g b (colours in [0, 1])
constexpr double kScale = 65536.0;
constexpr uint32_t kBlockMagic = 0x31424741;  // "AGB1"
constexpr uint16_t kBlockVersion = 1;
constexpr double kMaxVoxelIndex = 1 << 29;
constexpr int kBrickEdge = 2;  // [voxels]
constexpr int kBrickVoxels = kBrickEdge * kBrickEdge * kBrickEdge;

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

inline void add(int32_t& slot, int32_t value) {
  slot = static_cast<int32_t>(static_cast<uint32_t>(slot) + static_cast<uint32_t>(value));
}

// std::lrint (round to nearest, ties to even, then modulo 2^32) without the library call.
inline int32_t round_to_int(float x) {
#if defined(__x86_64__)
  return static_cast<int32_t>(_mm_cvtss_si64(_mm_set_ss(x)));
#else
  return static_cast<int32_t>(std::lrint(x));
#endif
}

// ---- blocks ----

// A block of B^3 voxels cut into bricks of kBrickEdge^3 (the last bricks along an axis stick out
// of the block when B is not a multiple of kBrickEdge; their outside voxels stay unused).
struct BlockShape {
  int edge = 0;             // B [voxels]
  int bricks_per_edge = 0;  // ceil(B / kBrickEdge)
  int bricks = 0;
  explicit BlockShape(int B)
      : edge(B), bricks_per_edge((B + kBrickEdge - 1) / kBrickEdge), bricks(bricks_per_edge * bricks_per_edge * bricks_per_edge) {}
  int brick(int x, int y, int z) const {
    return ((z / kBrickEdge) * bricks_per_edge + y / kBrickEdge) * bricks_per_edge + x / kBrickEdge;
  }
  static int in_brick(int x, int y, int z) {
    return ((z % kBrickEdge) * kBrickEdge + y % kBrickEdge) * kBrickEdge + x % kBrickEdge;
  }
  // Bytes of a block with every brick allocated, with its brick table.
  size_t full_bytes(int fields) const {
    return static_cast<size_t>(bricks) * (static_cast<size_t>(kBrickVoxels) * fields * sizeof(int32_t) + 16 + sizeof(void*));
  }
};

// Bricks of one size carved from chunks of 2 MiB whose pages are mapped in one system call:
// touching fresh memory page by page costs a fault per page, several times slower (notably on
// virtual machines). Freed bricks are kept for reuse (an evicted block's memory serves the next
// block loaded), so the pool holds at most the most bricks ever in use at once, plus a chunk.
// Thread-safe.
class BrickPool {
 public:
  static constexpr size_t kChunkBytes = size_t{2} << 20;

  explicit BrickPool(size_t brick_bytes) : brick_bytes_(brick_bytes) {}
  ~BrickPool() {
    for (void* chunk : chunks_) release_chunk(chunk);
  }
  BrickPool(const BrickPool&) = delete;
  BrickPool& operator=(const BrickPool&) = delete;

  size_t brick_bytes() const { return brick_bytes_; }
  // A brick of zeros.
  int32_t* get() {
    int32_t* p = nullptr;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (free_.empty()) {
        if (next_ + brick_bytes_ > end_) {
          next_ = static_cast<char*>(new_chunk());
          end_ = next_ + kChunkBytes;
        }
        p = reinterpret_cast<int32_t*>(next_);
        next_ += brick_bytes_;
        return p;  // never used: zeros
      }
      p = free_.back();
      free_.pop_back();
    }
    std::memset(p, 0, brick_bytes_);
    return p;
  }
  void put(int32_t* p) {
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(p);
  }

 private:
  void* new_chunk() {
#if defined(__linux__)
    void* p = mmap(nullptr, kChunkBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_POPULATE, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
#else
    void* p = std::calloc(1, kChunkBytes);
    if (!p) throw std::bad_alloc();
#endif
    chunks_.push_back(p);
    return p;
  }
  static void release_chunk(void* p) {
#if defined(__linux__)
    munmap(p, kChunkBytes);
#else
    std::free(p);
#endif
  }

  size_t brick_bytes_;
  std::mutex mutex_;
  std::vector<void*> chunks_;
  std::vector<int32_t*> free_;
  char* next_ = nullptr;
  char* end_ = nullptr;
};

// `fields` integers per voxel, stored per brick; only the bricks that were written have memory,
// each its own (a block grows without moving). Bricks come from a pool (the surface's) or from
// the heap (colour channels: their share of the budget varies, and a pool keeps its peak).
struct BrickArray {
  std::vector<int32_t*> slot;  // per brick: kBrickVoxels * fields, voxel-major; or null
  size_t allocated = 0;        // bricks with memory
  BrickPool* pool = nullptr;   // where they come from; null: the heap

  BrickArray() = default;
  BrickArray(BrickArray&& o) noexcept { swap(o); }
  BrickArray& operator=(BrickArray&& o) noexcept {
    BrickArray moved(std::move(o));
    swap(moved);
    return *this;
  }
  ~BrickArray() {
    for (int32_t* b : slot)
      if (b) pool ? pool->put(b) : delete[] b;
  }
  void swap(BrickArray& o) noexcept {
    std::swap(slot, o.slot);
    std::swap(allocated, o.allocated);
    std::swap(pool, o.pool);
  }

  // Bytes of one brick in memory.
  static size_t brick_bytes(int fields, const BrickPool* from) {
    return from ? from->brick_bytes() : static_cast<size_t>(kBrickVoxels) * fields * sizeof(int32_t) + 16;
  }

  const int32_t* voxel(const BlockShape& s, int fields, int x, int y, int z) const {
    if (slot.empty()) return nullptr;
    const int32_t* b = slot[s.brick(x, y, z)];
    return b ? b + BlockShape::in_brick(x, y, z) * fields : nullptr;
  }
  int32_t* brick(int b) { return slot[b]; }
  // Gives every brick in `bricks` memory (zeros where new), from `from` (or the heap).
  void allocate(const BlockShape& s, int fields, const std::vector<int>& bricks, BrickPool* from) {
    if (slot.empty()) {
      slot.assign(s.bricks, nullptr);
      pool = from;
    }
    for (int b : bricks)
      if (!slot[b]) {
        slot[b] = pool ? pool->get() : new int32_t[static_cast<size_t>(kBrickVoxels) * fields]();
        ++allocated;
      }
  }
  size_t bytes(int fields) const { return slot.capacity() * sizeof(slot[0]) + allocated * brick_bytes(fields, pool); }
};

struct Channel {
  uint32_t id = 0;
  BrickArray bricks;  // kChannelFields per voxel
};

struct Block {
  BrickArray surface;             // kSurfaceFields per voxel
  std::vector<Channel> channels;  // by ascending id
  bool dirty = false;
  int pins = 0;
  size_t accounted = 0;  // bytes() when the cache last counted it
  std::list<BlockKey>::iterator lru;

  size_t bytes() const {
    size_t n = surface.bytes(kSurfaceFields) + channels.capacity() * sizeof(Channel);
    for (const auto& c : channels) n += c.bricks.bytes(kChannelFields);
    return n;
  }
  BrickArray& channel(uint32_t id) {
    auto it = std::lower_bound(channels.begin(), channels.end(), id, [](const Channel& c, uint32_t i) { return c.id < i; });
    if (it == channels.end() || it->id != id) {
      const auto at = it - channels.begin();
      channels.reserve(channels.size() + 1);  // exactly: the cache counts capacity
      it = channels.insert(channels.begin() + at, Channel{id, {}});
    }
    return it->bricks;
  }
};

// Sparse encoding: header, channel ids, then per section (surface, each channel) an occupancy
// bit mask of the voxels with any non-zero field followed by those voxels' fields, voxels in
// x-fastest order.
void put_section(io::ByteWriter& w, const BrickArray& values, const BlockShape& shape, int fields) {
  const int B = shape.edge, voxels = B * B * B;
  std::vector<uint8_t> mask((voxels + 7) / 8, 0);
  std::vector<const int32_t*> set;
  int v = 0;
  for (int z = 0; z < B; ++z)
    for (int y = 0; y < B; ++y)
      for (int x = 0; x < B; ++x, ++v) {
        const int32_t* p = values.voxel(shape, fields, x, y, z);
        if (p && std::any_of(p, p + fields, [](int32_t q) { return q != 0; })) {
          mask[v / 8] = static_cast<uint8_t>(mask[v / 8] | (1u << (v % 8)));
          set.push_back(p);
        }
      }
  w.put<uint32_t>(static_cast<uint32_t>(set.size()));
  w.put_bytes(mask);
  for (const int32_t* p : set) w.put_array(p, fields);
}

void get_section(io::ByteReader& r, BrickArray& values, const BlockShape& shape, int fields, BrickPool* pool,
                 const char* field) {
  const int B = shape.edge, voxels = B * B * B;
  const auto set = r.get<uint32_t>(field);
  std::vector<uint8_t> mask((voxels + 7) / 8);
  r.get_array(mask.data(), mask.size(), field);
  std::vector<int> bricks;
  std::vector<uint8_t> needed(shape.bricks, 0);
  size_t count = 0;
  int v = 0;
  for (int z = 0; z < B; ++z)
    for (int y = 0; y < B; ++y)
      for (int x = 0; x < B; ++x, ++v) {
        if (!(mask[v / 8] & (1u << (v % 8)))) continue;
        ++count;
        const int b = shape.brick(x, y, z);
        if (!needed[b]) bricks.push_back(b);
        needed[b] = 1;
      }
  if (count != set) r.fail(field, "mask has " + std::to_string(count) + " voxels, count says " + std::to_string(set));
  if (count > r.remaining() / (fields * sizeof(int32_t)))
    r.fail(field, "needs " + std::to_string(count * fields * sizeof(int32_t)) + " bytes, " +
                      std::to_string(r.remaining()) + " left");
  std::sort(bricks.begin(), bricks.end());
  values = BrickArray{};
  if (bricks.empty()) return;
  values.allocate(shape, fields, bricks, pool);
  v = 0;
  for (int z = 0; z < B; ++z)
    for (int y = 0; y < B; ++y)
      for (int x = 0; x < B; ++x, ++v) {
        if (!(mask[v / 8] & (1u << (v % 8)))) continue;
        int32_t* p = values.brick(shape.brick(x, y, z)) + BlockShape::in_brick(x, y, z) * fields;
        r.get_array(p, fields, field);
      }
}

std::vector<uint8_t> encode_block(const Block& b, const BlockShape& shape) {
  io::ByteWriter w;
  w.put<uint32_t>(kBlockMagic);
  w.put<uint16_t>(kBlockVersion);
  w.put<uint16_t>(static_cast<uint16_t>(shape.edge));
  w.put<uint16_t>(kSurfaceFields);
  w.put<uint16_t>(kChannelFields);
  std::vector<const Channel*> kept;
  for (const auto& c : b.channels)
    if (!c.bricks.slot.empty()) kept.push_back(&c);
  w.put<uint32_t>(static_cast<uint32_t>(kept.size()));
  for (const Channel* c : kept) w.put<uint32_t>(c->id);
  put_section(w, b.surface, shape, kSurfaceFields);
  for (const Channel* c : kept) put_section(w, c->bricks, shape, kChannelFields);
  return std::move(w.bytes());
}

// Surface bricks from `pool`, channel bricks from the heap.
Block decode_block(const std::vector<uint8_t>& bytes, const BlockShape& shape, const BlockKey& key, BrickPool* pool) {
  const std::string source = "grid block (" + std::to_string(key.x) + ", " + std::to_string(key.y) + ", " +
                             std::to_string(key.z) + ")";
  io::ByteReader r(bytes, source);
  if (r.get<uint32_t>("magic") != kBlockMagic) r.fail("magic", "not an Artisan grid block");
  const auto version = r.get<uint16_t>("version");
  if (version != kBlockVersion) r.fail("version", "unsupported version " + std::to_string(version));
  const auto stored_edge = r.get<uint16_t>("block_edge");
  if (stored_edge != shape.edge)
    r.fail("block_edge", std::to_string(stored_edge) + " voxels, the grid has " + std::to_string(shape.edge));
  if (r.get<uint16_t>("surface_fields") != kSurfaceFields) r.fail("surface_fields", "unexpected count");
  if (r.get<uint16_t>("channel_fields") != kChannelFields) r.fail("channel_fields", "unexpected count");
  const auto channel_count = r.get<uint32_t>("channel_count");
  if (channel_count > 65536) r.fail("channel_count", std::to_string(channel_count) + " is too many");
  std::vector<uint32_t> ids(channel_count);
  for (auto& id : ids) {
    id = r.get<uint32_t>("channel_id");
    if (id >= 65536) r.fail("channel_id", std::to_string(id) + " out of range");
  }
  Block b;
  get_section(r, b.surface, shape, kSurfaceFields, pool, "surface");
  for (uint32_t id : ids) {
    const size_t before = b.channels.size();
    BrickArray& c = b.channel(id);
    if (b.channels.size() == before) r.fail("channel_id", "channel " + std::to_string(id) + " twice");
    get_section(r, c, shape, kChannelFields, nullptr, "channel");
  }
  if (r.remaining() != 0) r.fail("end", std::to_string(r.remaining()) + " trailing bytes");
  b.channels.shrink_to_fit();
  return b;
}

// ---- the cache ----

class BlockCache {
 public:
  BlockCache(BlockStore& store, const GridDefinition& def)
      : store_(store), def_(def), shape_(def.block_edge_voxels),
        pool_(static_cast<size_t>(kBrickVoxels) * kSurfaceFields * sizeof(int32_t)),
        max_block_bytes_(shape_.full_bytes(kSurfaceFields) + shape_.full_bytes(kChannelFields)) {
    for (const BlockKey& key : store_.keys()) stored_.emplace(key, 0);
  }

  const BlockShape& shape() const { return shape_; }
  BrickPool& pool() { return pool_; }
  Block* resident(const BlockKey& key) {
    auto it = blocks_.find(key);
    return it == blocks_.end() ? nullptr : it->second.get();
  }

  // Bytes `key` would add when brought in: 0 when resident or new; its size when last evicted;
  // for a block from an earlier session, the largest block size seen (at least a full block).
  size_t load_estimate(const BlockKey& key) const {
    if (blocks_.count(key)) return 0;
    auto it = stored_.find(key);
    if (it == stored_.end()) return 0;
    return it->second > 0 ? it->second : max_block_bytes_;
  }

  // The block, pinned; absent blocks are made (create) or nullptr.
  Block* pin(const BlockKey& key, bool create) {
    if (Block* b = resident(key)) {
      lru_.splice(lru_.begin(), lru_, b->lru);
      ++b->pins;
      return b;
    }
    auto bytes = load_bytes(key);
    if (!bytes && !create) return nullptr;
    return insert_pinned(key, bytes ? std::make_unique<Block>(decode_block(*bytes, shape_, key, &pool_)) : std::make_unique<Block>());
  }

  // The stored bytes of a block that is not resident, or nullopt for a new one.
  std::optional<std::vector<uint8_t>> load_bytes(const BlockKey& key) {
    if (!stored_.count(key)) return std::nullopt;
    auto bytes = store_.load(key);
    if (bytes) ++stats_.loads;
    return bytes;
  }

  // Makes `b` the resident, pinned block `key` (not resident before).
  Block* insert_pinned(const BlockKey& key, std::unique_ptr<Block> b) {
    lru_.push_front(key);
    b->lru = lru_.begin();
    b->pins = 1;
    Block* out = blocks_.emplace(key, std::move(b)).first->second.get();
    recount(out);
    return out;
  }

  void unpin(Block* b) { --b->pins; }

  // Counts a block's present size (after it grew).
  void recount(Block* b) {
    const size_t now = b->bytes();
    account(static_cast<int64_t>(now) - static_cast<int64_t>(b->accounted));
    b->accounted = now;
    max_block_bytes_ = std::max(max_block_bytes_, now);
  }

  // Bytes promised to blocks about to grow or be loaded: make_room keeps room for them.
  void reserve(size_t bytes) { reserved_ += bytes; }
  void release(size_t bytes) { reserved_ -= std::min(reserved_, bytes); }

  // Stores the dirty ones of `blocks` (resident) in order, then calls done(it) for each of
  // `blocks`. Encoding runs on every thread, a few blocks per thread at a time (the encoded bytes
  // in memory stay bounded); the store serves one thread at a time. When the store throws, the
  // blocks not yet done stay resident and dirty.
  template <typename Done>
  void store_dirty(const std::vector<std::list<BlockKey>::iterator>& blocks, Done done) {
    const size_t group = 2 * static_cast<size_t>(omp_get_max_threads());
    std::vector<std::vector<uint8_t>> bytes(group);
    for (size_t first = 0; first < blocks.size(); first += group) {
      const size_t count = std::min(group, blocks.size() - first);
      std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1) if (count > 1)
      for (size_t j = 0; j < count; ++j) {
        try {
          const Block& b = *blocks_.find(*blocks[first + j])->second;
          bytes[j] = b.dirty ? encode_block(b, shape_) : std::vector<uint8_t>{};
        } catch (...) {
#pragma omp critical(artisan_grid_encode)
          if (!error) error = std::current_exception();
        }
      }
      if (error) std::rethrow_exception(error);
      for (size_t j = 0; j < count; ++j) {
        const auto it = blocks[first + j];
        if (blocks_.find(*it)->second->dirty) {
          store_.store(*it, bytes[j]);
          ++stats_.stores;
        }
        done(it);
      }
    }
  }

  // Evicts unpinned blocks, least recently used first, until `needed` more bytes (beyond the
  // reservations) fit the budget; dirty ones are stored first.
  void make_room(size_t needed) {
    std::vector<std::list<BlockKey>::iterator> victims;
    size_t freed = 0;
    for (auto it = lru_.end(); stats_.resident_bytes + reserved_ + needed > def_.memory_budget_bytes + freed && it != lru_.begin();) {
      --it;
      const Block* b = blocks_.find(*it)->second.get();
      if (b->pins > 0) continue;
      victims.push_back(it);
      freed += b->accounted;
    }
    store_dirty(victims, [&](std::list<BlockKey>::iterator it) {
      Block* b = blocks_.find(*it)->second.get();
      stored_[*it] = b->accounted;
      account(-static_cast<int64_t>(b->accounted));
      ++stats_.evictions;
      blocks_.erase(*it);
      lru_.erase(it);
    });
  }

  void flush() {
    std::vector<std::list<BlockKey>::iterator> dirty;
    for (auto it = lru_.begin(); it != lru_.end(); ++it)
      if (blocks_.find(*it)->second->dirty) dirty.push_back(it);
    store_dirty(dirty, [&](std::list<BlockKey>::iterator it) {
      Block* b = blocks_.find(*it)->second.get();
      b->dirty = false;
      stored_[*it] = b->accounted;
    });
  }

  // Every block with data, sorted: the store's and the resident ones.
  std::vector<BlockKey> keys() {
    std::vector<BlockKey> out = store_.keys();
    for (const auto& [key, b] : blocks_) out.push_back(key);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }

  size_t max_block_bytes() const { return max_block_bytes_; }
  GridCacheStats stats() const {
    GridCacheStats s = stats_;
    s.resident_blocks = blocks_.size();
    return s;
  }

 private:
  void account(int64_t delta) {
    stats_.resident_bytes = static_cast<size_t>(static_cast<int64_t>(stats_.resident_bytes) + delta);
    stats_.peak_resident_bytes = std::max(stats_.peak_resident_bytes, stats_.resident_bytes);
  }

  BlockStore& store_;
  const GridDefinition& def_;
  BlockShape shape_;
  BrickPool pool_;  // surface bricks; before blocks_, which return theirs when destroyed
  size_t max_block_bytes_;
  size_t reserved_ = 0;
  std::unordered_map<BlockKey, std::unique_ptr<Block>, BlockKeyHash> blocks_;
  // Blocks the store holds, with their size in memory when this cache evicted them (0: unknown).
  std::unordered_map<BlockKey, size_t, BlockKeyHash> stored_;
  std::list<BlockKey> lru_;  // front: most recently used
  GridCacheStats stats_;
};

// ---- distribution ----

struct Splat {
  double p[3];     // centre [voxels]
  float a[6];      // inverse covariance [1/voxel^2]: xx xy xz yy yz zz
  float n[3];      // unit normal, toward the sensor
  float rgb[3];    // [0, 1]
  float w;         // weight
  int32_t lo[3];   // inclusive voxel box
  int32_t hi[3];
  int32_t block_lo[3];  // inclusive box of block keys
  int32_t block_hi[3];
};

// exp(x) for x in [-80, 0] with a relative error below 3e-7, in plain arithmetic so that loops
// over it vectorize (the library's expf is a call): exp(x) = 2^k * exp(f ln 2), k the integer
// nearest to x log2(e), |f| <= 1/2, the second factor by its Taylor series to degree 6.
inline float exp_nonpositive(float x) {
  const float t = x * 1.44269504f;
  const int32_t k = static_cast<int32_t>(t - 0.5f);  // t <= 0: truncation gives the nearest integer
  const float f = (t - static_cast<float>(k)) * 0.693147181f;
  const float p =
      1.0f + f * (1.0f + f * (0.5f + f * (1.0f / 6.0f + f * (1.0f / 24.0f + f * (1.0f / 120.0f + f * (1.0f / 720.0f))))));
  const int32_t bits = (k + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return p * scale;
}

// Eight floats or integers in one (AVX) register, or two (SSE); GCC vector extensions, so the
// same code serves both compilations of the kernel.
typedef float f8 __attribute__((vector_size(32)));
typedef int32_t i8 __attribute__((vector_size(32)));
typedef float f4 __attribute__((vector_size(16)));

// Bricks of a block that a splat's box covers, marked in `rows` (per row of bricks along x, by
// (y, z) brick index, one bit per brick).
void mark_bricks(const BlockShape& shape, const Splat& s, const BlockKey& key, std::vector<uint64_t>& rows) {
  const int B = shape.edge, nb = shape.bricks_per_edge;
  const int32_t origin[3] = {key.x * B, key.y * B, key.z * B};
  int lo[3], hi[3];
  for (int k = 0; k < 3; ++k) {
    lo[k] = std::max(s.lo[k] - origin[k], 0) / kBrickEdge;
    hi[k] = std::min(s.hi[k] - origin[k], B - 1) / kBrickEdge;
  }
  const uint64_t bits = ((uint64_t{2} << (hi[0] - lo[0])) - 1) << lo[0];
  for (int z = lo[2]; z <= hi[2]; ++z)
    for (int y = lo[1]; y <= hi[1]; ++y) rows[z * nb + y] |= bits;
}

// One block's contributions from one distribute() call, accumulated in floats (16 per voxel:
// the 13 surface fields, then g r, g g, g b; the colour weight sum g is L's) and then rounded
// once per voxel and field into the block's fixed-point sums (commit). A block's splats are always
// applied together by one thread in splat order, so the rounded values depend only on the mesh
// and the block: the integer sums stay independent of mesh order, threads and paging.
class BlockAccumulator {
 public:
  static constexpr int kFields = 16;
  static constexpr int kLanes = 8;

  explicit BlockAccumulator(const BlockShape& shape)
      : shape_(shape), voxels_(shape.edge * shape.edge * shape.edge),
        acc_(static_cast<float*>(std::aligned_alloc(64, static_cast<size_t>(voxels_) * kFields * sizeof(float)))),
        args_(static_cast<size_t>(voxels_) + 2 * kLanes), g_(args_.size()), voxel_(args_.size()), row_step_(args_.size()),
        rows_(static_cast<size_t>(shape.edge) * shape.edge + 2 * kLanes), heads_(4 * (static_cast<size_t>(shape.edge) * shape.edge + 1)),
        row_mask_(static_cast<size_t>(shape.edge) * shape.edge, 0) {
    if (!acc_) throw std::bad_alloc();
    std::memset(acc_.get(), 0, static_cast<size_t>(voxels_) * kFields * sizeof(float));
  }

  // Adds one splat's Gaussian over the voxels of block `key` inside its support ellipsoid, in
  // three passes without data-dependent branches (rows of two or three voxels made the branches
  // of a row-by-row loop its main cost):
  //  1. rows along x: for fixed (y, z) the quadratic form is q(dx) = a_xx dx^2 + 2 qb dx + qc,
  //     whose roots bound the row (eight rows at a time); each row writes eight lanes of
  //     exponents and voxel indices to flat lists, of which its length are kept (the next row
  //     writes over the rest);
  //  2. the Gaussian on the whole list in one vectorized loop;
  //  3. per voxel, sums += g * (1, -A (x - p), n n^T (6), n (3), rgb) as two 8-float vectors.
  // Compiled twice, for AVX2 and for the baseline, and picked when the program loads; no FMA
  // contraction in either, so both give the same bits.
  __attribute__((target_clones("avx2", "default")))
  size_t splat(const Splat& s, const BlockKey& key, float support2) {
    const int B = shape_.edge;
    const int32_t bx = key.x * B, by = key.y * B, bz = key.z * B;
    const int32_t z0 = std::max(s.lo[2], bz), z1 = std::min(s.hi[2], bz + B - 1);
    const int32_t y0 = std::max(s.lo[1], by), y1 = std::min(s.hi[1], by + B - 1);
    const float* a = s.a;
    // Block-local float coordinates: the splat's centre relative to the block's first voxel.
    const float cx = static_cast<float>(s.p[0] - bx), cy = static_cast<float>(s.p[1] - by), cz = static_cast<float>(s.p[2] - bz);
    const int32_t lx_lo = std::max(s.lo[0] - bx, 0), lx_hi = std::min(s.hi[0] - bx, B - 1);
    const float a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3], a4 = a[4], a5 = a[5], inv_a0 = 1.0f / a0;
    const float fB = static_cast<float>(B);
    const float gn[6] = {s.n[0] * s.n[0], s.n[0] * s.n[1], s.n[0] * s.n[2], s.n[1] * s.n[1], s.n[1] * s.n[2], s.n[2] * s.n[2]};
    const f8 iota = {0, 1, 2, 3, 4, 5, 6, 7};
    const i8 iota_i = {0, 1, 2, 3, 4, 5, 6, 7};
    float* args = args_.data();
    int32_t* voxel = voxel_.data();
    int32_t* row_step = row_step_.data();
    float* heads = heads_.data();
    Rows& r = rows_;

    // 1a. The candidate rows (y, z): the splat's box in the block.
    int candidates = 0;
    for (int32_t z = z0; z <= z1; ++z) {
      const int n = y1 - y0 + 1;
      const i8 ly = (y0 - by) + iota_i, lz = i8{} + (z - bz);
      int c = 0;
      do {  // eight at a time; the next z writes over the surplus
        const i8 y8 = ly + c;
        std::memcpy(r.y.data() + candidates + c, &y8, sizeof y8);
        std::memcpy(r.z.data() + candidates + c, &lz, sizeof lz);
        c += kLanes;
      } while (c < n);
      candidates += std::max(n, 0);
    }
    // 1b. Their voxels lx with centre lx + 0.5 inside the ellipsoid, within the splat's box, and
    // A (x - p) at the first (it grows by A's first column per step), eight rows at a time.
    const int lanes = (candidates + kLanes - 1) / kLanes * kLanes;
#pragma omp simd
    for (int k = 0; k < lanes; ++k) {
      const float dz = static_cast<float>(r.z[k]) + 0.5f - cz;
      const float qb_z = a2 * dz, qc_y = 2.0f * a4 * dz, qc_z = a5 * dz * dz;
      const float dy = static_cast<float>(r.y[k]) + 0.5f - cy;
      const float qb = a1 * dy + qb_z;
      const float qc = (a3 * dy + qc_y) * dy + qc_z;
      r.qb[k] = qb;
      r.qc[k] = qc;
      r.disc[k] = qb * qb - a0 * (qc - support2);
    }
#if defined(__x86_64__)
    for (int k = 0; k < lanes; k += 4)
      _mm_storeu_ps(r.root.data() + k, _mm_sqrt_ps(_mm_max_ps(_mm_loadu_ps(r.disc.data() + k), _mm_setzero_ps())));
#else
    for (int k = 0; k < lanes; ++k) r.root[k] = std::sqrt(std::max(r.disc[k], 0.0f));
#endif
#pragma omp simd
    for (int k = 0; k < lanes; ++k) {
      const float qb = r.qb[k], root = r.root[k];
      const float xlo = std::min(std::max(cx + (-qb - root) * inv_a0 - 0.5f, -1.0f), fB);
      const float xhi = std::min(std::max(cx + (-qb + root) * inv_a0 - 0.5f, -1.0f), fB);
      int32_t lx0 = static_cast<int32_t>(xlo), lx1 = static_cast<int32_t>(xhi);
      lx0 += static_cast<int32_t>(static_cast<float>(lx0) < xlo);  // ceil
      lx1 -= static_cast<int32_t>(static_cast<float>(lx1) > xhi);  // floor
      lx0 = std::max(lx0, lx_lo);
      lx1 = std::min(lx1, lx_hi);
      const int32_t keep = static_cast<int32_t>(r.disc[k] >= 0.0f) & static_cast<int32_t>(k < candidates);
      r.count[k] = std::max(lx1 - lx0 + 1, 0) * keep;
      r.lx0[k] = lx0;
      r.row[k] = r.z[k] * B + r.y[k];
      const float dx0 = static_cast<float>(lx0) + 0.5f - cx;
      const float dy = static_cast<float>(r.y[k]) + 0.5f - cy;
      const float dz = static_cast<float>(r.z[k]) + 0.5f - cz;
      r.dx0[k] = dx0;
      r.ax[k] = -(a0 * dx0 + a1 * dy + a2 * dz);
      r.ay[k] = -(a1 * dx0 + a3 * dy + a4 * dz);
      r.az[k] = -(a2 * dx0 + a4 * dy + a5 * dz);
    }
    // 1c. The rows with voxels.
    int rows = 0;
    for (int k = 0; k < candidates; ++k) {
      r.kept[rows] = k;
      rows += r.count[k] > 0;
    }
    // 1d. Each row's voxels: eight lanes of exponents, block indices and (row, step) written,
    // as many kept as the row has.
    int total = 0;
    for (int j = 0; j < rows; ++j) {
      const int k = r.kept[j];
      const int count = r.count[k], lx0 = r.lx0[k], row = r.row[k];
      const float dx0 = r.dx0[k], qb = r.qb[k], qc = r.qc[k];
      float* head = heads + 4 * j;
      head[0] = 1.0f;
      head[1] = r.ax[k];
      head[2] = r.ay[k];
      head[3] = r.az[k];
      // The row's voxels in its mask (bit lx), for commit().
      row_mask_[row] |= ((uint64_t{2} << (count - 1)) - 1) << lx0;
      const int v0 = row * B + lx0;
      int c = 0;
      do {  // eight voxels at a time: once, unless the row is longer
        const f8 dx = dx0 + (static_cast<float>(c) + iota);
        const f8 q = -0.5f * (qc + (2.0f * qb + a0 * dx) * dx);
        const f8 arg = q > -80.0f ? q : -80.0f;
        const i8 index = v0 + c + iota_i, rs = (j * 64 + c) + iota_i;
        std::memcpy(args + total, &arg, sizeof arg);
        std::memcpy(voxel + total, &index, sizeof index);
        std::memcpy(row_step + total, &rs, sizeof rs);
        total += std::min(count - c, kLanes);
        c += kLanes;
      } while (c < count);
    }
    const int padded = (total + kLanes - 1) / kLanes * kLanes;
    for (int i = total; i < padded; ++i) args[i] = 0.0f;
    const float w = s.w;
    float* g = g_.data();
#pragma omp simd
    for (int i = 0; i < padded; ++i) g[i] = w * exp_nonpositive(args[i]);

    const f8 step = {0.0f, -a0, -a1, -a2, 0.0f, 0.0f, 0.0f, 0.0f};
    const f4 n_outer = {gn[0], gn[1], gn[2], gn[3]};
    const f8 tail = {gn[4], gn[5], s.n[0], s.n[1], s.n[2], s.rgb[0], s.rgb[1], s.rgb[2]};
    float* __restrict acc = acc_.get();
    for (int i = 0; i < total; ++i) {
      float* out = acc + static_cast<size_t>(voxel[i]) * kFields;
      f4 head;
      f8 lo, hi;
      std::memcpy(&head, heads + 4 * (row_step[i] >> 6), sizeof head);
      std::memcpy(&lo, out, sizeof lo);
      std::memcpy(&hi, out + 8, sizeof hi);
      lo += g[i] * (__builtin_shufflevector(head, n_outer, 0, 1, 2, 3, 4, 5, 6, 7) + step * static_cast<float>(row_step[i] & 63));
      hi += g[i] * tail;
      std::memcpy(out, &lo, sizeof lo);
      std::memcpy(out + 8, &hi, sizeof hi);
    }
    return static_cast<size_t>(total);
  }

  // Rounds the sums into the block (scale kScale, to nearest, integers added modulo 2^32) and
  // clears them; the bricks with written voxels get memory in the block first.
  void commit(Block& block, int channel, BrickPool* pool) {
    const int B = shape_.edge, nb = shape_.bricks_per_edge;
    const uint64_t nibble = (uint64_t{1} << kBrickEdge) - 1;
    touched_.clear();
    for (int cz = 0; cz < nb; ++cz)
      for (int cy = 0; cy < nb; ++cy) {
        uint64_t m = 0;
        for (int z = cz * kBrickEdge; z < std::min(B, (cz + 1) * kBrickEdge); ++z)
          for (int y = cy * kBrickEdge; y < std::min(B, (cy + 1) * kBrickEdge); ++y) m |= row_mask_[z * B + y];
        for (int cx = 0; cx < nb; ++cx)
          if ((m >> (cx * kBrickEdge)) & nibble) touched_.push_back((cz * nb + cy) * nb + cx);
      }
    if (touched_.empty()) return;
    block.surface.allocate(shape_, kSurfaceFields, touched_, pool);
    BrickArray* colour = nullptr;
    if (channel >= 0) {
      colour = &block.channel(static_cast<uint32_t>(channel));
      colour->allocate(shape_, kChannelFields, touched_, nullptr);
    }
    constexpr size_t kBrickSurfaceBytes = static_cast<size_t>(kBrickVoxels) * kSurfaceFields * sizeof(int32_t);
    for (size_t t = 0; t < touched_.size(); ++t) {
      const int b = touched_[t];
      int32_t* surface = block.surface.brick(b);
      int32_t* rgb = colour ? colour->brick(b) : nullptr;
      if (t + 1 < touched_.size()) {  // the next brick's integers on their way while this one is summed
        const char* next = reinterpret_cast<const char*>(block.surface.brick(touched_[t + 1]));
        for (size_t o = 0; o < kBrickSurfaceBytes; o += 64) __builtin_prefetch(next + o, 1);
      }
      const int x0 = b % nb * kBrickEdge, y0 = b / nb % nb * kBrickEdge, z0 = b / nb / nb * kBrickEdge;
      const int x1 = std::min(x0 + kBrickEdge, B), y1 = std::min(y0 + kBrickEdge, B), z1 = std::min(z0 + kBrickEdge, B);
      for (int z = z0; z < z1; ++z)
        for (int y = y0; y < y1; ++y) {
          if (!((row_mask_[z * B + y] >> x0) & nibble)) continue;  // nothing written in this row of the brick
          for (int x = x0; x < x1; ++x) {
            float* in = acc_.get() + ((static_cast<size_t>(z) * B + y) * B + x) * kFields;
            const int v = BlockShape::in_brick(x, y, z);
            add_rounded(in, surface + v * kSurfaceFields, rgb ? rgb + v * kChannelFields : nullptr);
            std::memset(in, 0, kFields * sizeof(float));
          }
        }
    }
    std::fill(row_mask_.begin(), row_mask_.end(), 0);
  }

 private:
  // Adds the 16 sums of one voxel times kScale, rounded to the nearest integer (ties to even,
  // as std::lrint, saturated at +-2^31: a single mesh would need ~30000 head-on views of one
  // voxel), to its 13 surface integers and, when `rgb`, its 4 colour integers (the weight is L's).
  static void add_rounded(const float* in, int32_t* surface, int32_t* rgb) {
    const float S = static_cast<float>(kScale), top = 2147483520.0f;  // the largest float below 2^31
#if defined(__x86_64__)
    const __m128 s = _mm_set1_ps(S), hi = _mm_set1_ps(top), lo = _mm_set1_ps(-top);
    __m128i r[4];
    for (int k = 0; k < 4; ++k) r[k] = _mm_cvtps_epi32(_mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_loadu_ps(in + 4 * k), s), lo), hi));
    for (int k = 0; k < 3; ++k) {
      __m128i* out = reinterpret_cast<__m128i*>(surface + 4 * k);
      _mm_storeu_si128(out, _mm_add_epi32(_mm_loadu_si128(out), r[k]));
    }
    add(surface[12], _mm_cvtsi128_si32(r[3]));
    if (rgb) {  // (L, r, g, b): field 0, then fields 13..15
      const __m128i c = _mm_castps_si128(_mm_move_ss(_mm_castsi128_ps(r[3]), _mm_castsi128_ps(r[0])));
      __m128i* out = reinterpret_cast<__m128i*>(rgb);
      _mm_storeu_si128(out, _mm_add_epi32(_mm_loadu_si128(out), c));
    }
#else
    int32_t r[kFields];
    for (int k = 0; k < kFields; ++k) r[k] = static_cast<int32_t>(std::lrint(std::clamp(in[k] * S, -top, top)));
    for (int k = 0; k < kSurfaceFields; ++k) add(surface[k], r[k]);
    if (rgb) {
      add(rgb[0], r[0]);
      for (int k = 0; k < 3; ++k) add(rgb[1 + k], r[kSurfaceFields + k]);
    }
#endif
  }

  struct Free {
    void operator()(float* p) const { std::free(p); }
  };

  BlockShape shape_;
  int voxels_;
  std::unique_ptr<float, Free> acc_;  // voxels * kFields, 64-byte aligned
  // One splat's voxels in the block: exponent, Gaussian, block index, row, steps from its start.
  std::vector<float> args_, g_;
  std::vector<int32_t> voxel_, row_step_;  // row_step: row * 64 + steps from the row's start
  // One splat's candidate rows in the block (structure of arrays).
  struct Rows {
    explicit Rows(size_t n)
        : y(n), z(n), lx0(n), count(n), row(n), kept(n), qb(n), qc(n), disc(n), root(n), dx0(n), ax(n), ay(n), az(n) {}
    std::vector<int32_t> y, z, lx0, count, row, kept;
    std::vector<float> qb, qc, disc, root, dx0, ax, ay, az;
  };
  Rows rows_;
  std::vector<float> heads_;           // per row: (1, -A (x - p)) at its start
  std::vector<uint64_t> row_mask_;     // per row (y, z) of the block: voxels written since the last commit
  std::vector<int> touched_;
};

// ---- extraction ----

struct Sample {
  float L = 0;
  float f = 0;
  float n[3] = {0, 0, 0};
  float rgb[3] = {0, 0, 0};
  float cw = 0;  // colour weight
  bool valid = false;
};

void derive(const int32_t* raw, const std::vector<const int32_t*>& colours, double min_l, ExtractParams::Color mode,
            Sample& out) {
  out = Sample{};
  out.L = static_cast<float>(raw[0] / kScale);
  if (raw[0] / kScale < min_l) return;
  const Eigen::Vector3d N(raw[10], raw[11], raw[12]);
  Eigen::Matrix3d T;
  T << raw[4], raw[5], raw[6], raw[5], raw[7], raw[8], raw[6], raw[8], raw[9];
  // Consensus normal: T's principal eigenvector by power iteration from the mean normal
  // (deterministic, and one or two steps suffice where the normals agree), oriented by N.
  Eigen::Vector3d x = N;
  if (x.norm() < 1e-9 * raw[0]) {
    int k;
    T.diagonal().maxCoeff(&k);
    x = T.col(k);
  }
  if (!(x.norm() > 0)) return;
  x.normalize();
  for (int it = 0; it < 6; ++it) {
    const Eigen::Vector3d y = T * x;
    const double len = y.norm();
    if (!(len > 0)) return;
    x = y / len;
  }
  if (x.dot(N) < 0) x = -x;
  // f = (grad L . n) / L = d(log L)/dn: the same zero set as grad L . n, and linear across the
  // ridge for a Gaussian profile, so Marching Cubes' linear interpolation places it exactly.
  const Eigen::Vector3d G(raw[1], raw[2], raw[3]);
  out.f = static_cast<float>(G.dot(x) / raw[0]);
  for (int k = 0; k < 3; ++k) out.n[k] = static_cast<float>(x[k]);
  out.valid = true;
  double w = 0, c[3] = {0, 0, 0};
  for (const int32_t* ch : colours) {
    if (!ch || ch[0] <= 0) continue;
    if (mode == ExtractParams::Color::kBlend) {
      w += ch[0];
      for (int k = 0; k < 3; ++k) c[k] += ch[1 + k];
    } else if (ch[0] > w) {
      w = ch[0];
      for (int k = 0; k < 3; ++k) c[k] = ch[1 + k];
    }
  }
  if (w > 0) {
    out.cw = static_cast<float>(w / kScale);
    for (int k = 0; k < 3; ++k) out.rgb[k] = static_cast<float>(c[k] / w);
  }
}

struct EdgeKey {
  int32_t x, y, z, axis;
  bool operator==(const EdgeKey&) const = default;
};
struct EdgeKeyHash {
  size_t operator()(const EdgeKey& k) const noexcept {
    return BlockKeyHash{}(BlockKey{k.x, k.y, k.z}) * 3 + static_cast<size_t>(k.axis);
  }
};

struct BlockMesh {
  std::vector<EdgeKey> keys;
  std::vector<Eigen::Vector3f> vertices, normals, colours;
  std::vector<float> colour_weights;
  std::vector<Eigen::Vector3i> faces;  // local indices
  size_t cells = 0;
};

// A cell the ridge crosses is kept when its likeliest corner reaches min_likelihood and every
// corner has at least a quarter of that (enough evidence for a normal and f). Requiring
// min_likelihood at every corner, as before, cut the surface wherever it crossed a cell
// diagonally: a corner may lie sqrt(3) voxels off the ridge, where a Gaussian profile of sigma
// 0.8 voxel has fallen to a tenth. A sphere seen by one camera lost 70% of its surface that way
// at 1 mm voxels; a smaller share (1/16) let more of the bunny scans' misregistered second
// layers through (bench_integration: 0.3-0.5% more of the merge off the reference).
constexpr double kCornerLikelihoodShare = 0.25;

// Per-thread scratch for one block's extraction.
struct Scratch {
  std::vector<Sample> samples;      // (B+1)^3
  std::vector<int32_t> edge_vertex; // (B+1)^3 * 3, -1 = none
  std::vector<size_t> touched;
};

void extract_block(const BlockKey& key, const std::array<const Block*, 8>& blocks, const GridDefinition& def,
                   const ExtractParams& params, Scratch& scratch, BlockMesh& out) {
  const int B = def.block_edge_voxels, P = B + 1;
  const BlockShape shape(B);
  const size_t P3 = static_cast<size_t>(P) * P * P;
  scratch.samples.resize(P3);
  if (scratch.edge_vertex.size() != P3 * 3) scratch.edge_vertex.assign(P3 * 3, -1);
  std::vector<const int32_t*> colours;
  for (int lz = 0; lz < P; ++lz)
    for (int ly = 0; ly < P; ++ly)
      for (int lx = 0; lx < P; ++lx) {
        const int nb = (lx == B ? 1 : 0) | (ly == B ? 2 : 0) | (lz == B ? 4 : 0);
        Sample& s = scratch.samples[(static_cast<size_t>(lz) * P + ly) * P + lx];
        const Block* b = blocks[nb];
        const int x = lx % B, y = ly % B, z = lz % B;
        const int32_t* raw = b ? b->surface.voxel(shape, kSurfaceFields, x, y, z) : nullptr;
        if (!raw) {  // no evidence there
          s = Sample{};
          continue;
        }
        colours.clear();
        for (const auto& ch : b->channels) colours.push_back(ch.bricks.voxel(shape, kChannelFields, x, y, z));
        derive(raw, colours, params.min_likelihood * kCornerLikelihoodShare, params.color, s);
      }
  const auto& table = mc::cases();
  const double h = def.voxel_size_m;
  const float min_l = static_cast<float>(params.min_likelihood);
  auto sample = [&](int x, int y, int z) -> const Sample& {
    return scratch.samples[(static_cast<size_t>(z) * P + y) * P + x];
  };
  auto vertex_of = [&](int x, int y, int z, int axis) -> int32_t {
    const size_t slot = ((static_cast<size_t>(z) * P + y) * P + x) * 3 + axis;
    int32_t& id = scratch.edge_vertex[slot];
    if (id >= 0) return id;
    scratch.touched.push_back(slot);
    const Sample& a = sample(x, y, z);
    const Sample& b = sample(x + (axis == 0), y + (axis == 1), z + (axis == 2));
    const double t = static_cast<double>(a.f) / (static_cast<double>(a.f) - b.f);
    const int32_t gx = key.x * B + x, gy = key.y * B + y, gz = key.z * B + z;
    Eigen::Vector3d p(gx + 0.5, gy + 0.5, gz + 0.5);
    p[axis] += t;
    Eigen::Vector3f n;
    for (int k = 0; k < 3; ++k) n[k] = static_cast<float>((1 - t) * a.n[k] + t * b.n[k]);
    n.normalize();
    Eigen::Vector3f c;
    for (int k = 0; k < 3; ++k) c[k] = static_cast<float>((1 - t) * a.rgb[k] + t * b.rgb[k]);
    id = static_cast<int32_t>(out.vertices.size());
    out.keys.push_back({gx, gy, gz, axis});
    out.vertices.push_back((p * h).cast<float>());
    out.normals.push_back(n);
    out.colours.push_back(c);
    out.colour_weights.push_back(static_cast<float>((1 - t) * a.cw + t * b.cw));
    return id;
  };
  for (int z = 0; z < B; ++z)
    for (int y = 0; y < B; ++y)
      for (int x = 0; x < B; ++x) {
        int config = 0;
        bool valid = true;
        float top = 0;
        Eigen::Vector3d nbar = Eigen::Vector3d::Zero(), grad = Eigen::Vector3d::Zero();
        for (int c = 0; c < 8 && valid; ++c) {
          const int cx = c & 1, cy = (c >> 1) & 1, cz = (c >> 2) & 1;
          const Sample& s = sample(x + cx, y + cy, z + cz);
          valid = s.valid;
          top = std::max(top, s.L);
          if (s.f > 0) config |= 1 << c;  // inside: behind the ridge
          nbar += Eigen::Vector3d(s.n[0], s.n[1], s.n[2]);
          grad += Eigen::Vector3d(cx ? s.f : -s.f, cy ? s.f : -s.f, cz ? s.f : -s.f);
        }
        if (!valid || config == 0 || config == 255 || top < min_l) continue;
        if (grad.dot(nbar) >= 0) continue;  // a valley of L, not a ridge
        ++out.cells;
        for (const auto& tri : table[config].triangles) {
          Eigen::Vector3i face;
          for (int k = 0; k < 3; ++k) {
            const auto o = mc::edge_origin(tri[k]);
            face[k] = vertex_of(x + o[0], y + o[1], z + o[2], mc::edge_axis(tri[k]));
          }
          out.faces.push_back(face);
        }
      }
  for (size_t slot : scratch.touched) scratch.edge_vertex[slot] = -1;
  scratch.touched.clear();
}

}  // namespace

// ---- GridDefinition ----

size_t GridDefinition::block_surface_bytes() const { return BlockShape(block_edge_voxels).full_bytes(kSurfaceFields); }
size_t GridDefinition::block_channel_bytes() const {
  return BlockShape(block_edge_voxels).full_bytes(kChannelFields) + sizeof(Channel);
}

bool GridDefinition::operator==(const GridDefinition& o) const {
  const bool same_bounds = bounds_m.has_value() == o.bounds_m.has_value() &&
                           (!bounds_m || (bounds_m->min() == o.bounds_m->min() && bounds_m->max() == o.bounds_m->max()));
  return voxel_size_m == o.voxel_size_m && same_bounds && block_edge_voxels == o.block_edge_voxels &&
         channels == o.channels && sensor == o.sensor && point_spread_sigma_voxels == o.point_spread_sigma_voxels &&
         resolution_sigma_voxels == o.resolution_sigma_voxels && support_sigmas == o.support_sigmas &&
         memory_budget_bytes == o.memory_budget_bytes;
}

void GridDefinition::validate() const {
  auto fail = [](const std::string& field, double value, const std::string& rule) {
    throw Error("grid definition: " + field + " = " + std::to_string(value) + ": " + rule);
  };
  auto nonneg = [&](const char* field, double v) {
    if (!(std::isfinite(v) && v >= 0)) fail(field, v, "must be finite and >= 0");
  };
  if (!(std::isfinite(voxel_size_m) && voxel_size_m > 0)) fail("voxel_size_m", voxel_size_m, "must be > 0");
  if (bounds_m) {
    for (int k = 0; k < 3; ++k)
      if (!(std::isfinite(bounds_m->min()[k]) && std::isfinite(bounds_m->max()[k]) &&
            bounds_m->min()[k] < bounds_m->max()[k]))
        fail("bounds_m", bounds_m->min()[k], "min must be finite and below max on every axis");
  }
  if (block_edge_voxels < 4 || block_edge_voxels > 64) fail("block_edge_voxels", block_edge_voxels, "must be in [4, 64]");
  nonneg("sensor.sigma_along_m", sensor.sigma_along_m);
  nonneg("sensor.sigma_along_per_m", sensor.sigma_along_per_m);
  nonneg("sensor.sigma_along_per_m2", sensor.sigma_along_per_m2);
  nonneg("sensor.sigma_across_m", sensor.sigma_across_m);
  nonneg("sensor.sigma_across_per_m", sensor.sigma_across_per_m);
  if (!(sensor.min_view_cosine >= 0 && sensor.min_view_cosine < 1))
    fail("sensor.min_view_cosine", sensor.min_view_cosine, "must be in [0, 1)");
  nonneg("point_spread_sigma_voxels", point_spread_sigma_voxels);
  if (!(std::isfinite(resolution_sigma_voxels) && resolution_sigma_voxels >= 0.25))
    fail("resolution_sigma_voxels", resolution_sigma_voxels, "must be >= 0.25");
  if (!(support_sigmas >= 1 && support_sigmas <= 6)) fail("support_sigmas", support_sigmas, "must be in [1, 6]");
  const size_t minimum = 8 * (block_surface_bytes() + block_channel_bytes());
  if (memory_budget_bytes < minimum)
    throw Error("grid definition: memory_budget_bytes = " + std::to_string(memory_budget_bytes) +
                ": must hold at least 8 blocks (" + std::to_string(minimum) + " bytes)");
}

std::string GridDefinition::to_json() const {
  nlohmann::json j;
  j["format"] = 1;
  j["voxel_size_m"] = voxel_size_m;
  if (bounds_m)
    j["bounds_m"] = {bounds_m->min().x(), bounds_m->min().y(), bounds_m->min().z(),
                     bounds_m->max().x(), bounds_m->max().y(), bounds_m->max().z()};
  else
    j["bounds_m"] = nullptr;
  j["block_edge_voxels"] = block_edge_voxels;
  j["channels"] = channels == ChannelMode::kShared ? "shared" : "per_mesh";
  j["sensor"] = {{"kind", sensor.kind == SensorModel::Kind::kLaser ? "laser" : "stereo"},
                 {"sigma_along_m", sensor.sigma_along_m},
                 {"sigma_along_per_m", sensor.sigma_along_per_m},
                 {"sigma_along_per_m2", sensor.sigma_along_per_m2},
                 {"sigma_across_m", sensor.sigma_across_m},
                 {"sigma_across_per_m", sensor.sigma_across_per_m},
                 {"min_view_cosine", sensor.min_view_cosine}};
  j["point_spread_sigma_voxels"] = point_spread_sigma_voxels;
  j["resolution_sigma_voxels"] = resolution_sigma_voxels;
  j["support_sigmas"] = support_sigmas;
  j["memory_budget_bytes"] = memory_budget_bytes;
  return j.dump();
}

GridDefinition GridDefinition::from_json(const std::string& text) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("grid definition: not JSON: ") + e.what());
  }
  GridDefinition d;
  std::string field;
  try {
    field = "format";
    if (j.at("format").get<int>() != 1) throw Error("grid definition: format " + j.at("format").dump() + " unsupported");
    field = "voxel_size_m";
    d.voxel_size_m = j.at(field).get<double>();
    field = "bounds_m";
    if (!j.at(field).is_null()) {
      const auto b = j.at(field).get<std::vector<double>>();
      if (b.size() != 6) throw Error("grid definition: bounds_m: needs 6 numbers, has " + std::to_string(b.size()));
      d.bounds_m = Eigen::AlignedBox3d(Eigen::Vector3d(b[0], b[1], b[2]), Eigen::Vector3d(b[3], b[4], b[5]));
    }
    field = "block_edge_voxels";
    d.block_edge_voxels = j.at(field).get<int>();
    field = "channels";
    const auto channels = j.at(field).get<std::string>();
    if (channels == "shared") d.channels = ChannelMode::kShared;
    else if (channels == "per_mesh") d.channels = ChannelMode::kPerMesh;
    else throw Error("grid definition: channels: \"" + channels + "\" is neither shared nor per_mesh");
    const auto& s = j.at("sensor");
    field = "sensor.kind";
    const auto kind = s.at("kind").get<std::string>();
    if (kind == "laser") d.sensor.kind = SensorModel::Kind::kLaser;
    else if (kind == "stereo") d.sensor.kind = SensorModel::Kind::kStereo;
    else throw Error("grid definition: sensor.kind: \"" + kind + "\" is neither laser nor stereo");
    field = "sensor.sigma_along_m";
    d.sensor.sigma_along_m = s.at("sigma_along_m").get<double>();
    field = "sensor.sigma_along_per_m";
    d.sensor.sigma_along_per_m = s.at("sigma_along_per_m").get<double>();
    field = "sensor.sigma_along_per_m2";
    d.sensor.sigma_along_per_m2 = s.at("sigma_along_per_m2").get<double>();
    field = "sensor.sigma_across_m";
    d.sensor.sigma_across_m = s.at("sigma_across_m").get<double>();
    field = "sensor.sigma_across_per_m";
    d.sensor.sigma_across_per_m = s.at("sigma_across_per_m").get<double>();
    field = "sensor.min_view_cosine";
    d.sensor.min_view_cosine = s.at("min_view_cosine").get<double>();
    field = "point_spread_sigma_voxels";
    d.point_spread_sigma_voxels = j.at(field).get<double>();
    field = "resolution_sigma_voxels";
    d.resolution_sigma_voxels = j.at(field).get<double>();
    field = "support_sigmas";
    d.support_sigmas = j.at(field).get<double>();
    field = "memory_budget_bytes";
    d.memory_budget_bytes = j.at(field).get<size_t>();
  } catch (const nlohmann::json::exception& e) {
    throw Error("grid definition: " + field + ": " + e.what());
  }
  d.validate();
  return d;
}

// ---- OccupancyGrid ----

namespace {

struct SurfaceSample {
  Eigen::Vector3d p;    // mesh frame
  Eigen::Vector3d n;    // mesh frame
  Eigen::Vector3f rgb;  // [0, 1]
  double area = 0;      // [m^2] of surface the sample stands for
};

// distribute()'s working memory, kept for the next call: fresh memory is slow to come by (page
// faults), and meshes of one grid are mostly alike in size.
struct DistributeScratch {
  std::vector<SurfaceSample> samples;
  std::vector<Splat> splats;
  std::vector<uint8_t> state;
  std::vector<uint32_t> flat;    // splat indices per block (distribute's bins)
  std::vector<uint32_t> counts;  // the bins' counting sort
  std::vector<std::unique_ptr<BlockAccumulator>> accumulators;  // per thread
};

}  // namespace

struct OccupancyGrid::Impl {
  Impl(const GridDefinition& d, BlockStore& s) : def(d), store(s), cache(s, def) {}
  DistributeScratch scratch;
  GridDefinition def;
  BlockStore& store;
  BlockCache cache;
};

OccupancyGrid::OccupancyGrid(const GridDefinition& definition, BlockStore& store) {
  definition.validate();
  impl_ = std::make_unique<Impl>(definition, store);
}

OccupancyGrid::~OccupancyGrid() = default;

const GridDefinition& OccupancyGrid::definition() const { return impl_->def; }
GridCacheStats OccupancyGrid::cache_stats() const { return impl_->cache.stats(); }
void OccupancyGrid::flush() { impl_->cache.flush(); }

DistributeResult OccupancyGrid::distribute(const TriangleMesh& mesh, const Transform& T_grid_mesh,
                                           const SensorView& view_mesh, int mesh_index) {
  const auto t0 = Clock::now();
  const GridDefinition& def = impl_->def;
  // ---- checks ----
  if (mesh.vertices.empty()) throw Error("distribute: the mesh has no vertices");
  if (!T_grid_mesh.matrix().allFinite()) throw Error("distribute: T_grid_mesh is not finite");
  if (mesh_index < 0) throw Error("distribute: mesh_index " + std::to_string(mesh_index) + " is negative");
  if (def.channels == ChannelMode::kPerMesh && mesh_index >= 65536)
    throw Error("distribute: mesh_index " + std::to_string(mesh_index) + " exceeds 65535 texture channels");
  mesh.validate();
  if (view_mesh.rays == SensorView::Rays::kPerspective) {
    if (!view_mesh.origin_mesh.allFinite()) throw Error("distribute: sensor origin is not finite");
  } else {
    const double len = view_mesh.toward_sensor_mesh.norm();
    if (!(std::isfinite(len) && std::abs(len - 1) < 1e-3))
      throw Error("distribute: toward_sensor_mesh must be a unit vector, its length is " + std::to_string(len));
    if (!(std::isfinite(view_mesh.parallel_range_m) && view_mesh.parallel_range_m >= 0))
      throw Error("distribute: parallel_range_m = " + std::to_string(view_mesh.parallel_range_m) + " must be >= 0");
  }
  std::vector<Eigen::Vector3f> normals = mesh.normals;
  if (normals.empty()) {
    TriangleMesh copy;
    copy.vertices = mesh.vertices;
    copy.faces = mesh.faces;
    copy.compute_vertex_normals();
    normals = std::move(copy.normals);
  }
  for (size_t i = 0; i < normals.size(); ++i)
    if (!normals[i].allFinite()) throw Error("distribute: normal " + std::to_string(i) + " is not finite");

  // ---- surface samples: the vertices, and sub-triangle centroids of faces longer than two
  // point-spread sigmas (a thinned mesh's large flat triangles), so every sample's tangent
  // spread stays near the point-spread sigma: a wide tangent spread would push the ridge out of
  // convex surfaces by about sigma_t^2 / radius.
  const double h = def.voxel_size_m;
  const size_t vertex_count = mesh.vertices.size();
  const bool has_faces = !mesh.faces.empty();
  const bool has_colour = mesh.colors.size() == vertex_count || (!mesh.texture.empty() && mesh.uv.size() == vertex_count);
  const int channel = !has_colour ? -1 : (def.channels == ChannelMode::kShared ? 0 : mesh_index);
  auto& samples = impl_->scratch.samples;
  samples.clear();
  samples.resize(vertex_count);
  for (size_t i = 0; i < vertex_count; ++i) {
    samples[i].p = mesh.vertices[i].cast<double>();
    samples[i].n = normals[i].cast<double>();
    samples[i].rgb.setZero();
    if (!has_colour) continue;
    Color3 c;
    if (mesh.colors.size() == vertex_count) {
      c = mesh.colors[i];
    } else {
      const auto& tex = mesh.texture;
      const int px = std::clamp(static_cast<int>(mesh.uv[i].x() * tex.width), 0, tex.width - 1);
      const int py = std::clamp(static_cast<int>(mesh.uv[i].y() * tex.height), 0, tex.height - 1);
      const uint8_t* q = tex.at(px, py);
      c = tex.channels >= 3 ? Color3(q[0], q[1], q[2]) : Color3(q[0], q[0], q[0]);
    }
    samples[i].rgb = c.cast<float>() / 255.0f;
  }
  const double max_edge = 2.0 * std::max(def.point_spread_sigma_voxels, def.resolution_sigma_voxels) * h;
  // First pass (serial: vertex areas are shared between faces): each face's subdivision k and
  // where its k^2 samples go; second pass (parallel): the samples, in face order.
  const size_t face_count = mesh.faces.size();
  std::vector<int> face_k(face_count, 1);
  std::vector<size_t> first_sample(face_count + 1, vertex_count);
  for (size_t fi = 0; fi < face_count; ++fi) {
    const auto& f = mesh.faces[fi];
    const Eigen::Vector3d a = samples[f[0]].p, b = samples[f[1]].p, c = samples[f[2]].p;
    const double area = 0.5 * (b - a).cross(c - a).norm();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int k = static_cast<int>(std::min(256.0, std::ceil(longest / max_edge)));
    if (k <= 1) {
      for (int m = 0; m < 3; ++m) samples[f[m]].area += area / 3.0;
    } else {
      face_k[fi] = k;
    }
    first_sample[fi + 1] = first_sample[fi] + (k <= 1 ? 0 : static_cast<size_t>(k) * k);
  }
  samples.resize(first_sample[face_count]);
#pragma omp parallel for schedule(dynamic, 256)
  for (size_t fi = 0; fi < face_count; ++fi) {
    const int k = face_k[fi];
    if (k <= 1) continue;
    const auto& f = mesh.faces[fi];
    const SurfaceSample &A = samples[f[0]], &Bv = samples[f[1]], &Cv = samples[f[2]];
    const double piece = 0.5 * (Bv.p - A.p).cross(Cv.p - A.p).norm() / (k * k);
    size_t out = first_sample[fi];
    auto add_sample = [&](double u, double v) {
      const double w = 1.0 - u - v;
      SurfaceSample& s = samples[out++];
      s.p = w * A.p + u * Bv.p + v * Cv.p;
      s.n = (w * A.n + u * Bv.n + v * Cv.n).normalized();
      s.rgb = static_cast<float>(w) * A.rgb + static_cast<float>(u) * Bv.rgb + static_cast<float>(v) * Cv.rgb;
      s.area = piece;
    };
    for (int i = 0; i < k; ++i)
      for (int j = 0; i + j < k; ++j) {
        add_sample((i + 1.0 / 3) / k, (j + 1.0 / 3) / k);
        if (i + j + 1 < k) add_sample((i + 2.0 / 3) / k, (j + 2.0 / 3) / k);
      }
  }
  const size_t n = samples.size();

  // ---- splats ----
  const Eigen::Matrix3d R = T_grid_mesh.linear();
  const Eigen::Vector3d origin_grid = T_grid_mesh * view_mesh.origin_mesh;
  const Eigen::Vector3d toward_grid = (R * view_mesh.toward_sensor_mesh).normalized();
  Eigen::Vector3i bound_lo(INT32_MIN, INT32_MIN, INT32_MIN), bound_hi(INT32_MAX, INT32_MAX, INT32_MAX);
  if (def.bounds_m) {
    for (int k = 0; k < 3; ++k) {
      bound_lo[k] = static_cast<int32_t>(std::max(-kMaxVoxelIndex, std::floor(def.bounds_m->min()[k] / h)));
      bound_hi[k] = static_cast<int32_t>(std::min(kMaxVoxelIndex, std::ceil(def.bounds_m->max()[k] / h) - 1));
    }
  }
  auto& splats = impl_->scratch.splats;
  splats.clear();
  splats.resize(n);
  auto& state = impl_->scratch.state;  // 0 used, 1 oblique, 2 outside, 3 too far, 4 no area
  state.assign(n, 0);
  const double support = def.support_sigmas;
#pragma omp parallel for schedule(static)
  for (size_t i = 0; i < n; ++i) {
    if (has_faces && !(samples[i].area > 0)) {
      state[i] = 4;  // a vertex of large faces only: their samples carry the surface
      continue;
    }
    const Eigen::Vector3d p = T_grid_mesh * samples[i].p;
    Eigen::Vector3d nrm = (R * samples[i].n).normalized();
    Eigen::Vector3d v;
    double range;
    if (view_mesh.rays == SensorView::Rays::kPerspective) {
      v = origin_grid - p;
      range = v.norm();
      v /= range;
    } else {
      v = toward_grid;
      range = view_mesh.parallel_range_m;
    }
    double cosine = nrm.dot(v);
    if (cosine < 0) {
      nrm = -nrm;
      cosine = -cosine;
    }
    if (!(cosine >= def.sensor.min_view_cosine) || !(range > 0 || view_mesh.rays == SensorView::Rays::kParallel)) {
      state[i] = 1;
      continue;
    }
    const double sa = def.sensor.sigma_along(range) / h, sc = def.sensor.sigma_across(range) / h;
    const double area_v = samples[i].area / (h * h);
    const double st = std::max(def.point_spread_sigma_voxels, 0.7 * std::sqrt(area_v));
    const double s0 = def.resolution_sigma_voxels;
    const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    const Eigen::Matrix3d C = sa * sa * v * v.transpose() + sc * sc * (I - v * v.transpose()) +
                              st * st * (I - nrm * nrm.transpose()) + s0 * s0 * I;
    const Eigen::Matrix3d A = C.inverse();
    Splat& s = splats[i];
    const Eigen::Vector3d pv = p / h;
    bool outside = false;
    for (int k = 0; k < 3; ++k) {
      if (!(std::abs(pv[k]) < kMaxVoxelIndex)) {
        state[i] = 3;
        break;
      }
      s.p[k] = pv[k];
      const double e = support * std::sqrt(C(k, k));
      s.lo[k] = std::max(bound_lo[k], static_cast<int32_t>(std::ceil(pv[k] - e - 0.5)));
      s.hi[k] = std::min(bound_hi[k], static_cast<int32_t>(std::floor(pv[k] + e - 0.5)));
      s.block_lo[k] = static_cast<int32_t>(floor_div(s.lo[k], def.block_edge_voxels));
      s.block_hi[k] = static_cast<int32_t>(floor_div(s.hi[k], def.block_edge_voxels));
      outside = outside || s.lo[k] > s.hi[k];
      s.n[k] = static_cast<float>(nrm[k]);
      s.rgb[k] = samples[i].rgb[k];
    }
    if (state[i] == 3) continue;
    if (outside) {
      state[i] = 2;
      continue;
    }
    s.a[0] = static_cast<float>(A(0, 0));
    s.a[1] = static_cast<float>(A(0, 1));
    s.a[2] = static_cast<float>(A(0, 2));
    s.a[3] = static_cast<float>(A(1, 1));
    s.a[4] = static_cast<float>(A(1, 2));
    s.a[5] = static_cast<float>(A(2, 2));
    const double tangent_var = st * st + s0 * s0 + sc * sc;
    s.w = static_cast<float>(has_faces ? cosine * area_v / (2 * M_PI * tangent_var) : cosine);
  }
  for (size_t i = 0; i < n; ++i)
    if (state[i] == 3)
      throw Error("distribute: the mesh lies more than 2^29 voxels from the grid origin (sample " + std::to_string(i) + ")");

  // ---- bin by block ----
  DistributeResult result;
  BlockCache& cache = impl_->cache;
  const BlockShape& shape = cache.shape();
  // Bins: the splats of each block touched, in ascending splat order (the order of the sums),
  // as ranges of one flat list; bin_keys ascending. A counting sort over the box of block keys
  // the mesh touches, in parallel (each thread counts, then places, one range of splats); over a
  // very large box, a hash map instead, serially.
  auto& flat = impl_->scratch.flat;
  std::vector<BlockKey> bin_keys;
  std::vector<uint32_t> bin_begin;  // bin b: flat[bin_begin[b], bin_begin[b + 1])
  int32_t key_lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, key_hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
  size_t pairs = 0;
  for (size_t i = 0; i < n; ++i) {
    if (state[i] == 1) ++result.skipped_oblique;
    else if (state[i] == 2) ++result.skipped_outside;
    if (state[i] != 0) continue;
    ++result.points;
    const Splat& s = splats[i];
    size_t count = 1;
    for (int k = 0; k < 3; ++k) {
      key_lo[k] = std::min(key_lo[k], s.block_lo[k]);
      key_hi[k] = std::max(key_hi[k], s.block_hi[k]);
      count *= static_cast<size_t>(s.block_hi[k] - s.block_lo[k] + 1);
    }
    pairs += count;
  }
  flat.resize(pairs);
  const int64_t extent[3] = {int64_t{key_hi[0]} - key_lo[0] + 1, int64_t{key_hi[1]} - key_lo[1] + 1,
                             int64_t{key_hi[2]} - key_lo[2] + 1};
  const int64_t cells = result.points == 0 ? 0 : extent[0] * extent[1] * extent[2];
  if (cells > 0 && cells <= std::min<int64_t>(int64_t{1} << 22, 16 * static_cast<int64_t>(result.points) + 4096)) {
    // Cell of a key: x-major, so that ascending cells are ascending keys.
    auto cell_of = [&](int32_t x, int32_t y, int32_t z) {
      return static_cast<size_t>(((int64_t{x} - key_lo[0]) * extent[1] + (y - key_lo[1])) * extent[2] + (z - key_lo[2]));
    };
    const int threads = omp_get_max_threads();
    auto& counts = impl_->scratch.counts;  // [thread][cell]
    counts.assign(static_cast<size_t>(cells) * threads, 0);
    int team = 1;
#pragma omp parallel num_threads(threads)
    {
      const int t = omp_get_thread_num();
#pragma omp single
      team = omp_get_num_threads();
      const size_t first = n * t / team, last = n * (t + 1) / team;
      auto each_key = [&](auto&& f) {
        for (size_t i = first; i < last; ++i) {
          if (state[i] != 0) continue;
          const Splat& s = splats[i];
          for (int32_t x = s.block_lo[0]; x <= s.block_hi[0]; ++x)
            for (int32_t y = s.block_lo[1]; y <= s.block_hi[1]; ++y)
              for (int32_t z = s.block_lo[2]; z <= s.block_hi[2]; ++z) f(i, static_cast<size_t>(t) * cells + cell_of(x, y, z));
        }
      };
      each_key([&](size_t, size_t slot) { ++counts[slot]; });
#pragma omp barrier
#pragma omp single
      {
        uint32_t at = 0;
        for (size_t c = 0; c < static_cast<size_t>(cells); ++c) {
          const uint32_t start = at;
          for (int u = 0; u < team; ++u) {
            const uint32_t m = counts[static_cast<size_t>(u) * cells + c];
            counts[static_cast<size_t>(u) * cells + c] = at;
            at += m;
          }
          if (at == start) continue;
          const int64_t x = static_cast<int64_t>(c) / (extent[1] * extent[2]), rest = static_cast<int64_t>(c) % (extent[1] * extent[2]);
          bin_keys.push_back(BlockKey{static_cast<int32_t>(key_lo[0] + x), static_cast<int32_t>(key_lo[1] + rest / extent[2]),
                                      static_cast<int32_t>(key_lo[2] + rest % extent[2])});
          bin_begin.push_back(start);
        }
        bin_begin.push_back(at);
      }
      each_key([&](size_t i, size_t slot) { flat[counts[slot]++] = static_cast<uint32_t>(i); });
    }
  } else if (cells > 0) {
    std::map<BlockKey, uint32_t> count_of;
    for (size_t i = 0; i < n; ++i) {
      if (state[i] != 0) continue;
      const Splat& s = splats[i];
      for (int32_t x = s.block_lo[0]; x <= s.block_hi[0]; ++x)
        for (int32_t y = s.block_lo[1]; y <= s.block_hi[1]; ++y)
          for (int32_t z = s.block_lo[2]; z <= s.block_hi[2]; ++z) ++count_of[BlockKey{x, y, z}];
    }
    uint32_t at = 0;
    for (auto& [key, m] : count_of) {
      bin_keys.push_back(key);
      bin_begin.push_back(at);
      const uint32_t start = at;
      at += m;
      m = start;
    }
    bin_begin.push_back(at);
    for (size_t i = 0; i < n; ++i) {
      if (state[i] != 0) continue;
      const Splat& s = splats[i];
      for (int32_t x = s.block_lo[0]; x <= s.block_hi[0]; ++x)
        for (int32_t y = s.block_lo[1]; y <= s.block_hi[1]; ++y)
          for (int32_t z = s.block_lo[2]; z <= s.block_hi[2]; ++z) flat[count_of[BlockKey{x, y, z}]++] = static_cast<uint32_t>(i);
    }
  }
  std::vector<uint32_t> order(bin_keys.size());
  for (uint32_t k = 0; k < order.size(); ++k) order[k] = k;
  result.blocks_touched = order.size();
  // Blocks already in the cache first: under a budget smaller than the grid, the previous mesh
  // left the tail of its pass resident, and a plain key-order pass would evict it before use.
  std::stable_partition(order.begin(), order.end(), [&](uint32_t k) { return cache.resident(bin_keys[k]) != nullptr; });

  // What each block can grow by: the bricks its splats' boxes cover, and new brick tables.
  const bool colour = channel >= 0;
  const size_t brick_bytes = BrickArray::brick_bytes(kSurfaceFields, &cache.pool()) +
                             (colour ? BrickArray::brick_bytes(kChannelFields, nullptr) : 0);
  const size_t table_bytes = shape.bricks * sizeof(void*) * (colour ? 2 : 1) + (colour ? sizeof(Channel) : 0);
  std::vector<size_t> growth(order.size());
  // Under a budget that every block at its fullest fits (in memory), that bound will do.
  const size_t fullest = shape.full_bytes(kSurfaceFields) + (colour ? shape.full_bytes(kChannelFields) + sizeof(Channel) : 0);
  const bool roomy = cache.stats().resident_bytes + order.size() * fullest <= def.memory_budget_bytes;
  if (roomy) std::fill(growth.begin(), growth.end(), fullest);
#pragma omp parallel if (!roomy)
  if (!roomy) {
    std::vector<uint64_t> rows(static_cast<size_t>(shape.bricks_per_edge) * shape.bricks_per_edge);
#pragma omp for schedule(dynamic, 16)
    for (size_t j = 0; j < order.size(); ++j) {
      std::fill(rows.begin(), rows.end(), 0);
      for (uint32_t k = bin_begin[order[j]]; k < bin_begin[order[j] + 1]; ++k)
        mark_bricks(shape, splats[flat[k]], bin_keys[order[j]], rows);
      size_t bricks = 0;
      for (uint64_t r : rows) bricks += static_cast<size_t>(std::popcount(r));
      growth[j] = bricks * brick_bytes + table_bytes;
    }
  }

  // ---- apply, in batches that fit the budget ----
  const float support2 = static_cast<float>(support * support);
  size_t next = 0;
  std::vector<Block*> batch;
  std::vector<size_t> load_estimate;
  std::vector<std::optional<std::vector<uint8_t>>> stored;
  std::vector<std::unique_ptr<Block>> fresh;
  auto& accumulators = impl_->scratch.accumulators;
  if (accumulators.size() < static_cast<size_t>(omp_get_max_threads())) accumulators.resize(omp_get_max_threads());
  while (next < order.size()) {
    // Plan: blocks in order while their present size, what loading them adds and their growth
    // fit the budget (at least one).
    const size_t first = next;
    size_t planned = 0;
    while (next < order.size()) {
      const BlockKey& key = bin_keys[order[next]];
      const Block* r = cache.resident(key);
      const size_t need = (r ? r->accounted : cache.load_estimate(key)) + growth[next];
      if (next > first && planned + need > def.memory_budget_bytes) break;
      planned += need;
      ++next;
    }
    // Pin the resident ones (room is not made by evicting them), reserve room for the rest and
    // for the growth, evict, then load.
    batch.assign(next - first, nullptr);
    load_estimate.assign(next - first, 0);
    size_t reserved = 0;
    for (size_t j = 0; j < batch.size(); ++j) {
      const BlockKey& key = bin_keys[order[first + j]];
      if (cache.resident(key)) batch[j] = cache.pin(key, true);
      else load_estimate[j] = cache.load_estimate(key);
      reserved += load_estimate[j] + growth[first + j];
    }
    cache.reserve(reserved);
    // Evict, then read the absent blocks' stored bytes in turn (the store serves one thread at
    // a time); they are decoded in the parallel loop, and join the cache after it.
    stored.assign(batch.size(), std::nullopt);
    fresh.clear();
    fresh.resize(batch.size());
    try {
      cache.make_room(0);
      for (size_t j = 0; j < batch.size(); ++j)
        if (!batch[j]) stored[j] = cache.load_bytes(bin_keys[order[first + j]]);
    } catch (...) {
      for (Block* b : batch)
        if (b) cache.unpin(b);
      cache.release(reserved);
      throw;
    }
    size_t updates = 0;
    std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : updates)
    for (size_t j = 0; j < batch.size(); ++j) {
      try {
        const uint32_t bin = order[first + j];
        Block* block = batch[j];
        if (!block) {
          fresh[j] = stored[j] ? std::make_unique<Block>(decode_block(*stored[j], shape, bin_keys[bin], &cache.pool()))
                               : std::make_unique<Block>();
          stored[j].reset();
          block = fresh[j].get();
        }
        auto& acc = accumulators[omp_get_thread_num()];
        if (!acc) acc = std::make_unique<BlockAccumulator>(shape);
        for (uint32_t k = bin_begin[bin]; k < bin_begin[bin + 1]; ++k) updates += acc->splat(splats[flat[k]], bin_keys[bin], support2);
        acc->commit(*block, channel, &cache.pool());
      } catch (...) {
#pragma omp critical(artisan_grid_apply)
        if (!error) error = std::current_exception();
      }
    }
    for (size_t j = 0; j < batch.size(); ++j)
      if (!batch[j] && fresh[j]) {
        batch[j] = cache.insert_pinned(bin_keys[order[first + j]], std::move(fresh[j]));
        cache.release(load_estimate[j]);  // its real size is counted now
      }
    if (error) {  // a corrupt stored block: the batch's other blocks keep this mesh's evidence
      for (Block* b : batch)
        if (b) {
          b->dirty = true;
          cache.recount(b);
          cache.unpin(b);
        }
      cache.release(reserved);
      std::rethrow_exception(error);
    }
    result.voxel_updates += updates;
    for (Block* b : batch) {
      b->dirty = true;
      cache.recount(b);
      cache.unpin(b);
    }
    cache.release(reserved);
  }
  cache.make_room(0);
  result.seconds = seconds_since(t0);
  return result;
}

ExtractResult OccupancyGrid::extract(const ExtractParams& params) {
  const auto t0 = Clock::now();
  if (!(std::isfinite(params.min_likelihood) && params.min_likelihood > 0))
    throw Error("extract: min_likelihood = " + std::to_string(params.min_likelihood) + " must be > 0");
  const GridDefinition& def = impl_->def;
  BlockCache& cache = impl_->cache;
  const auto keys = cache.keys();
  const std::unordered_set<BlockKey, BlockKeyHash> present(keys.begin(), keys.end());
  ExtractResult result;
  TriangleMesh& mesh = result.mesh;
  std::unordered_map<EdgeKey, int32_t, EdgeKeyHash> vertex_ids;
  std::vector<float> colour_weights;

  const int threads = omp_get_max_threads();
  std::vector<Scratch> scratch(threads);
  size_t next = 0;
  std::vector<std::array<const Block*, 8>> batch_blocks;
  std::vector<Block*> pinned;
  std::vector<BlockMesh> outputs;
  while (next < keys.size()) {
    batch_blocks.clear();
    pinned.clear();
    size_t pinned_bytes = 0;
    std::unordered_map<BlockKey, Block*, BlockKeyHash> batch_pins;
    while (next < keys.size()) {
      const BlockKey& key = keys[next];
      std::array<BlockKey, 8> around;
      size_t estimate = 0;  // bytes the block's neighbourhood adds to the batch
      for (int c = 0; c < 8; ++c) {
        around[c] = BlockKey{key.x + (c & 1), key.y + ((c >> 1) & 1), key.z + ((c >> 2) & 1)};
        if (!present.count(around[c]) || batch_pins.count(around[c])) continue;
        const Block* r = cache.resident(around[c]);
        estimate += r ? r->accounted : cache.load_estimate(around[c]);
      }
      if (!batch_blocks.empty() && pinned_bytes + estimate > def.memory_budget_bytes) break;
      std::array<const Block*, 8> blocks{};
      for (int c = 0; c < 8; ++c) {
        if (!present.count(around[c])) continue;
        auto it = batch_pins.find(around[c]);
        if (it == batch_pins.end()) {
          cache.make_room(cache.load_estimate(around[c]));
          Block* b = cache.pin(around[c], false);
          it = batch_pins.emplace(around[c], b).first;
          if (b) {
            pinned.push_back(b);
            pinned_bytes += b->bytes();
          }
        }
        blocks[c] = it->second;
      }
      batch_blocks.push_back(blocks);
      ++next;
    }
    const size_t first = next - batch_blocks.size();
    outputs.assign(batch_blocks.size(), BlockMesh{});
#pragma omp parallel for schedule(dynamic, 1)
    for (size_t j = 0; j < batch_blocks.size(); ++j)
      extract_block(keys[first + j], batch_blocks[j], def, params, scratch[omp_get_thread_num()], outputs[j]);
    for (Block* b : pinned) cache.unpin(b);
    // Merge in key order: one vertex per grid edge.
    for (auto& out : outputs) {
      std::vector<int32_t> global(out.vertices.size());
      for (size_t v = 0; v < out.vertices.size(); ++v) {
        auto [it, inserted] = vertex_ids.try_emplace(out.keys[v], static_cast<int32_t>(mesh.vertices.size()));
        if (inserted) {
          mesh.vertices.push_back(out.vertices[v]);
          mesh.normals.push_back(out.normals[v]);
          mesh.colors.push_back((out.colours[v] * 255.0f).array().round().cwiseMax(0).cwiseMin(255).cast<uint8_t>());
          colour_weights.push_back(out.colour_weights[v]);
        }
        global[v] = it->second;
      }
      for (const auto& f : out.faces) mesh.faces.emplace_back(global[f[0]], global[f[1]], global[f[2]]);
      result.cells_on_surface += out.cells;
    }
    result.blocks += batch_blocks.size();
  }
  cache.make_room(0);
  result.voxels = result.blocks * static_cast<size_t>(def.block_edge_voxels) * def.block_edge_voxels *
                  def.block_edge_voxels;
  const bool any_colour = std::any_of(colour_weights.begin(), colour_weights.end(), [](float w) { return w > 0; });
  if (!any_colour) {
    mesh.colors.clear();
  } else {
    for (size_t v = 0; v < mesh.colors.size(); ++v)
      if (!(colour_weights[v] > 0)) mesh.colors[v] = Color3(128, 128, 128);
  }
  result.seconds = seconds_since(t0);
  return result;
}

}  // namespace artisan
