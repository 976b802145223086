// The local passes of the distributed engine: the single-rank engines over a rank's owned
// particles and halos, and every job on them (kernels, neighbour lists, sph_force, the caller's
// functors) as rows of the owned targets. A host method runs every job on one row schedule
// (raycut/detail/row_pass.hpp): one engine of owned + halos, or with owned rows only two (the
// owned particles; the boundary rows as queries over the halos), each owned row's pairs visited
// through both and finished once, so nothing is merged after. The built-in kernels and the lists
// run it in the method's own loop (Method::compute_rows, Method::list_rows: the engine's own list
// functors), a caller's functors through LocalPass (raycut/mpi/pairs.hpp). A GPU method
// has one engine over owned + halos, all rows, and its own passes (the rows past the owned ones
// are the halos', not read).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mpi/domains.hpp"
#include "mpi/residence.hpp"
#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"

namespace raycut::mpi::detail {

// The owned rows of a neighbour list, with local sources (owned below the owned count, then the
// halos) and global shifts (the halo's plus the local engine's), as the passes found them.
struct LocalList {
  std::vector<std::uint64_t> offsets;  // owned + 1
  std::vector<std::uint32_t> sources;
  std::vector<std::int32_t> shifts;  // 3 per entry
  std::vector<float> distances;      // when asked
  std::vector<float> vectors;        // when asked, 3 per entry
};

class LocalPasses {
 public:
  // The engines of `method` (its errors: an unknown or unavailable one). Owned rows only when
  // asked and the method declares periodic boxes and query points (method_capabilities) and
  // works on the host; a GPU method runs all rows (a second build there costs more than the
  // rows it saves).
  LocalPasses(const std::string& method, bool owned_rows_only);

  const Engine& engine() const { return *engine_; }
  const Engine* halo_engine() const { return halo_engine_built_ ? halo_engine_.get() : nullptr; }
  const std::vector<std::uint32_t>& boundary() const { return boundary_; }
  bool owned_rows_only() const { return split_; }
  // The method takes periodic boxes: the local engines image the local axes themselves.
  bool periodic_boxes() const { return periodic_boxes_; }
  MemorySpace space() const { return engine_->space(); }

  // Builds the engines over the residence's owned particles and `halos` halos, in the local box
  // (periodic on the local axes only). `same_sources`: the same particles as the last build,
  // moved (a refresh: the engine updates). Owned rows only: the owned particles within `reach`
  // of a face that halos cross (`domains`, this `rank`'s domain) are the boundary rows.
  void build(Residence& residence, std::size_t owned, std::size_t halos, float cutoff,
             const Box& box, bool same_sources, const Domains& domains, int rank, double reach);

  // The kernel for the owned rows: left where the method keeps them, valid until the next call
  // (rows 0 .. owned - 1), or as host Results of the owned rows.
  ResultsView run(Kernel kernel, const KernelOptions& options);
  Results compute(Kernel kernel, const KernelOptions& options);
  // The owned rows' full neighbour lists (options: distances, vectors; half and coo ignored).
  LocalList neighbours(const ListOptions& options, const std::vector<std::int32_t>& halo_shifts);

 private:
  Results visit_kernel(Kernel kernel, const KernelOptions& options) const;
  void select_boundary(const std::vector<float>& owned_xyz, const Domains& domains, int rank,
                       double reach);

  std::unique_ptr<Engine> engine_, halo_engine_;
  bool periodic_boxes_ = false;
  bool split_ = false;
  bool halo_engine_built_ = false;
  std::size_t owned_ = 0;
  float cutoff_ = 0;
  const std::int32_t* halo_shifts_ = nullptr;  // host methods: the residence's, since build()
  std::vector<std::uint32_t> boundary_;        // owned indices, ascending
  std::vector<float> boundary_xyz_;
  Results results_;  // run()'s, of a host method
};

}  // namespace raycut::mpi::detail
