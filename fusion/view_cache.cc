#include "fusion/view_cache.h"

#include <algorithm>
#include <utility>

namespace dispmvs::fusion {

FusionViewCache::FusionViewCache(Loader loader, std::size_t max_bytes)
    : loader_(std::move(loader)), max_bytes_(max_bytes) {}

std::size_t FusionViewCache::BytesOf(const FusionView& view) {
  const std::size_t floats =
      view.geometry.depth.size() + view.geometry.confidence.size() + view.normals.size();
  return floats * sizeof(float) + view.image.total() * view.image.elemSize();
}

void FusionViewCache::MakeRoom(std::size_t incoming) {
  // Oldest first; views still in use elsewhere stay (the budget may then be
  // exceeded by what one reference and its sources need).
  for (auto it = lru_.end(); it != lru_.begin() && held_bytes_ + incoming > max_bytes_;) {
    --it;
    const auto entry = held_.find(*it);
    if (entry->second.view.use_count() > 1) continue;
    held_bytes_ -= entry->second.bytes;
    held_.erase(entry);
    it = lru_.erase(it);
  }
}

std::shared_ptr<const FusionView> FusionViewCache::Get(int index) {
  const auto found = held_.find(index);
  if (found != held_.end()) {
    lru_.splice(lru_.begin(), lru_, found->second.age);
    return found->second.view;
  }
  if (unusable_.count(index) > 0) return nullptr;
  ++loads_;
  std::shared_ptr<const FusionView> view = loader_(index);
  if (view == nullptr) {
    unusable_[index] = true;
    return nullptr;
  }
  const std::size_t bytes = BytesOf(*view);
  MakeRoom(bytes);
  lru_.push_front(index);
  held_[index] = Entry{view, bytes, lru_.begin()};
  held_bytes_ += bytes;
  peak_bytes_ = std::max(peak_bytes_, held_bytes_);
  return view;
}

}  // namespace dispmvs::fusion
