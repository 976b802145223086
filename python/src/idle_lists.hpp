// Host list buffers that no output uses any more, kept for the next list (pyraycut's NumPy
// arrays and the PyTorch operators' CPU tensors wrap list memory without a copy). Each call fills
// a buffer of its own (the outputs of earlier calls stay valid), and a fresh one pays a page fault
// on every page it writes: a third of a CPU list call at 10,000 particles (perf: the kernel
// zeroing pages). A loop that drops each call's outputs after the next call alternates two
// buffers, so two are kept (the newest), while they hold at most kept_bytes together; larger
// lists are freed.
// One instance per extension module (idle_lists()).
#pragma once

#include <cstddef>
#include <memory>
#include <mutex>
#include <vector>

#include "raycut/engine.hpp"

namespace raycut_py {

class IdleLists {
 public:
  static constexpr std::size_t kept = 2, kept_bytes = std::size_t{256} << 20;

  // A buffer that comes back here when the last owner of it (an output) lets go.
  std::shared_ptr<raycut::NeighbourListBuffer> take() {
    std::unique_ptr<raycut::NeighbourListBuffer> list;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!idle_.empty()) {
        list = std::move(idle_.back());
        idle_.pop_back();
      }
    }
    if (!list) list = std::make_unique<raycut::NeighbourListBuffer>();
    return {list.release(), [this](raycut::NeighbourListBuffer* done) { give_back(done); }};
  }

  void clear() {
    std::vector<std::unique_ptr<raycut::NeighbourListBuffer>> freed;
    std::lock_guard<std::mutex> lock(mutex_);
    freed.swap(idle_);
  }

 private:
  // The newest is kept, the oldest make room (a loop whose sizes change keeps what it uses).
  void give_back(raycut::NeighbourListBuffer* done) {
    std::unique_ptr<raycut::NeighbourListBuffer> list(done);
    // Unfilled (a failed call), too large, or device memory (pooled already): freed.
    if (list->bytes() == 0 || list->bytes() > kept_bytes ||
        list->space() != raycut::MemorySpace::host)
      return;
    std::vector<std::unique_ptr<raycut::NeighbourListBuffer>> evicted;  // freed after unlocking
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(std::move(list));
    std::size_t held = 0;
    for (const auto& l : idle_) held += l->bytes();
    while (idle_.size() > kept || held > kept_bytes) {
      held -= idle_.front()->bytes();
      evicted.push_back(std::move(idle_.front()));
      idle_.erase(idle_.begin());
    }
  }

  std::mutex mutex_;
  std::vector<std::unique_ptr<raycut::NeighbourListBuffer>> idle_;
};

// Process-wide and never destroyed: outputs may outlive the module's teardown.
inline IdleLists& idle_lists() {
  static auto* lists = new IdleLists;
  return *lists;
}

}  // namespace raycut_py
