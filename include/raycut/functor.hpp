// The contract of a pair functor: what every traversal (CPU include/raycut/pairs.hpp, CUDA
// include/raycut/cuda/pairs.cuh, the built-in kernels of include/raycut/kernels.hpp) runs for
// each in-range (target i, source j) pair, checked at compile time with readable messages.
//
//   struct MyFunctor {
//     using Accumulator = ...;  // per-target state, default-constructible
//     // One of three forms of the pair call (r = x_j - x_i, r2 = |r|^2 < C^2):
//     RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r,
//                               float r2) const;                  // reads the source j
//     RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r,
//                               float r2, const Shift& s) const;  // j and the image shift S
//     RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, Vec3 r,
//                               float r2) const;                  // neither j nor S
//     RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const;  // once per target: store
//     // Optional behaviour, each named in `options` (below) and only then looked for:
//     using options = raycut::functor_options<raycut::option::combine, ...>;
//   };
//
// The form without j is what a functor that reads neither j nor S declares (counts, energies of
// r alone): with periodic images the traversal may then run as on an open cloud, no lookup per
// pair, and the functor is never handed a j that is a point's index rather than a particle's.
//
// Options (raycut::option::...), each a type, so that a misspelt option does not compile:
//   vanishes_at_infinity  terms are 0 at r2 = +inf: the traversal may feed out-of-range
//                         candidates that instead of a branch
//   init                  RAYCUT_HD Accumulator init(std::uint32_t i) const;  initial state
//                         (default: Accumulator{})
//   accepts               RAYCUT_HD bool accepts(std::uint32_t i, std::uint32_t j) const;  which
//                         in-range pairs the functor takes (default: all), decided before the
//                         call; with the shifted pair call, accepts(i, j, const Shift& s)
//   combine               RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b);
//                         a += b: lets several GPU lanes share one target (small inputs); then
//                         Accumulator{} must be its identity (lanes start there and init(i) is
//                         combined once) and the Accumulator made of 32-bit words (shuffled
//                         between lanes)
//   emits_entries         the Accumulator is the position of the target's next entry: each call
//                         writes one entry there and adds one. The grid may then give each call
//                         its position itself, so that the lanes sharing a target write its
//                         entries together (coalesced lists); it requires RAYCUT_HD bool
//                         within(i, j, const Shift& s, float r2) const: whether the call writes
//                         the pair (a list with per-pair cutoffs drops some), asked before the
//                         positions are given
//   repeatable            a target's pairs may be visited twice, from init, and only the
//                         second visit finished: operator() writes nothing but the Accumulator
//                         (with emits_entries: the entry it is handed). A periodic GPU grid pass
//                         then decides in float the pairs outside the float band, and visits the
//                         few targets with a candidate in it again in a second launch, in
//                         double: no double arithmetic in its loop, whose registers it would
//                         double (without the option it decides them inline)
//   mirror                RAYCUT_HD static void mirror(Accumulator& a);  turns a pair's term
//                         for its target i (one call from Accumulator{}, with r = x_j - x_i)
//                         into its term for the other particle j (for a force: negated). Then
//                         a CPU traversal with a half stencil (the cell list) computes each
//                         pair once and adds its term to both particles (Newton's third law)
//                         instead of computing it from each side. It requires combine, the
//                         pair call without j (the term is of r alone), and neither init nor
//                         accepts
//
// Why a list of types rather than optional members found by name: C++ cannot tell a misspelt
// member (`vanishes_at_infinty`, `combin`) from one that is not there, so an optional member
// detected by name is silently ignored when misspelt. Here the check runs both ways: an option
// without its member (or with the wrong signature) is an error, a member named like an option
// (`init`, `accepts`, `combine`, the former flags `vanishes_at_infinity`, `emits_entries`,
// `uses_source`, `takes_shift`) without its option is an error, and an option's name misspelt
// names no type.
#pragma once

#include <cstdint>
#include <type_traits>

#include "raycut/predicate.hpp"

namespace raycut {

// The image shift S of a pair (i, j, S): r_ij = x_j - x_i + S . cell (docs/periodic.md,
// "Semantics"); zero without a periodic box. A functor gets it through the shifted pair call
//   operator()(acc, i, j, r, r2, const Shift& s)   and then   accepts(i, j, const Shift& s)
struct Shift {
  std::int32_t a = 0, b = 0, c = 0;
  // Lexicographically positive: the half-list orientation of a self-image (i, i, S).
  RAYCUT_HD bool positive() const { return a != 0 ? a > 0 : (b != 0 ? b > 0 : c > 0); }
};

// The half-list orientation: of (i, j, S) and (j, i, -S), the one with i < j, or i == j and S
// positive, is kept ((i, i, 0) never reaches a functor).
RAYCUT_HD bool half_keeps(std::uint32_t i, std::uint32_t j, const Shift& s) {
  return i < j || (i == j && s.positive());
}

// The optional behaviours a functor opts into (see above).
namespace option {
struct vanishes_at_infinity {};
struct init {};
struct accepts {};
struct combine {};
struct emits_entries {};
struct repeatable {};
struct mirror {};
}  // namespace option

namespace detail {
template <class Option, class... Known>
inline constexpr bool one_of = (std::is_same_v<Option, Known> || ...);
template <class Option>
inline constexpr bool known_option =
    one_of<Option, option::vanishes_at_infinity, option::init, option::accepts, option::combine,
           option::emits_entries, option::repeatable, option::mirror>;
}  // namespace detail

template <class... Options>
struct functor_options {
  static_assert((detail::known_option<Options> && ...),
                "raycut::functor_options: every option must be one of raycut::option::"
                "vanishes_at_infinity, init, accepts, combine, emits_entries, repeatable, "
                "mirror");
  template <class Option>
  static constexpr bool has = detail::one_of<Option, Options...>;
};

namespace detail {

template <class T>
struct is_functor_options : std::false_type {};
template <class... Options>
struct is_functor_options<functor_options<Options...>> : std::true_type {};

// F::options, or none.
template <class F, class = void>
struct options_of {
  using type = functor_options<>;
  static constexpr bool declared = false;
};
template <class F>
struct options_of<F, std::void_t<typename F::options>> {
  using type = typename F::options;
  static constexpr bool declared = true;
};
template <class Options, class Option>
struct options_have : std::false_type {};
template <class... Options, class Option>
struct options_have<functor_options<Options...>, Option>
    : std::bool_constant<one_of<Option, Options...>> {};
template <class Options>
struct options_known : std::false_type {};
template <class... Options>
struct options_known<functor_options<Options...>>
    : std::bool_constant<(known_option<Options> && ...)> {};
template <class F, class Option>
inline constexpr bool opts_into = options_have<typename options_of<F>::type, Option>::value;

template <class F, class = void>
struct has_accumulator : std::false_type {};
template <class F>
struct has_accumulator<F, std::void_t<typename F::Accumulator>> : std::true_type {};

// The three forms of the pair call.
template <class F, class = void>
struct calls_with_source : std::false_type {};
template <class F>
struct calls_with_source<F, std::void_t<decltype(std::declval<const F&>()(
                                std::declval<typename F::Accumulator&>(), std::uint32_t{},
                                std::uint32_t{}, Vec3{}, float{}))>> : std::true_type {};
template <class F, class = void>
struct calls_with_shift : std::false_type {};
template <class F>
struct calls_with_shift<F, std::void_t<decltype(std::declval<const F&>()(
                               std::declval<typename F::Accumulator&>(), std::uint32_t{},
                               std::uint32_t{}, Vec3{}, float{}, std::declval<const Shift&>()))>>
    : std::true_type {};
template <class F, class = void>
struct calls_without_source : std::false_type {};
template <class F>
struct calls_without_source<
    F, std::void_t<decltype(std::declval<const F&>()(std::declval<typename F::Accumulator&>(),
                                                     std::uint32_t{}, Vec3{}, float{}))>>
    : std::true_type {};

template <class F, class = void>
struct has_finish : std::false_type {};
template <class F>
struct has_finish<F, std::void_t<decltype(std::declval<const F&>().finish(
                         std::uint32_t{}, std::declval<typename F::Accumulator&>()))>>
    : std::true_type {};

// The members an option stands for, with their signatures.
template <class F, class = void>
struct init_member : std::false_type {};
template <class F>
struct init_member<F, std::void_t<decltype(std::declval<const F&>().init(std::uint32_t{}))>>
    : std::is_convertible<decltype(std::declval<const F&>().init(std::uint32_t{})),
                          typename F::Accumulator> {};
// within(i, j, s, r2): whether an entry-emitting functor writes the pair it is handed.
template <class F, class = void>
struct within_member : std::false_type {};
template <class F>
struct within_member<F, std::void_t<decltype(std::declval<const F&>().within(
                            std::uint32_t{}, std::uint32_t{}, Shift{}, 0.0f))>>
    : std::is_convertible<decltype(std::declval<const F&>().within(std::uint32_t{}, std::uint32_t{},
                                                                   Shift{}, 0.0f)),
                          bool> {};
template <class F, class = void>
struct combine_member : std::false_type {};
template <class F>
struct combine_member<
    F, std::void_t<decltype(F::combine(std::declval<typename F::Accumulator&>(),
                                       std::declval<const typename F::Accumulator&>()))>>
    : std::true_type {};
template <class F, class = void>
struct mirror_member : std::false_type {};
template <class F>
struct mirror_member<F, std::void_t<decltype(F::mirror(std::declval<typename F::Accumulator&>()))>>
    : std::true_type {};
// accepts(i, j), or accepts(i, j, s) for a functor with the shifted pair call. Two plain
// detections and a choice: nvcc's front end took any shifted functor for one with accepts when
// the shift's detection sat inside enable_if_t.
template <class F, class = void>
struct accepts_of_pair : std::false_type {};
template <class F>
struct accepts_of_pair<
    F, std::void_t<decltype(std::declval<const F&>().accepts(std::uint32_t{}, std::uint32_t{}))>>
    : std::true_type {};
template <class F, class = void>
struct accepts_of_shifted_pair : std::false_type {};
template <class F>
struct accepts_of_shifted_pair<F, std::void_t<decltype(std::declval<const F&>().accepts(
                                      std::uint32_t{}, std::uint32_t{}, Shift{}))>>
    : std::true_type {};

// Members named like an option, whatever their signature (non-overloaded names: enough to catch
// a functor written for the name-detected options).
#define RAYCUT_DETAIL_NAMED_MEMBER(name)    \
  template <class F, class = void>          \
  struct names_##name : std::false_type {}; \
  template <class F>                        \
  struct names_##name<F, std::void_t<decltype(&F::name)>> : std::true_type {};
RAYCUT_DETAIL_NAMED_MEMBER(init)
RAYCUT_DETAIL_NAMED_MEMBER(accepts)
RAYCUT_DETAIL_NAMED_MEMBER(combine)
RAYCUT_DETAIL_NAMED_MEMBER(mirror)
RAYCUT_DETAIL_NAMED_MEMBER(vanishes_at_infinity)
RAYCUT_DETAIL_NAMED_MEMBER(emits_entries)
RAYCUT_DETAIL_NAMED_MEMBER(uses_source)
RAYCUT_DETAIL_NAMED_MEMBER(takes_shift)
#undef RAYCUT_DETAIL_NAMED_MEMBER

}  // namespace detail

// ---- what the traversals ask of a functor --------------------------------------------------

// Reads j (or S): the two pair calls with j.
template <class F>
struct uses_source : std::bool_constant<!detail::calls_without_source<F>::value> {};
// Gets the image shift S.
template <class F>
struct takes_shift : detail::calls_with_shift<F> {};
template <class F>
struct vanishes_at_infinity
    : std::bool_constant<detail::opts_into<F, option::vanishes_at_infinity>> {};
template <class F>
struct has_combine : std::bool_constant<detail::opts_into<F, option::combine>> {};
template <class F>
struct has_init : std::bool_constant<detail::opts_into<F, option::init>> {};
template <class F>
struct has_accepts : std::bool_constant<detail::opts_into<F, option::accepts>> {};
template <class F>
struct emits_entries : std::bool_constant<detail::opts_into<F, option::emits_entries>> {};
template <class F>
struct repeatable : std::bool_constant<detail::opts_into<F, option::repeatable>> {};
template <class F>
struct has_mirror : std::bool_constant<detail::opts_into<F, option::mirror>> {};

namespace detail {

// The contract, one readable message per broken rule; true when F keeps it. The traversals'
// entry points assert it (static_assert(raycut::detail::check_functor<F>())).
template <class F>
constexpr bool check_functor() {
  static_assert(has_accumulator<F>::value,
                "raycut functor: declare the per-target state, `using Accumulator = ...;`");
  if constexpr (has_accumulator<F>::value) {
    using A = typename F::Accumulator;
    static_assert(std::is_default_constructible_v<A>,
                  "raycut functor: the Accumulator must be default-constructible");
    constexpr int forms = int{calls_with_source<F>::value} + int{calls_with_shift<F>::value} +
                          int{calls_without_source<F>::value};
    static_assert(forms != 0,
                  "raycut functor: no pair call found; declare one const operator() of "
                  "(Accumulator&, uint32_t i, uint32_t j, Vec3 r, float r2), or the same with a "
                  "last `const raycut::Shift&`, or (Accumulator&, uint32_t i, Vec3 r, float r2) "
                  "when it reads neither j nor the shift");
    static_assert(forms <= 1,
                  "raycut functor: operator() accepts more than one of the pair calls (with j, "
                  "with j and a Shift, without j); declare exactly one");
    static_assert(has_finish<F>::value,
                  "raycut functor: declare `void finish(uint32_t i, Accumulator& acc) const` "
                  "(called once per target)");
    static_assert(is_functor_options<typename options_of<F>::type>::value,
                  "raycut functor: `options` must be raycut::functor_options<raycut::option::...>");
    static_assert(!is_functor_options<typename options_of<F>::type>::value ||
                      options_known<typename options_of<F>::type>::value,
                  "raycut functor: every option must be one of raycut::option::"
                  "vanishes_at_infinity, init, accepts, combine, emits_entries, repeatable, "
                  "mirror");
    static_assert(!names_vanishes_at_infinity<F>::value && !names_emits_entries<F>::value,
                  "raycut functor: vanishes_at_infinity and emits_entries are not members; name "
                  "them in `using options = raycut::functor_options<raycut::option::...>`");
    static_assert(!names_uses_source<F>::value,
                  "raycut functor: uses_source is not a member; a functor that reads neither j "
                  "nor the shift declares operator()(Accumulator&, uint32_t i, Vec3 r, float r2)");
    static_assert(!names_takes_shift<F>::value,
                  "raycut functor: takes_shift is not a member; a functor that reads the shift "
                  "declares operator()(Accumulator&, uint32_t i, uint32_t j, Vec3 r, float r2, "
                  "const raycut::Shift& s)");
    static_assert(!opts_into<F, option::init> || init_member<F>::value,
                  "raycut functor: option::init is declared but no `Accumulator init(uint32_t i) "
                  "const` is found");
    static_assert(opts_into<F, option::init> || !names_init<F>::value,
                  "raycut functor: a member init is declared without option::init in `options` "
                  "(it would be ignored)");
    static_assert(!opts_into<F, option::combine> || combine_member<F>::value,
                  "raycut functor: option::combine is declared but no `static void "
                  "combine(Accumulator& a, const Accumulator& b)` is found");
    static_assert(opts_into<F, option::combine> || !names_combine<F>::value,
                  "raycut functor: a member combine is declared without option::combine in "
                  "`options` (it would be ignored)");
    static_assert(!opts_into<F, option::accepts> ||
                      (calls_with_shift<F>::value ? accepts_of_shifted_pair<F>::value
                                                  : accepts_of_pair<F>::value),
                  "raycut functor: option::accepts is declared but no `bool accepts(uint32_t i, "
                  "uint32_t j) const` is found (accepts(i, j, const raycut::Shift& s) with the "
                  "shifted pair call)");
    static_assert(opts_into<F, option::accepts> || !names_accepts<F>::value,
                  "raycut functor: a member accepts is declared without option::accepts in "
                  "`options` (it would be ignored)");
    static_assert(!opts_into<F, option::emits_entries> || within_member<F>::value,
                  "raycut functor: option::emits_entries is declared but no `bool within(uint32_t "
                  "i, uint32_t j, const raycut::Shift& s, float r2) const` is found (whether the "
                  "call writes the pair: the grid places entries before the calls)");
    static_assert(!opts_into<F, option::mirror> || mirror_member<F>::value,
                  "raycut functor: option::mirror is declared but no `static void "
                  "mirror(Accumulator& a)` is found");
    static_assert(opts_into<F, option::mirror> || !names_mirror<F>::value,
                  "raycut functor: a member mirror is declared without option::mirror in "
                  "`options` (it would be ignored)");
    static_assert(!opts_into<F, option::mirror> ||
                      (opts_into<F, option::combine> && calls_without_source<F>::value &&
                       !opts_into<F, option::init> && !opts_into<F, option::accepts>),
                  "raycut functor: option::mirror needs option::combine and the pair call "
                  "without j (a term of r alone), and neither init nor accepts: the pair's term "
                  "is computed once, from Accumulator{}, and added to both particles");
  }
  return true;
}

}  // namespace detail

// Whether f takes the in-range pair (i, j, s).
template <class F>
RAYCUT_HD bool accepts(const F& f, std::uint32_t i, std::uint32_t j, const Shift& s = {}) {
  if constexpr (!has_accepts<F>::value)
    return true;
  else if constexpr (takes_shift<F>::value)
    return f.accepts(i, j, s);
  else
    return f.accepts(i, j);
}

// f's call for the in-range pair (i, j, s), in the form f declares.
template <class F>
RAYCUT_HD void apply(const F& f, typename F::Accumulator& acc, std::uint32_t i, std::uint32_t j,
                     Vec3 r, float r2, const Shift& s = {}) {
  if constexpr (takes_shift<F>::value) {
    f(acc, i, j, r, r2, s);
  } else if constexpr (uses_source<F>::value) {
    f(acc, i, j, r, r2);
  } else {
    (void)j;
    f(acc, i, r, r2);
  }
}

// The initial state of target i.
template <class F>
RAYCUT_HD typename F::Accumulator initial_state(const F& f, std::uint32_t i) {
  if constexpr (has_init<F>::value)
    return f.init(i);
  else
    return typename F::Accumulator{};
}

}  // namespace raycut
