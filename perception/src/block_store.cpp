#include "artisan/perception/block_store.hpp"

namespace artisan {

std::optional<std::vector<uint8_t>> InMemoryBlockStore::load(const BlockKey& key) {
  const auto it = blocks_.find(key);
  if (it == blocks_.end()) return std::nullopt;
  return it->second;
}

void InMemoryBlockStore::store(const BlockKey& key, const std::vector<uint8_t>& bytes) {
  auto& slot = blocks_[key];
  bytes_ = bytes_ - slot.size() + bytes.size();
  slot = bytes;
}

std::vector<BlockKey> InMemoryBlockStore::keys() {
  std::vector<BlockKey> out;
  out.reserve(blocks_.size());
  for (const auto& [key, bytes] : blocks_) out.push_back(key);
  return out;
}

}  // namespace artisan
