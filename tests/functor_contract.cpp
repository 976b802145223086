// Functors that break the contract of include/raycut/functor.hpp, one per RAYCUT_CONTRACT_CASE:
// tests/CMakeLists.txt compiles each and expects the compiler to refuse it with the message
// named there. Case 0 keeps every rule and must compile (the harness itself works).
#include <cstdint>

#include "raycut/engine.hpp"
#include "raycut/pairs.hpp"

namespace {

using raycut::Shift;
using raycut::Vec3;

#if RAYCUT_CONTRACT_CASE == 0
// Every form at once: a pair call with j and the shift, and each option with its member.
struct Functor {
  using Accumulator = float;
  using options =
      raycut::functor_options<raycut::option::vanishes_at_infinity, raycut::option::init,
                              raycut::option::accepts, raycut::option::combine>;
  Accumulator init(std::uint32_t) const { return 0; }
  bool accepts(std::uint32_t, std::uint32_t, const Shift&) const { return true; }
  static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  void operator()(Accumulator& a, std::uint32_t, std::uint32_t, Vec3, float r2,
                  const Shift&) const {
    a += r2;
  }
  void finish(std::uint32_t, Accumulator&) const {}
};
static_assert(raycut::takes_shift<Functor>::value && raycut::uses_source<Functor>::value);
#elif RAYCUT_CONTRACT_CASE == 1
// A misspelt option names no type.
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::vanishes_at_infinty>;
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 2
// An option flag written as a member (the name-detected form): refused, not ignored.
struct Functor {
  using Accumulator = float;
  static constexpr bool vanishes_at_infinity = true;
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 3
// uses_source = false with a pair call that still takes j: refused (the call without j says it).
struct Functor {
  using Accumulator = float;
  static constexpr bool uses_source = false;
  void operator()(Accumulator&, std::uint32_t, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 4
// option::combine declared, the member misspelt.
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::combine>;
  static void combin(Accumulator& a, const Accumulator& b) { a += b; }
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 5
// A combine() without option::combine would be ignored: refused.
struct Functor {
  using Accumulator = float;
  static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 6
// No Accumulator.
struct Functor {
  void operator()(float&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, float&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 7
// No finish().
struct Functor {
  using Accumulator = float;
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
};
#elif RAYCUT_CONTRACT_CASE == 8
// A pair call of none of the three forms (r2 missing).
struct Functor {
  using Accumulator = float;
  void operator()(Accumulator&, std::uint32_t, std::uint32_t, Vec3) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 9
// Two forms at once: which one runs would depend on the traversal.
struct Functor {
  using Accumulator = float;
  void operator()(Accumulator&, std::uint32_t, std::uint32_t, Vec3, float) const {}
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 10
// accepts(i, j) on a functor with the shifted pair call, which is given accepts(i, j, s).
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::accepts>;
  bool accepts(std::uint32_t, std::uint32_t) const { return true; }
  void operator()(Accumulator&, std::uint32_t, std::uint32_t, Vec3, float, const Shift&) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 11
// Something that is not an option in the list.
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<int>;
  void operator()(Accumulator&, std::uint32_t, Vec3, float) const {}
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 12
// Entries placed by the traversal, without saying which pairs the call writes.
struct Functor {
  using Accumulator = std::uint64_t;
  using options = raycut::functor_options<raycut::option::emits_entries>;
  void operator()(Accumulator& slot, std::uint32_t, std::uint32_t, Vec3, float,
                  const Shift&) const {
    ++slot;
  }
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 13
// option::mirror declared, the member missing.
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::combine, raycut::option::mirror>;
  static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  void operator()(Accumulator& a, std::uint32_t, Vec3, float r2) const { a += r2; }
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 14
// option::mirror on a term that reads j: computed once, it could not be j's term.
struct Functor {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::combine, raycut::option::mirror>;
  static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  static void mirror(Accumulator&) {}
  void operator()(Accumulator& a, std::uint32_t, std::uint32_t j, Vec3, float) const { a += j; }
  void finish(std::uint32_t, Accumulator&) const {}
};
#elif RAYCUT_CONTRACT_CASE == 15
// A mirror member without its option: it would be ignored.
struct Functor {
  using Accumulator = float;
  static void mirror(Accumulator&) {}
  void operator()(Accumulator& a, std::uint32_t, Vec3, float r2) const { a += r2; }
  void finish(std::uint32_t, Accumulator&) const {}
};
#else
#error "unknown RAYCUT_CONTRACT_CASE"
#endif

}  // namespace

void run(const raycut::Engine& engine) {
  raycut::for_each_pair(engine, Functor{});
}
