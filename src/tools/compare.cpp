#include "raycut/tools/compare.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <limits>
#include <sstream>
#include <tuple>
#include <vector>

namespace raycut {
namespace {

// One list entry: the source index and, when the list has them, its image shift S.
struct Entry {
  std::uint32_t j = 0;
  std::array<std::int32_t, 3> shift{};
  bool operator<(const Entry& o) const { return std::tie(j, shift) < std::tie(o.j, o.shift); }
  bool operator==(const Entry& o) const { return j == o.j && shift == o.shift; }
};

std::vector<Entry> sorted_row(const NeighbourList& list, std::size_t i, bool with_shifts) {
  std::vector<Entry> row;
  for (std::uint64_t k = list.offsets[i]; k < list.offsets[i + 1]; ++k) {
    Entry e;
    e.j = list.indices[k];
    if (with_shifts)
      for (int c = 0; c < 3; ++c) e.shift[c] = list.shifts[3 * k + c];
    row.push_back(e);
  }
  std::sort(row.begin(), row.end());
  return row;
}

void print(std::ostringstream& s, const Entry& e, bool with_shifts) {
  s << ' ' << e.j;
  if (with_shifts) s << '(' << e.shift[0] << ',' << e.shift[1] << ',' << e.shift[2] << ')';
}

std::string describe(std::size_t i, const std::vector<Entry>& got, const std::vector<Entry>& want,
                     bool with_shifts) {
  std::vector<Entry> missing, extra;
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(),
                      std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
  std::ostringstream s;
  s << "target " << i << ": " << got.size() << " neighbours, expected " << want.size()
    << "; missing";
  for (std::size_t k = 0; k < std::min<std::size_t>(missing.size(), 5); ++k)
    print(s, missing[k], with_shifts);
  s << "; extra or repeated";
  for (std::size_t k = 0; k < std::min<std::size_t>(extra.size(), 5); ++k)
    print(s, extra[k], with_shifts);
  return s.str();
}

}  // namespace

NeighbourComparison compare_neighbours(const NeighbourList& got, const NeighbourList& expected) {
  NeighbourComparison c;
  c.targets = expected.offsets.empty() ? 0 : expected.offsets.size() - 1;
  c.pairs = got.indices.size();
  c.expected_pairs = expected.indices.size();
  if (got.offsets.size() != expected.offsets.size()) {
    c.first_difference = "the list has " + std::to_string(got.offsets.size()) +
                         " offsets, expected " + std::to_string(expected.offsets.size());
    c.differing_targets = c.targets;
    return c;
  }
  // Shifts take part when the expected list has them: then (j, S) is the entry, and a list
  // without them (or with too few) cannot match.
  const bool with_shifts = !expected.shifts.empty();
  if (with_shifts && (expected.shifts.size() != 3 * expected.indices.size() ||
                      got.shifts.size() != 3 * got.indices.size())) {
    c.first_difference =
        "the list has " + std::to_string(got.shifts.size()) + " shift values for " +
        std::to_string(got.indices.size()) +
        " entries, expected 3 per entry (the oracle's: " + std::to_string(expected.shifts.size()) +
        " for " + std::to_string(expected.indices.size()) + ")";
    c.differing_targets = c.targets;
    return c;
  }
  for (std::size_t i = 0; i < c.targets; ++i) {
    const auto g = sorted_row(got, i, with_shifts), w = sorted_row(expected, i, with_shifts);
    if (g != w && c.differing_targets++ == 0) c.first_difference = describe(i, g, w, with_shifts);
  }
  return c;
}

double scaled_difference(double got, double want, double scale) {
  constexpr double failure = std::numeric_limits<double>::infinity();
  if (std::isnan(got) || std::isnan(want)) return failure;
  if (std::isinf(got) || std::isinf(want)) return got == want ? 0.0 : failure;
  const double d = std::fabs(got - want) / scale;
  return std::isnan(d) ? failure : d;  // a NaN or zero scale
}

double max_scaled_difference(const std::vector<float>& got, const std::vector<float>& want,
                             const std::vector<double>& scale, std::size_t stride) {
  if (got.size() != want.size() || scale.size() * stride < want.size())
    return std::numeric_limits<double>::infinity();
  double worst = 0;
  for (std::size_t k = 0; k < want.size(); ++k) {
    const double d =
        got[k] == want[k] ? 0.0 : scaled_difference(got[k], want[k], scale[k / stride]);
    if (!(d <= worst)) worst = d;  // NaN-safe max (d is never NaN here)
  }
  return worst;
}

SmoothReference smooth_reference(const float* xyz, float cutoff, const NeighbourList& list,
                                 const Box& box) {
  constexpr double u = 0x1p-24;
  const std::size_t n = list.offsets.empty() ? 0 : list.offsets.size() - 1;
  const bool with_shifts = !list.shifts.empty();
  const double c = cutoff, c2 = c * c;
  // In a box, the methods' r carries the rounding of image positions at the box's scale.
  double extent = 0;
  for (int k = 0; k < 3; ++k)
    if (box.pbc[k])
      extent += std::fabs(box.cell[k][0]) + std::fabs(box.cell[k][1]) + std::fabs(box.cell[k][2]);
  const double r_error = 4 * std::sqrt(3.0) * u * (extent + c);
  const double energy_term_error = 13 * u * c2 * c2 + 4 * c2 * c * r_error;
  const double force_term_error = 9 * u * c2 * c + 3 * c2 * r_error;
  SmoothReference ref;
  ref.energy.assign(n, 0);
  ref.force.assign(3 * n, 0);
  ref.energy_bound.assign(n, 0);
  ref.force_bound.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    double energy_abs = 0, force_abs[3] = {0, 0, 0};
    for (std::uint64_t p = list.offsets[i]; p < list.offsets[i + 1]; ++p) {
      const std::size_t j = list.indices[p];
      double r[3];
      for (int a = 0; a < 3; ++a) {
        r[a] = static_cast<double>(xyz[3 * j + a]) - static_cast<double>(xyz[3 * i + a]);
        if (with_shifts)
          for (int k = 0; k < 3; ++k) r[a] += list.shifts[3 * p + k] * box.cell[k][a];
      }
      const double w = c2 - (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
      ref.energy[i] += w * w;
      energy_abs += w * w;
      for (int a = 0; a < 3; ++a) {
        ref.force[3 * i + a] += w * r[a];
        force_abs[a] += std::fabs(w * r[a]);
      }
    }
    const double terms = static_cast<double>(list.offsets[i + 1] - list.offsets[i]);
    ref.energy_bound[i] = 2 * ((terms + 1) * u * energy_abs + terms * energy_term_error);
    const double largest_force_abs = std::max({force_abs[0], force_abs[1], force_abs[2]});
    ref.force_bound[i] = 2 * ((terms + 1) * u * largest_force_abs + terms * force_term_error);
  }
  return ref;
}

double smooth_bound_ratio(const Results& got, const SmoothReference& ref) {
  constexpr double failure = std::numeric_limits<double>::infinity();
  const std::size_t n = ref.energy.size();
  if (got.energy.size() != n || got.force.size() != 3 * n) return failure;
  double worst = 0;
  const auto take = [&](double d) {
    if (!(d <= worst)) worst = d;
  };
  for (std::size_t i = 0; i < n; ++i) {
    // A bound of 0 (no terms): any difference fails, none passes.
    const double eb = ref.energy_bound[i] > 0 ? ref.energy_bound[i] : 1e-300;
    const double fb = ref.force_bound[i] > 0 ? ref.force_bound[i] : 1e-300;
    take(scaled_difference(got.energy[i], ref.energy[i], eb));
    for (int a = 0; a < 3; ++a)
      take(scaled_difference(got.force[3 * i + a], ref.force[3 * i + a], fb));
  }
  return worst;
}

}  // namespace raycut
