// The local passes (local_passes.hpp): the engines over owned + halos and the jobs on them.
#include "mpi/local_passes.hpp"

#include <utility>

#include "core/engine_access.hpp"
#include "core/list_functors.hpp"
#include "raycut/detail/row_pass.hpp"

namespace raycut::mpi::detail {
LocalPasses::LocalPasses(const std::string& method, bool owned_rows_only)
    : engine_(std::make_unique<Engine>(method)) {  // an unknown method throws here
  const MethodCapabilities caps = method_capabilities(engine_->method());
  periodic_boxes_ = caps.periodic_boxes;
  split_ = owned_rows_only && caps.periodic_boxes && caps.query_points &&
           engine_->space() == MemorySpace::host;
  if (split_) halo_engine_ = std::make_unique<Engine>(engine_->method());
}

void LocalPasses::build(Residence& residence, std::size_t owned, std::size_t halos, float cutoff,
                        const Box& box, bool same_sources, const Domains& domains, int rank,
                        double reach) {
  owned_ = owned;
  cutoff_ = cutoff;
  const PositionsView local = residence.local_positions(split_ ? owned : owned + halos);
  if (same_sources)  // the owned positions were checked; halos are their images
    raycut::detail::EngineAccess::update_checked(*engine_, local);
  else
    engine_->build(local, cutoff, box);
  // The lists' global shifts (host methods, so a host residence: no copy).
  halo_shifts_ = space() == MemorySpace::host ? residence.halo_shifts().data() : nullptr;
  if (split_) select_boundary(residence.positions(), domains, rank, reach);
  halo_engine_built_ = split_ && !boundary_.empty() && halos > 0;
  if (halo_engine_built_) {  // with query points update() refuses: build again
    Systems systems = Systems::periodic(box);
    systems.queries = {boundary_xyz_.data(), boundary_.size(), MemorySpace::host};
    halo_engine_->build({local.xyz + 3 * owned, halos, MemorySpace::host}, cutoff, systems);
  }
}

// Owned rows only, exactly: the self pair (i, i, 0) must never reach a kernel (Lennard-Jones is
// infinite at r = 0), and a query point does not exclude itself. So the owned particles are
// never sources of the query engine: pairs among owned particles (and their images along local
// axes) come from an engine over them (which excludes (i, i, 0) by index, as a single rank
// does), pairs with halos (and their local images) from the owned particles near a face as
// queries over the halos only. Every pair of an owned target is in exactly one of the two; a
// particle's own images are halos or local images, so (i, i, S != 0) is kept. The row schedule
// takes a boundary row's state from its halo pass into its owned pass, so each row is one sum.
//
// Only owned particles within cutoff + skin of a face that halos cross (Decomposition::halo_axis:
// not a local axis's, nor the outer face of an open end slab) are queries (the others meet no
// halo): a halo lies beyond such a face along an axis at the exchange (local images do not move
// it along the others) and has moved at most skin / 2 since, so an owned particle within the
// cutoff of one is within cutoff + skin / 2 of such a face. The query engine's structure holds
// its queries too (they are candidates it rejects), so fewer queries is most of what makes this
// cheaper than all rows.
void LocalPasses::select_boundary(const std::vector<float>& owned_xyz, const Domains& domains,
                                  int rank, double reach) {
  const Faces faces(domains, rank);
  boundary_.clear();
  boundary_xyz_.clear();
  for (std::size_t i = 0; i < owned_; ++i) {
    if (!faces.near(domains, &owned_xyz[3 * i], reach)) continue;
    boundary_.push_back(static_cast<std::uint32_t>(i));
    boundary_xyz_.insert(boundary_xyz_.end(), &owned_xyz[3 * i], &owned_xyz[3 * i] + 3);
  }
}

// The built-in kernel over the owned rows, in the method's own loop (Method::compute_rows).
Results LocalPasses::visit_kernel(Kernel kernel, const KernelOptions& options) const {
  validate_kernel_range(kernel, options, cutoff_);
  Results r;
  if (owned_ == 0) return r;  // a rank the particles left: no rows (and no output to point at)
  const KernelProduces p = produces(kernel);
  KernelOutputs out;
  if (p.count) out.count = (r.count.assign(owned_, 0), r.count.data());
  if (p.energy) out.energy = (r.energy.assign(owned_, 0.0f), r.energy.data());
  if (p.force) out.force = (r.force.assign(3 * owned_, 0.0f), r.force.data());
  if (p.virial) out.virial = (r.virial.assign(6 * owned_, 0.0f), r.virial.data());
  if (p.density) out.density = (r.density.assign(owned_, 0.0f), r.density.data());
  // The rows' schedule of every job, each pass the method's own loop over mapped rows.
  with_kernel(kernel, options, squared_cutoff(cutoff_), out, [&](const auto& f) {
    raycut::detail::run_local_rows<typename std::decay_t<decltype(f)>::Accumulator>(
        *engine_, halo_engine(), boundary_, split_, static_cast<std::uint32_t>(owned_), nullptr,
        [&](const Engine& engine, const raycut::detail::RowMap& rows) {
          raycut::detail::EngineAccess::compute_rows(engine, kernel, options, rows, out);
        });
  });
  return r;
}

ResultsView LocalPasses::run(Kernel kernel, const KernelOptions& options) {
  if (space() != MemorySpace::host) {  // the method's own pass over all rows
    engine_->run(kernel, options);
    return engine_->results_view();
  }
  results_ = visit_kernel(kernel, options);
  const auto data = [](const auto& v) { return v.empty() ? nullptr : v.data(); };
  return {data(results_.count),  data(results_.energy),  data(results_.force),
          data(results_.virial), data(results_.density), MemorySpace::host};
}

Results LocalPasses::compute(Kernel kernel, const KernelOptions& options) {
  if (space() == MemorySpace::host) return visit_kernel(kernel, options);
  Results r = engine_->compute(kernel, options);  // rows past the owned are the halos'
  const auto keep = [this](auto& v, std::size_t per) {
    if (!v.empty()) v.resize(per * owned_);
  };
  keep(r.count, 1);
  keep(r.energy, 1);
  keep(r.force, 3);
  keep(r.virial, 6);
  keep(r.density, 1);
  return r;
}

LocalList LocalPasses::neighbours(const ListOptions& options,
                                  const std::vector<std::int32_t>& halo_shifts) {
  LocalList out;
  out.offsets.assign(owned_ + 1, 0);
  const auto append = [&](std::uint32_t j, const std::int32_t* s, float distance, const float* r) {
    out.sources.push_back(j);
    out.shifts.insert(out.shifts.end(), s, s + 3);
    if (options.distances) out.distances.push_back(distance);
    if (options.vectors) out.vectors.insert(out.vectors.end(), r, r + 3);
  };
  if (space() == MemorySpace::host) {
    if (owned_ == 0) return out;
    // The engine's own count and fill functors over the row schedule, in the method's own loop
    // (Method::list_rows): a row's cursor carried from a boundary row's halo pass into its owned
    // pass, so a row holds its halo entries, then its owned ones.
    const auto visit = [&](const auto& pass) {
      raycut::detail::run_local_rows<typename std::decay_t<decltype(pass)>::Accumulator>(
          *engine_, halo_engine(), boundary_, split_, static_cast<std::uint32_t>(owned_),
          halo_shifts_, [&](const Engine& engine, const raycut::detail::RowMap& rows) {
            raycut::detail::EngineAccess::list_rows(engine, rows, pass);
          });
    };
    std::vector<std::uint32_t> counts(owned_);
    visit(raycut::detail::ListCount{counts.data()});
    for (std::size_t i = 0; i < owned_; ++i) out.offsets[i + 1] = out.offsets[i] + counts[i];
    const std::uint64_t entries = out.offsets[owned_];
    out.sources.resize(entries);
    out.shifts.resize(3 * entries);
    if (options.distances) out.distances.resize(entries);
    if (options.vectors) out.vectors.resize(3 * entries);
    const auto data = [](auto& v) { return v.empty() ? nullptr : v.data(); };
    raycut::detail::ListFill fill{};
    fill.half = false;  // oriented by global index afterwards
    fill.offsets = out.offsets.data();
    fill.indices = data(out.sources);
    fill.shifts = data(out.shifts);
    fill.distances = data(out.distances);
    fill.vectors = data(out.vectors);
    visit(fill);
    return out;
  }
  // The method's own list over all rows: the owned rows, the halos' shifts added to the
  // engine's (local axes).
  ListOptions local = options;
  local.half = false;   // oriented by global index
  local.shifts = true;  // along the local axes: added to the halo's
  local.coo = false;    // read as CSR
  const NeighbourList list = engine_->neighbours(local);
  for (std::size_t i = 0; i < owned_; ++i) {
    for (std::uint64_t e = list.offsets[i]; e < list.offsets[i + 1]; ++e) {
      const std::uint32_t j = list.indices[e];
      std::int32_t s[3];
      for (int c = 0; c < 3; ++c)
        s[c] = list.shifts[3 * e + c] + (j < owned_ ? 0 : halo_shifts[3 * (j - owned_) + c]);
      append(j, s, options.distances ? list.distances[e] : 0.0f,
             options.vectors ? &list.vectors[3 * e] : nullptr);
    }
    out.offsets[i + 1] = out.sources.size();
  }
  return out;
}

}  // namespace raycut::mpi::detail
