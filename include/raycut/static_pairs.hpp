// A pair list of static capacity: what the stream-ordered calls write (docs/streams.md), in the
// memory where the pass works, with the true count beside the pairs so that nothing has to be
// read back before the next operation is queued.
#pragma once

#include <cstddef>
#include <cstdint>

namespace raycut {

// Where a pass writes its pairs: `capacity` entries of i, j (int64) and S (3 int32, or null),
// and the true count (one int64), all in the pass's memory (device memory for the GPU paths,
// host memory for an Engine on a CPU method). Entries [count, capacity) are padding:
// i = j = pad_index, S = 0. The pairs are valid iff 0 <= count <= capacity; a count above the
// capacity says how many there are (the first `capacity` in the fixed order are written). A
// negative count is bad input, named by read_pair_count: one of the codes below.
struct StaticPairs {
  std::int64_t* i = nullptr;
  std::int64_t* j = nullptr;
  std::int32_t* shifts = nullptr;
  std::int64_t* count = nullptr;
  std::size_t capacity = 0;
  std::int64_t pad_index = 0;
  // 0: one list, as above. B > 0 (the small-system pass only): a list per system of a batch,
  // system s in entries [s * capacity, (s + 1) * capacity) with its own count, count[s] (B
  // counts), and its own padding; indices stay global. What jax.vmap maps onto: every system's
  // count exact, whatever the others hold.
  std::size_t systems = 0;
};

// What a negative count says (the small-system pass, which checks its data on the device).
inline constexpr std::int64_t count_non_finite_position = -1;
inline constexpr std::int64_t count_unsorted_batch = -2;
inline constexpr std::int64_t count_invalid_cell = -3;  // non-finite, or periodic rows dependent
inline constexpr std::int64_t count_batch_out_of_range = -4;  // a system without its cell/pbc
// A cell so much thinner than the cutoff that a pair has more than max_images_per_pair images
// (the brute force over them would run for hours; the Engine's cell lists take such boxes).
inline constexpr std::int64_t count_too_many_images = -5;
inline constexpr double max_images_per_pair = 16777216.0;  // 2^24
// An engine that reuses its previous build's plan (Engine::set_reuse_plan) found on the device
// that it no longer fits these positions (more periodic images than planned, a point outside the
// planned grid, a wider float band, or a bad coordinate): the pairs are not valid. Once this
// count has been read, the next build of the same engine plans afresh (and names any bad input).
inline constexpr std::int64_t count_plan_outgrown = -6;

}  // namespace raycut
