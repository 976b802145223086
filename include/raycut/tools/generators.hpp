// Deterministic, seeded inputs: the two benchmark suites of docs/benchmarks.md and the test
// families of docs/methods.md. The same (name, n, cutoff, seed) gives the same bits on every
// platform (own RNG, no std:: distributions).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "raycut/box.hpp"

namespace raycut {

struct PointCloud {
  std::string name;        // family or suite label, e.g. "uniform" or "surface alpha=64 p=8"
  std::vector<float> xyz;  // (N,3) row-major
  float cutoff = 0;        // the cutoff the input is meant for
  Box box;                 // periodic box (an extended XYZ file's Lattice and pbc); open if none
  std::size_t size() const { return xyz.size() / 3; }
};

// The suites draw each point from its own counter-based stream (hash of seed and index), so the
// result does not depend on the number of threads that generate it. Both throw
// Error(invalid_argument) for a parameter or p below 1.
//
// Uniform suite (paper 5.2): N = p * beta^3 uniform in [0,1)^3, cutoff 1/beta.
PointCloud uniform_suite(int beta, int p, std::uint64_t seed = 1);
// Surface suite (paper 5.3, Code 2): N = p * alpha^3 uniform on the unit sphere centred at
// (1,1,1), cutoff acos(clamp(1 - 2*9p/N, -1, 1)) (about 9p neighbours each).
PointCloud surface_suite(int alpha, int p, std::uint64_t seed = 1);
// Particle count of a suite configuration, without generating it.
std::size_t suite_size(int param, int p);

// The test families (docs/methods.md, "Test inputs"), by name, in a stable order.
std::vector<std::string> family_names();
// About n points of family `name` for cutoff `cutoff` (C below); name = the family name, cutoff =
// C. Exactly n points except for lattices, which have m^3 points, m = max(1, round(cbrt(n)))
// (so n = 2 gives 1 point); n = 0 always gives an empty cloud. Random families aim at 10-40
// in-range neighbours per point; lattices have what their spacing gives (k1: none, all at or
// beyond C; k2: 26; k3: 92; k4: 250 for an interior point). The families:
//   uniform             uniform in a cube of side max(C, C cbrt(n (4/3) pi / 25)): ~25 neighbours.
//   sphere-surface      uniform on a sphere of radius max(C, C sqrt(n / 80)): ~20 neighbours.
//   lattice-kK          simple cubic, spacing s = C/K in float, coordinates float(i) * s
//                       (K = 1..4); with C a power of two, pairs lie exactly at the cutoff.
//   lattice-shifted-kK  the same plus s/2 on every coordinate.
//   coincident          uniform sites (density as uniform), each repeated 1..6 times exactly.
//   near-coincident     n/2 pairs at distance C 10^(-7+4u) in a random direction (one ulp
//                       apart where float cannot hold the offset); odd n adds a lone point.
//   axis-aligned        lines of 24 points along x, y, z in bundles of 4 lines within C of each
//                       other, spacing ~C/3 (every 4th bundle ~C/2, exactly C/2 when C is a
//                       power of two); coordinates exact multiples of a power of two ~C/4096.
//   diagonal            stars: a centre and 16 points on each of the 4 body diagonals, 3D
//                       spacing ~C/4, |dx| = |dy| = |dz| exactly along a diagonal.
//   gaussian-outlier    3 Gaussian clusters of n - 1 points in all (sigma = 2C at 1000 points
//                       per cluster, scaled by cbrt of the cluster size so the density does
//                       not depend on n) and, last, one point 1e5 C away on a diagonal.
//   offset-1e3/-1e5     the uniform cloud (same seed) plus 1e3 / 1e5 on every coordinate.
//   large-cutoff        uniform in a cube of side C/4: every pair is in range.
// Extreme scales (docs/limits.md), all exactly n points:
//   tiny-scale          the uniform cloud times 2^-50 (~8.9e-16), and the cloud's cutoff too
//                       (PointCloud::cutoff = C 2^-50): exactly uniform's pairs, tiny numbers.
//   huge-scale          the same times 2^50 (~1.1e15). With C = 1 both lie well inside the
//                       supported cutoffs [2^-60, 2^60]; C = 2^-10 / 2^10 puts them at its edges.
//   offset-1e7/-1e15    uniform points + 1e7 / 1e15 on every coordinate, rounded to float once;
//                       the cube is widened to cbrt(n/4) float spacings where that is wider, so
//                       ~4 points at most share a float site. There the float spacing (1 at 1e7,
//                       2^26 at 1e15) reaches or exceeds C: most pairs are coincident or exactly
//                       one spacing apart (at the cutoff when C = 1).
//   cauchy              multivariate Cauchy around the origin (~25 neighbours at the centre): a
//                       heavy tail, the farthest points ~n cube-sides away.
//   groups-far          a uniform cube at the origin (n - 3 floor(n/4) points) and three square
//                       sheets of floor(n/4) points (~20 neighbours) at x = 1e10 C, y = 1e20 C,
//                       z = 1e30 C (capped at 1e36), each exactly flat along its far axis.
//   sheet-flat          a square sheet, ~20 neighbours, z = 0 exactly.
//   sheet-thin          the same with z uniform in [0, 1e-6 C).
//   rod-1e6             uniform in a box C x C x 10^6 C (few neighbours; a 10^6-cell grid).
// Throws Error(invalid_argument) for an unknown name (naming the known ones) and for a cutoff
// that is not finite and > 0.
PointCloud make_family(std::string_view name, std::size_t n, float cutoff, std::uint64_t seed);

}  // namespace raycut
