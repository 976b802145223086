#include "raycut/compare.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <sstream>
#include <vector>

namespace raycut {
namespace {

std::vector<std::uint32_t> sorted_row(const NeighbourList& list, std::size_t i) {
  std::vector<std::uint32_t> row(list.indices.begin() + list.offsets[i],
                                 list.indices.begin() + list.offsets[i + 1]);
  std::sort(row.begin(), row.end());
  return row;
}

std::string describe(std::size_t i, const std::vector<std::uint32_t>& got,
                     const std::vector<std::uint32_t>& want) {
  std::vector<std::uint32_t> missing, extra;
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(),
                      std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
  std::ostringstream s;
  s << "target " << i << ": " << got.size() << " neighbours, expected " << want.size()
    << "; missing";
  for (std::size_t k = 0; k < std::min<std::size_t>(missing.size(), 5); ++k) s << ' ' << missing[k];
  s << "; extra or repeated";
  for (std::size_t k = 0; k < std::min<std::size_t>(extra.size(), 5); ++k) s << ' ' << extra[k];
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
  for (std::size_t i = 0; i < c.targets; ++i) {
    const auto g = sorted_row(got, i), w = sorted_row(expected, i);
    if (g != w && c.differing_targets++ == 0) c.first_difference = describe(i, g, w);
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

}  // namespace raycut
