// The decomposition's part of the distributed engine (Decomposition, raycut/mpi/distributed.hpp):
// its geometry from the box, the cuts (equal slabs, or the particle-count quantiles of
// Balance::particles), and its arithmetic as plain data (domains.hpp) for the exchange. Nothing
// here moves particles; balance_cuts() is the only collective.
#pragma once

#include <mpi.h>

#include <array>
#include <cstdint>
#include <vector>

#include "mpi/domains.hpp"
#include "raycut/box.hpp"
#include "raycut/mpi/distributed.hpp"

namespace raycut::mpi::detail {

// The box's part of the decomposition: periodic axes, normals, periods, rows, orthogonal and
// aligned. Validates the box first (Error(invalid_argument) from validate()).
void set_geometry(Decomposition& dec, const Box& box);

// Decomposition's arithmetic as plain data, over its cuts in place (valid while they are).
Domains domains_of(const Decomposition& dec);

// Halo candidates a little beyond the halo width: extra halos are harmless (they are sources
// only), missing ones are not, and the slab and distance tests round in double at the scale of
// the coordinates.
double halo_reach(const Decomposition& dec, double halo_width);

// Equal slabs along every axis: the regions of periodic axes and of open axes with a cell row;
// an open axis without one spans the particles' extent `bounds` (min u per axis, then -max u per
// axis, over every rank; `any_particles` false: an empty region). Error(invalid_argument) naming
// the axis when a slab along an axis that halos cross is thinner than `halo_width`.
void set_equal_cuts(Decomposition& dec, const std::array<double, 6>& bounds, bool any_particles,
                    double halo_width);

// Balance::particles (docs/distributed.md): the inner cuts of each split axis at the quantiles of
// the particle count along it over all ranks' owned positions `xyz` (3 floats each), each slab
// kept at least `halo_width` wide. Collective over `comm`; every rank gets the same cuts. False
// (nothing moved) when there is nothing to balance: no particles or one domain.
bool balance_cuts(Decomposition& dec, MPI_Comm comm, const std::vector<float>& xyz,
                  std::uint64_t global_size, double halo_width);

}  // namespace raycut::mpi::detail
