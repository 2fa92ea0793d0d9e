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
// Distribution: vertices become splats (centre, inverse covariance, weight, normal, colour, the
// box of voxels within support_sigmas); splats are binned by the blocks their box touches and the
// blocks are processed (those already in the cache first, then in key order) in batches that fit
// the memory budget, one block per thread, through a per-thread float accumulator whose rows of
// voxels along x are vectorized (BlockAccumulator).
//
// Extraction: blocks in key order, in batches that fit the budget with their +x/+y/+z
// neighbours (a cell's far corners lie in them); per block the derived samples (L, f, oriented
// consensus normal, colour) on (B+1)^3 voxels, then Marching Cubes on its B^3 cells. Vertices
// are keyed by their grid edge, so neighbouring blocks share them; blocks are merged in key order.
#include "artisan/perception/integration.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <list>
#include <unordered_map>
#include <unordered_set>

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

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

inline void add(int32_t& slot, int32_t value) {
  slot = static_cast<int32_t>(static_cast<uint32_t>(slot) + static_cast<uint32_t>(value));
}

// ---- blocks ----

struct Block {
  std::vector<int32_t> surface;                 // voxels * kSurfaceFields
  std::vector<std::vector<int32_t>> channels;   // per channel id: empty or voxels * kChannelFields
  bool dirty = false;
  bool unzeroed = false;  // a new block whose surface is reserved, zeroed by zero_if_new() (in parallel)
  int pins = 0;
  std::list<BlockKey>::iterator lru;

  size_t bytes() const {
    size_t n = surface.capacity();
    for (const auto& c : channels) n += c.capacity();
    return n * sizeof(int32_t);
  }
};

// Sparse encoding: header, channel ids, then per section (surface, each channel) an occupancy
// bit mask of the voxels with any non-zero field followed by those voxels' fields.
void put_section(io::ByteWriter& w, const std::vector<int32_t>& values, int fields, int voxels) {
  std::vector<uint8_t> mask((voxels + 7) / 8, 0);
  size_t set = 0;
  for (int v = 0; v < voxels; ++v) {
    const int32_t* p = values.data() + static_cast<size_t>(v) * fields;
    if (std::any_of(p, p + fields, [](int32_t x) { return x != 0; })) {
      mask[v / 8] = static_cast<uint8_t>(mask[v / 8] | (1u << (v % 8)));
      ++set;
    }
  }
  w.put<uint32_t>(static_cast<uint32_t>(set));
  w.put_bytes(mask);
  for (int v = 0; v < voxels; ++v)
    if (mask[v / 8] & (1u << (v % 8))) w.put_array(values.data() + static_cast<size_t>(v) * fields, fields);
}

void get_section(io::ByteReader& r, std::vector<int32_t>& values, int fields, int voxels, const char* field) {
  const auto set = r.get<uint32_t>(field);
  std::vector<uint8_t> mask((voxels + 7) / 8);
  r.get_array(mask.data(), mask.size(), field);
  values.assign(static_cast<size_t>(voxels) * fields, 0);
  size_t count = 0;
  for (int v = 0; v < voxels; ++v) {
    if (!(mask[v / 8] & (1u << (v % 8)))) continue;
    if (++count > set) r.fail(field, "more voxels in the mask than the count " + std::to_string(set));
    r.get_array(values.data() + static_cast<size_t>(v) * fields, fields, field);
  }
  if (count != set) r.fail(field, "mask has " + std::to_string(count) + " voxels, count says " + std::to_string(set));
}

std::vector<uint8_t> encode_block(const Block& b, int edge) {
  const int voxels = edge * edge * edge;
  io::ByteWriter w;
  w.put<uint32_t>(kBlockMagic);
  w.put<uint16_t>(kBlockVersion);
  w.put<uint16_t>(static_cast<uint16_t>(edge));
  w.put<uint16_t>(kSurfaceFields);
  w.put<uint16_t>(kChannelFields);
  std::vector<uint32_t> ids;
  for (size_t c = 0; c < b.channels.size(); ++c)
    if (!b.channels[c].empty()) ids.push_back(static_cast<uint32_t>(c));
  w.put<uint32_t>(static_cast<uint32_t>(ids.size()));
  for (uint32_t id : ids) w.put<uint32_t>(id);
  put_section(w, b.surface, kSurfaceFields, voxels);
  for (uint32_t id : ids) put_section(w, b.channels[id], kChannelFields, voxels);
  return std::move(w.bytes());
}

Block decode_block(const std::vector<uint8_t>& bytes, int edge, const BlockKey& key) {
  const std::string source = "grid block (" + std::to_string(key.x) + ", " + std::to_string(key.y) + ", " +
                             std::to_string(key.z) + ")";
  io::ByteReader r(bytes, source);
  if (r.get<uint32_t>("magic") != kBlockMagic) r.fail("magic", "not an Artisan grid block");
  const auto version = r.get<uint16_t>("version");
  if (version != kBlockVersion) r.fail("version", "unsupported version " + std::to_string(version));
  const auto stored_edge = r.get<uint16_t>("block_edge");
  if (stored_edge != edge) r.fail("block_edge", std::to_string(stored_edge) + " voxels, the grid has " + std::to_string(edge));
  if (r.get<uint16_t>("surface_fields") != kSurfaceFields) r.fail("surface_fields", "unexpected count");
  if (r.get<uint16_t>("channel_fields") != kChannelFields) r.fail("channel_fields", "unexpected count");
  const auto channel_count = r.get<uint32_t>("channel_count");
  if (channel_count > 65536) r.fail("channel_count", std::to_string(channel_count) + " is too many");
  std::vector<uint32_t> ids(channel_count);
  for (auto& id : ids) {
    id = r.get<uint32_t>("channel_id");
    if (id >= 65536) r.fail("channel_id", std::to_string(id) + " out of range");
  }
  const int voxels = edge * edge * edge;
  Block b;
  get_section(r, b.surface, kSurfaceFields, voxels, "surface");
  for (uint32_t id : ids) {
    if (b.channels.size() <= id) b.channels.resize(id + 1);
    if (!b.channels[id].empty()) r.fail("channel_id", "channel " + std::to_string(id) + " twice");
    get_section(r, b.channels[id], kChannelFields, voxels, "channel");
  }
  if (r.remaining() != 0) r.fail("end", std::to_string(r.remaining()) + " trailing bytes");
  return b;
}

void zero_if_new(Block& b) {
  if (!b.unzeroed) return;
  b.surface.assign(b.surface.capacity(), 0);
  b.unzeroed = false;
}

// ---- the cache ----

class BlockCache {
 public:
  BlockCache(BlockStore& store, const GridDefinition& def)
      : store_(store), def_(def), voxels_(def.block_edge_voxels * def.block_edge_voxels * def.block_edge_voxels),
        max_block_bytes_(def.block_surface_bytes()) {}

  // The block, pinned; absent blocks are made (create) or nullptr.
  Block* pin(const BlockKey& key, bool create) {
    auto it = blocks_.find(key);
    if (it != blocks_.end()) {
      Block* b = it->second.get();
      lru_.splice(lru_.begin(), lru_, b->lru);
      ++b->pins;
      return b;
    }
    auto bytes = store_.load(key);
    std::unique_ptr<Block> b;
    if (bytes) {
      ++stats_.loads;
      b = std::make_unique<Block>(decode_block(*bytes, def_.block_edge_voxels, key));
    } else {
      if (!create) return nullptr;
      b = std::make_unique<Block>();
      // Only reserved here: the zeros (and the page faults of fresh memory) come in the
      // parallel part of distribute(), by zero_if_new().
      b->surface.reserve(static_cast<size_t>(voxels_) * kSurfaceFields);
      b->unzeroed = true;
    }
    lru_.push_front(key);
    b->lru = lru_.begin();
    b->pins = 1;
    account(static_cast<int64_t>(b->bytes()));
    max_block_bytes_ = std::max(max_block_bytes_, b->bytes());
    return blocks_.emplace(key, std::move(b)).first->second.get();
  }

  void unpin(Block* b) { --b->pins; }

  void ensure_channel(Block* b, int channel) {
    if (static_cast<int>(b->channels.size()) <= channel) b->channels.resize(channel + 1);
    auto& c = b->channels[channel];
    if (!c.empty()) return;
    c.assign(static_cast<size_t>(voxels_) * kChannelFields, 0);
    account(static_cast<int64_t>(c.size() * sizeof(int32_t)));
    max_block_bytes_ = std::max(max_block_bytes_, b->bytes());
  }

  // Evicts unpinned blocks, least recently used first, until `needed` more bytes fit the budget.
  void make_room(size_t needed) {
    auto it = lru_.end();
    while (stats_.resident_bytes + needed > def_.memory_budget_bytes && it != lru_.begin()) {
      --it;
      auto found = blocks_.find(*it);
      Block* b = found->second.get();
      if (b->pins > 0) continue;
      if (b->dirty) {
        zero_if_new(*b);
        store_.store(*it, encode_block(*b, def_.block_edge_voxels));
        ++stats_.stores;
      }
      account(-static_cast<int64_t>(b->bytes()));
      ++stats_.evictions;
      blocks_.erase(found);
      it = lru_.erase(it);
    }
  }

  void flush() {
    for (auto& [key, b] : blocks_) {
      if (!b->dirty) continue;
      zero_if_new(*b);
      store_.store(key, encode_block(*b, def_.block_edge_voxels));
      ++stats_.stores;
      b->dirty = false;
    }
  }

  // Every block with data, sorted: the store's and the resident ones.
  std::vector<BlockKey> keys() {
    std::vector<BlockKey> out = store_.keys();
    for (const auto& [key, b] : blocks_) out.push_back(key);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }

  bool resident(const BlockKey& key) const { return blocks_.count(key) > 0; }

  size_t pinned_bytes() const {
    size_t n = 0;
    for (const auto& [key, b] : blocks_)
      if (b->pins > 0) n += b->bytes();
    return n;
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
  int voxels_;
  size_t max_block_bytes_;
  std::unordered_map<BlockKey, std::unique_ptr<Block>, BlockKeyHash> blocks_;
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

// One block's contributions from one distribute() call, accumulated in floats (fields stored
// field-major, so a row of voxels along x is contiguous) and then rounded once per voxel and
// field into the block's fixed-point sums (commit). A block's splats are always applied together
// by one thread in splat order, so the rounded values depend only on the mesh and the block:
// the integer sums stay independent of mesh order, threads and paging.
class BlockAccumulator {
 public:
  static constexpr int kFields = kSurfaceFields + kChannelFields;

  // Each field's array is padded by kLanes floats: rows are processed in whole groups of kLanes
  // voxels (no scalar remainder loop), the voxels past a row's end getting exact zeros (g = 0).
  static constexpr int kLanes = 8;

  explicit BlockAccumulator(int edge)
      : edge_(edge), voxels_(edge * edge * edge), stride_(static_cast<size_t>(voxels_) + kLanes),
        acc_(static_cast<size_t>(kFields) * stride_, 0.0f), touched_(voxels_, 0) {}

  // Adds one splat's Gaussian over the voxels of block `key` inside its support ellipsoid.
  // Rows run along x: for fixed (y, z) the quadratic form is q(dx) = a_xx dx^2 + 2 qb dx + qc,
  // whose roots bound the row; along the row the Gaussian and the 17 field sums are plain
  // arithmetic over contiguous floats, which the compiler vectorizes.
  // Compiled twice, for AVX2 (8 lanes) and for the baseline, and picked when the program loads;
  // no FMA contraction in either, so both give the same bits.
  __attribute__((target_clones("avx2", "default")))
  size_t splat(const Splat& s, const BlockKey& key, float support2, bool colour) {
    const int B = edge_;
    const int32_t bx = key.x * B, by = key.y * B, bz = key.z * B;
    const int32_t z0 = std::max(s.lo[2], bz), z1 = std::min(s.hi[2], bz + B - 1);
    const int32_t y0 = std::max(s.lo[1], by), y1 = std::min(s.hi[1], by + B - 1);
    const float* a = s.a;
    const float gn[6] = {s.n[0] * s.n[0], s.n[0] * s.n[1], s.n[0] * s.n[2], s.n[1] * s.n[1], s.n[1] * s.n[2], s.n[2] * s.n[2]};
    size_t updates = 0;
    float g[64];
    // Block-local float coordinates: the splat's centre relative to the block's first voxel.
    const float cx = static_cast<float>(s.p[0] - bx), cy = static_cast<float>(s.p[1] - by), cz = static_cast<float>(s.p[2] - bz);
    const int32_t lx_lo = std::max(s.lo[0] - bx, 0), lx_hi = std::min(s.hi[0] - bx, B - 1);
    const float a0 = a[0], inv_a0 = 1.0f / a[0];
    for (int32_t z = z0; z <= z1; ++z) {
      const float dz = static_cast<float>(z - bz) + 0.5f - cz;
      const float qb_z = a[2] * dz, qc_y = 2.0f * a[4] * dz, qc_z = a[5] * dz * dz;
      for (int32_t y = y0; y <= y1; ++y) {
        const float dy = static_cast<float>(y - by) + 0.5f - cy;
        const float qb = a[1] * dy + qb_z;
        const float qc = (a[3] * dy + qc_y) * dy + qc_z;
        const float disc = qb * qb - a0 * (qc - support2);
        if (disc < 0) continue;
        const float root = std::sqrt(disc);
        // The row's voxels lx with centre lx + 0.5 inside the ellipsoid, within the splat's box.
        const float xlo = std::clamp(cx + (-qb - root) * inv_a0 - 0.5f, -1.0f, static_cast<float>(B));
        const float xhi = std::clamp(cx + (-qb + root) * inv_a0 - 0.5f, -1.0f, static_cast<float>(B));
        int32_t lx0 = static_cast<int32_t>(xlo), lx1 = static_cast<int32_t>(xhi);
        lx0 += static_cast<float>(lx0) < xlo;  // ceil
        lx1 -= static_cast<float>(lx1) > xhi;  // floor
        lx0 = std::max(lx0, lx_lo);
        lx1 = std::min(lx1, lx_hi);
        if (lx0 > lx1) continue;
        const int32_t x0 = bx + lx0;
        const int count = lx1 - lx0 + 1;
        const int padded = (count + kLanes - 1) / kLanes * kLanes;
        const float dx0 = static_cast<float>(lx0) + 0.5f - cx;
        const float w = s.w;
#pragma omp simd
        for (int i = 0; i < padded; ++i) {
          const float dx = dx0 + static_cast<float>(i);
          g[i] = w * exp_nonpositive(std::max(-80.0f, -0.5f * (qc + (2.0f * qb + a0 * dx) * dx)));
        }
        for (int i = count; i < padded; ++i) g[i] = 0.0f;
        // A (x - p) at the row's first voxel; it grows by A's first column per step.
        const float adx0 = a[0] * dx0 + a[1] * dy + a[2] * dz;
        const float ady0 = a[1] * dx0 + a[3] * dy + a[4] * dz;
        const float adz0 = a[2] * dx0 + a[4] * dy + a[5] * dz;
        const size_t v0 = static_cast<size_t>(((z - bz) * B + (y - by)) * B + (x0 - bx));
        const size_t V = stride_;
        float* __restrict f = acc_.data() + v0;
        float* __restrict fl = f;
        float* __restrict fgx = f + 1 * V;
        float* __restrict fgy = f + 2 * V;
        float* __restrict fgz = f + 3 * V;
        float* __restrict ft0 = f + 4 * V;
        float* __restrict ft1 = f + 5 * V;
        float* __restrict ft2 = f + 6 * V;
        float* __restrict ft3 = f + 7 * V;
        float* __restrict ft4 = f + 8 * V;
        float* __restrict ft5 = f + 9 * V;
        float* __restrict fn0 = f + 10 * V;
        float* __restrict fn1 = f + 11 * V;
        float* __restrict fn2 = f + 12 * V;
        const float a1 = a[1], a2 = a[2], n0 = s.n[0], n1 = s.n[1], n2 = s.n[2];
#pragma omp simd
        for (int i = 0; i < padded; ++i) {
          const float gi = g[i], fi = static_cast<float>(i);
          fl[i] += gi;
          fgx[i] -= gi * (adx0 + a0 * fi);
          fgy[i] -= gi * (ady0 + a1 * fi);
          fgz[i] -= gi * (adz0 + a2 * fi);
          ft0[i] += gi * gn[0];
          ft1[i] += gi * gn[1];
          ft2[i] += gi * gn[2];
          ft3[i] += gi * gn[3];
          ft4[i] += gi * gn[4];
          ft5[i] += gi * gn[5];
          fn0[i] += gi * n0;
          fn1[i] += gi * n1;
          fn2[i] += gi * n2;
        }
        if (colour) {
          float* __restrict fw = f + 13 * V;
          float* __restrict fr = f + 14 * V;
          float* __restrict fg = f + 15 * V;
          float* __restrict fb = f + 16 * V;
          const float r0 = s.rgb[0], g0 = s.rgb[1], b0 = s.rgb[2];
#pragma omp simd
          for (int i = 0; i < padded; ++i) {
            const float gi = g[i];
            fw[i] += gi;
            fr[i] += gi * r0;
            fg[i] += gi * g0;
            fb[i] += gi * b0;
          }
        }
        std::memset(touched_.data() + v0, 1, static_cast<size_t>(count));
        updates += static_cast<size_t>(count);
      }
    }
    return updates;
  }

  // Rounds the sums into the block (scale kScale, integers added modulo 2^32) and clears them.
  void commit(Block& block, int channel) {
    const size_t V = stride_;
    int32_t* surface = block.surface.data();
    int32_t* colour = channel >= 0 ? block.channels[channel].data() : nullptr;
    const float S = static_cast<float>(kScale);
    for (size_t v = 0; v < static_cast<size_t>(voxels_); ++v) {
      if (!touched_[v]) continue;
      touched_[v] = 0;
      int32_t* out = surface + v * kSurfaceFields;
      for (int k = 0; k < kSurfaceFields; ++k) {
        float& x = acc_[k * V + v];
        add(out[k], static_cast<int32_t>(std::lrint(x * S)));
        x = 0.0f;
      }
      for (int k = 0; k < kChannelFields; ++k) {
        float& x = acc_[(kSurfaceFields + k) * V + v];
        if (colour) add(colour[v * kChannelFields + k], static_cast<int32_t>(std::lrint(x * S)));
        x = 0.0f;
      }
    }
  }

 private:
  int edge_;
  int voxels_;
  size_t stride_;  // floats per field array
  std::vector<float> acc_;
  std::vector<uint8_t> touched_;
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

// Per-thread scratch for one block's extraction.
struct Scratch {
  std::vector<Sample> samples;      // (B+1)^3
  std::vector<int32_t> edge_vertex; // (B+1)^3 * 3, -1 = none
  std::vector<size_t> touched;
};

void extract_block(const BlockKey& key, const std::array<const Block*, 8>& blocks, const GridDefinition& def,
                   const ExtractParams& params, Scratch& scratch, BlockMesh& out) {
  const int B = def.block_edge_voxels, P = B + 1;
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
        if (!b) {
          s = Sample{};
          continue;
        }
        const size_t v = static_cast<size_t>(((lz % B) * B + (ly % B)) * B + (lx % B));
        colours.clear();
        for (const auto& ch : b->channels) colours.push_back(ch.empty() ? nullptr : ch.data() + v * kChannelFields);
        derive(b->surface.data() + v * kSurfaceFields, colours, params.min_likelihood, params.color, s);
      }
  const auto& table = mc::cases();
  const double h = def.voxel_size_m;
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
        Eigen::Vector3d nbar = Eigen::Vector3d::Zero(), grad = Eigen::Vector3d::Zero();
        for (int c = 0; c < 8 && valid; ++c) {
          const int cx = c & 1, cy = (c >> 1) & 1, cz = (c >> 2) & 1;
          const Sample& s = sample(x + cx, y + cy, z + cz);
          valid = s.valid;
          if (s.f > 0) config |= 1 << c;  // inside: behind the ridge
          nbar += Eigen::Vector3d(s.n[0], s.n[1], s.n[2]);
          grad += Eigen::Vector3d(cx ? s.f : -s.f, cy ? s.f : -s.f, cz ? s.f : -s.f);
        }
        if (!valid || config == 0 || config == 255) continue;
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

size_t GridDefinition::block_surface_bytes() const {
  return static_cast<size_t>(block_edge_voxels) * block_edge_voxels * block_edge_voxels * kSurfaceFields *
         sizeof(int32_t);
}
size_t GridDefinition::block_channel_bytes() const {
  return static_cast<size_t>(block_edge_voxels) * block_edge_voxels * block_edge_voxels * kChannelFields *
         sizeof(int32_t);
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

struct OccupancyGrid::Impl {
  Impl(const GridDefinition& d, BlockStore& s) : def(d), store(s), cache(s, def) {}
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
  struct SurfaceSample {
    Eigen::Vector3d p;    // mesh frame
    Eigen::Vector3d n;    // mesh frame
    Eigen::Vector3f rgb;  // [0, 1]
    double area = 0;      // [m^2] of surface the sample stands for
  };
  std::vector<SurfaceSample> samples(vertex_count);
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
  std::vector<Splat> splats(n);
  std::vector<uint8_t> state(n, 0);  // 0 used, 1 oblique, 2 outside, 3 too far, 4 no area
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
  const int B = def.block_edge_voxels;
  std::unordered_map<BlockKey, std::vector<uint32_t>, BlockKeyHash> bins;
  for (size_t i = 0; i < n; ++i) {
    if (state[i] == 1) {
      ++result.skipped_oblique;
      continue;
    }
    if (state[i] == 2) {
      ++result.skipped_outside;
      continue;
    }
    if (state[i] == 4) continue;
    ++result.points;
    const Splat& s = splats[i];
    for (int64_t bz = floor_div(s.lo[2], B); bz <= floor_div(s.hi[2], B); ++bz)
      for (int64_t by = floor_div(s.lo[1], B); by <= floor_div(s.hi[1], B); ++by)
        for (int64_t bx = floor_div(s.lo[0], B); bx <= floor_div(s.hi[0], B); ++bx)
          bins[BlockKey{static_cast<int32_t>(bx), static_cast<int32_t>(by), static_cast<int32_t>(bz)}].push_back(
              static_cast<uint32_t>(i));
  }
  std::vector<BlockKey> keys;
  keys.reserve(bins.size());
  for (const auto& [key, list] : bins) keys.push_back(key);
  std::sort(keys.begin(), keys.end());
  result.blocks_touched = keys.size();
  // Blocks already in the cache first: under a budget smaller than the grid, the previous mesh
  // left the tail of its pass resident, and a plain key-order pass would evict it before use.
  std::stable_partition(keys.begin(), keys.end(), [&](const BlockKey& k) { return impl_->cache.resident(k); });

  // ---- apply, in batches that fit the budget ----
  BlockCache& cache = impl_->cache;
  const float support2 = static_cast<float>(support * support);
  const size_t block_estimate = def.block_surface_bytes() + (channel >= 0 ? def.block_channel_bytes() : 0);
  size_t next = 0;
  std::vector<Block*> batch;
  std::vector<std::unique_ptr<BlockAccumulator>> accumulators(omp_get_max_threads());
  while (next < keys.size()) {
    batch.clear();
    size_t pinned = 0;
    while (next < keys.size()) {
      const size_t estimate = std::max(block_estimate, cache.max_block_bytes());
      if (!batch.empty() && pinned + estimate > def.memory_budget_bytes) break;
      cache.make_room(estimate);
      Block* b = cache.pin(keys[next], true);
      if (channel >= 0) cache.ensure_channel(b, channel);
      b->dirty = true;
      pinned += b->bytes();
      batch.push_back(b);
      ++next;
    }
    const size_t first = next - batch.size();
    size_t updates = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : updates)
    for (size_t j = 0; j < batch.size(); ++j) {
      const BlockKey& key = keys[first + j];
      zero_if_new(*batch[j]);
      auto& acc = accumulators[omp_get_thread_num()];
      if (!acc) acc = std::make_unique<BlockAccumulator>(B);
      for (uint32_t i : bins.at(key)) updates += acc->splat(splats[i], key, support2, channel >= 0);
      acc->commit(*batch[j], channel);
    }
    result.voxel_updates += updates;
    for (Block* b : batch) cache.unpin(b);
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
      size_t missing = 0;
      for (int c = 0; c < 8; ++c) {
        around[c] = BlockKey{key.x + (c & 1), key.y + ((c >> 1) & 1), key.z + ((c >> 2) & 1)};
        missing += present.count(around[c]) && !batch_pins.count(around[c]);
      }
      const size_t estimate = missing * cache.max_block_bytes();
      if (!batch_blocks.empty() && pinned_bytes + estimate > def.memory_budget_bytes) break;
      std::array<const Block*, 8> blocks{};
      for (int c = 0; c < 8; ++c) {
        if (!present.count(around[c])) continue;
        auto it = batch_pins.find(around[c]);
        if (it == batch_pins.end()) {
          cache.make_room(cache.max_block_bytes());
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
