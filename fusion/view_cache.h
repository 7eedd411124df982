#pragma once
// The views fusion works on, loaded on demand and kept within a memory
// budget, so that fusing thousands of images holds no more maps at once than
// the budget, or than one reference and its sources if they need more.
// Least recently used views are dropped first; a view in use (its
// shared_ptr held outside the cache) is never dropped. A view the loader
// cannot load is remembered as unusable and not tried again.

#include <cstddef>
#include <functional>
#include <list>
#include <memory>
#include <unordered_map>

#include "fusion/point_fusion.h"

namespace dispmvs::fusion {

class FusionViewCache {
 public:
  // nullptr: the view cannot be used (the loader reports why itself).
  using Loader = std::function<std::shared_ptr<const FusionView>(int index)>;

  FusionViewCache(Loader loader, std::size_t max_bytes);

  // The view, loaded if not held; nullptr if it cannot be used.
  std::shared_ptr<const FusionView> Get(int index);

  // Bytes of the maps and image a view holds.
  static std::size_t BytesOf(const FusionView& view);

  std::size_t loads() const { return loads_; }        // calls of the loader
  std::size_t held_bytes() const { return held_bytes_; }
  std::size_t peak_bytes() const { return peak_bytes_; }

 private:
  struct Entry {
    std::shared_ptr<const FusionView> view;
    std::size_t bytes = 0;
    std::list<int>::iterator age;  // position in lru_
  };
  // Drops least recently used views not in use until `incoming` more bytes fit.
  void MakeRoom(std::size_t incoming);

  Loader loader_;
  std::size_t max_bytes_;
  std::unordered_map<int, Entry> held_;
  std::unordered_map<int, bool> unusable_;
  std::list<int> lru_;  // front: most recently used
  std::size_t held_bytes_ = 0, peak_bytes_ = 0, loads_ = 0;
};

}  // namespace dispmvs::fusion
