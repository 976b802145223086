// The distributed engine's facade (raycut/mpi/distributed.hpp): options and collective checks,
// then the parts in their order. decomposition.hpp places the domains, exchange.hpp moves
// particles and halos between ranks, residence.hpp keeps them on the host or the GPU (chosen at
// build()), local_passes.hpp runs every job over the local engines (docs/distributed.md).
#include "raycut/mpi/distributed.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "mpi/decomposition.hpp"
#include "mpi/exchange.hpp"
#include "mpi/local_passes.hpp"
#include "mpi/mpi_check.hpp"
#include "mpi/residence.hpp"

namespace raycut::mpi {
namespace {

using Clock = std::chrono::steady_clock;

double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

std::string dims_text(const std::array<int, 3>& d) {
  return "[" + std::to_string(d[0]) + " " + std::to_string(d[1]) + " " + std::to_string(d[2]) + "]";
}

// A kernel that reads per-particle inputs needs its neighbours' values on the halos: only
// sph_force's fields are exchanged (SphFields), the other kernels' are refused.
void refuse_inputs_without_fields(Kernel kernel) {
  if (kernel == Kernel::sph_force)
    throw Error(ErrorCode::unsupported,
                "distributed engine: sph_force needs its neighbours' velocities, densities and "
                "pressures: call compute(Kernel::sph_force, options, SphFields{...}) with the "
                "owned particles' fields");
  visit_kernel(kernel, [&](auto spec) {
    if (!decltype(spec)::inputs.empty())
      throw Error(ErrorCode::unsupported,
                  "distributed engine: kernel " + to_string(kernel) +
                      " reads per-particle inputs of its neighbours, which the distributed "
                      "engine does not exchange; run it on a raycut::Engine");
  });
}

// [id][image xyz][shift] of a new halo, [xyz] of a refreshed one.
constexpr std::size_t halo_record =
    sizeof(std::uint64_t) + 3 * sizeof(float) + 3 * sizeof(std::int32_t);
constexpr std::size_t refresh_record = 3 * sizeof(float);

// What the accessors give before build(): nothing.
const std::vector<float> no_floats;
const std::vector<std::uint64_t> no_ids;
const std::vector<std::int32_t> no_shifts;

// The options every rank must share (a rank with other dims or another skin decomposes, or
// exchanges, differently: wrong answers or a hang, as adversarial tests found), as numbers
// that must be the same on every rank.
std::vector<std::uint64_t> shared_options(const DistributedOptions& o) {
  std::uint64_t method = 14695981039346656037ull;  // FNV-1a of the method's name
  for (unsigned char c : o.method) method = (method ^ c) * 1099511628211ull;
  std::uint32_t skin_bits = 0;
  std::memcpy(&skin_bits, &o.skin, sizeof skin_bits);
  const auto as_bits = [](int v) {
    return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v));
  };
  return {method,
          skin_bits,
          as_bits(o.dims[0]),
          as_bits(o.dims[1]),
          as_bits(o.dims[2]),
          o.owned_rows_only,
          o.local_images,
          as_bits(static_cast<int>(o.balance)),
          as_bits(o.rebalance_every)};
}
constexpr const char* shared_option_names[] = {"method",       "skin",    "dims[0]",
                                               "dims[1]",      "dims[2]", "owned_rows_only",
                                               "local_images", "balance", "rebalance_every"};

}  // namespace

// ---- construction -----------------------------------------------------------------------------

DistributedEngine::DistributedEngine(MPI_Comm comm, DistributedOptions options)
    : comm_(comm), options_(std::move(options)) {
  check(MPI_Comm_rank(comm_, &rank_), "MPI_Comm_rank");
  check(MPI_Comm_size(comm_, &size_), "MPI_Comm_size");
  // Collective: every rank checks, then all agree, so that a rank that refuses (or knows no such
  // method) does not leave the others waiting in build().
  std::string error;
  ErrorCode code = ErrorCode::invalid_argument;
  try {
    setup();
  } catch (const Error& e) {
    error = e.what();
    code = e.code();
  }
  agree(error, code);
  // One collective for both bounds: the largest of v and of ~v (~ of the smallest v).
  std::vector<std::uint64_t> mine = shared_options(options_);
  const std::size_t count = mine.size();
  for (std::size_t k = 0; k < count; ++k) mine.push_back(~mine[k]);
  std::vector<std::uint64_t> largest(mine.size());
  check(MPI_Allreduce(mine.data(), largest.data(), static_cast<int>(mine.size()), MPI_UINT64_T,
                      MPI_MAX, comm_),
        "MPI_Allreduce");
  for (std::size_t k = 0; k < count; ++k)
    if (largest[k] != ~largest[count + k])
      throw Error(ErrorCode::invalid_argument,
                  std::string("distributed options differ between ranks: ") +
                      shared_option_names[k] + " (every rank must pass the same options)");
  // Collective (the host transport's MPI_Comm_dup): only once every rank got this far.
  exchange_ = std::make_unique<detail::Exchange>(comm_, options_.transport);
}

void DistributedEngine::setup() {
  if (!std::isfinite(options_.skin) || options_.skin < 0)
    throw Error(ErrorCode::invalid_argument,
                "distributed skin must be finite and >= 0, got " + std::to_string(options_.skin));
  if (options_.rebalance_every < 0)
    throw Error(ErrorCode::invalid_argument, "distributed rebalance_every must be >= 0, got " +
                                                 std::to_string(options_.rebalance_every));
  std::array<int, 3> dims = options_.dims;
  std::int64_t fixed = 1;  // 64-bit, each factor at most the ranks: no overflow
  bool all_given = true;
  for (int d : dims) {
    if (d < 0)
      throw Error(ErrorCode::invalid_argument, "distributed dims " + dims_text(dims) +
                                                   ": entries must be >= 0 (0: MPI chooses)");
    if (d > size_)
      throw Error(ErrorCode::invalid_argument, "distributed dims " + dims_text(dims) +
                                                   ": more domains along an axis than the " +
                                                   std::to_string(size_) + " ranks");
    if (d > 0) fixed *= d;
    all_given = all_given && d > 0;
  }
  if (size_ % fixed != 0 || (all_given && fixed != size_))
    throw Error(ErrorCode::invalid_argument,
                "distributed dims " + dims_text(dims) +
                    (all_given ? " make " + std::to_string(fixed) + " domains for the "
                               : " do not divide the ") +
                    std::to_string(size_) + " ranks of the communicator");
  check(MPI_Dims_create(size_, 3, dims.data()), "MPI_Dims_create");
  decomposition_.dims = dims;
  // The scheme from the method's declared capabilities (an unknown method throws here).
  passes_ = std::make_unique<detail::LocalPasses>(options_.method, options_.owned_rows_only);
}

DistributedEngine::~DistributedEngine() = default;

void DistributedEngine::check_built(const char* call) const {
  if (!built_)
    throw Error(ErrorCode::invalid_argument,
                std::string("DistributedEngine::") + call + "() called before build()");
}

void DistributedEngine::agree(const std::string& local_error, ErrorCode code) {
  detail::agree(comm_, local_error, code);
}

// ---- build ------------------------------------------------------------------------------------

void DistributedEngine::build(PositionsView positions, const std::uint64_t* ids, float cutoff,
                              const Box& box, const float* carried, std::size_t width) {
  built_ = false;
  std::string error;
  ErrorCode code = ErrorCode::invalid_argument;
  const double inf = std::numeric_limits<double>::infinity();
  std::array<double, 6> bounds = {inf, inf, inf, inf, inf, inf};  // min, -max
  const bool on_device = positions.space == MemorySpace::device;
  try {
    if (positions.size > 0 && (positions.xyz == nullptr || ids == nullptr))
      throw Error(ErrorCode::invalid_argument, "distributed build: null positions or ids");
    if (positions.size > detail::max_owned)
      throw Error(ErrorCode::unsupported, "distributed build: " + std::to_string(positions.size) +
                                              " particles given on one rank, more than 2^32 - 1 "
                                              "(the exchange's indices are 32-bit)");
    if (positions.size > 0 && width > 0 && carried == nullptr)
      throw Error(ErrorCode::invalid_argument, "distributed build: null carried values");
    if (on_device && passes_->space() != MemorySpace::device)
      throw Error(ErrorCode::unsupported,
                  "distributed build: positions in device memory, but method '" +
                      passes_->engine().method() + "' works on the host; give host positions");
    // The residence, chosen once for this build: where the positions were given.
    residence_ = on_device ? detail::make_device_resident() : detail::make_host_residence();
    residence_->adopt(positions.xyz, carried, ids, positions.size, width);
    positions.xyz = residence_->positions().data();  // checked here, on the host
    if (!(cutoff > 0) || !std::isfinite(cutoff))
      throw Error(ErrorCode::invalid_argument,
                  "cutoff must be finite and > 0, got " + std::to_string(cutoff));
    detail::set_geometry(decomposition_, box);  // validates the box
    local_box_ = box;
    for (int a = 0; a < 3; ++a) {
      decomposition_.local[a] = box.pbc[a] && decomposition_.dims[a] == 1 &&
                                options_.local_images && passes_->periodic_boxes();
      local_box_.pbc[a] = decomposition_.local[a];
    }
    const detail::Domains domains = detail::domains_of(decomposition_);
    for (std::size_t i = 0; i < positions.size; ++i) {
      for (int c = 0; c < 3; ++c)
        if (!std::isfinite(positions.xyz[3 * i + c]))
          throw Error(ErrorCode::invalid_input, "distributed build: particle " +
                                                    std::to_string(ids[i]) +
                                                    " has a non-finite coordinate");
      for (int a = 0; a < 3; ++a) {
        const double u = domains.coordinate(a, &positions.xyz[3 * i]);
        bounds[a] = std::min(bounds[a], u);
        bounds[3 + a] = std::min(bounds[3 + a], -u);
      }
    }
  } catch (const Error& e) {
    error = e.what();
    code = e.code();
  }
  // Every rank must describe the same system: compare with rank 0's. Outside the try, so that a
  // rank that threw above still takes part (a skipped broadcast would be matched by a later one).
  double mine[15];
  for (int a = 0; a < 3; ++a) {
    for (int c = 0; c < 3; ++c) mine[3 * a + c] = box.cell[a][c];
    mine[9 + a] = box.pbc[a];
  }
  mine[12] = cutoff;
  mine[13] = static_cast<double>(width);
  mine[14] = on_device;
  double root[15];
  std::memcpy(root, mine, sizeof mine);
  check(MPI_Bcast(root, 15, MPI_DOUBLE, 0, comm_), "MPI_Bcast");
  if (error.empty() && std::memcmp(root, mine, sizeof mine) != 0)
    error =
        "distributed build: box, cutoff, carried width or positions' memory space differ from "
        "rank 0's";
  agree(error, code);

  std::array<double, 6> global;
  check(MPI_Allreduce(bounds.data(), global.data(), 6, MPI_DOUBLE, MPI_MIN, comm_),
        "MPI_Allreduce");
  std::uint64_t local_n = positions.size;
  check(MPI_Allreduce(&local_n, &global_size_, 1, MPI_UINT64_T, MPI_SUM, comm_), "MPI_Allreduce");

  cutoff_ = cutoff;
  width_ = width;
  halo_width_ = static_cast<double>(cutoff) + static_cast<double>(options_.skin);
  detail::set_equal_cuts(decomposition_, global, global_size_ > 0, halo_width_);
  ids_.assign(ids, ids + positions.size);
  stats_ = {};
  built_ = true;
  exchange();
}

// ---- step loop ----------------------------------------------------------------------------------

bool DistributedEngine::update(const float* positions, const float* carried) {
  check_built("update");
  const auto start = Clock::now();
  const std::size_t n = ids_.size();
  std::string error;
  if (n > 0 && positions == nullptr) error = "distributed update: null positions";
  bool moved = false;  // some owned particle more than skin / 2 from its place at the last exchange
  if (error.empty()) {
    const auto moves = residence_->check_moves(positions, carried, 0.5 * options_.skin);
    if (moves.first_bad < n)
      error = "distributed update: particle " + std::to_string(ids_[moves.first_bad]) +
              " has a non-finite coordinate";
    moved = moves.moved;
  }
  // One collective for both verdicts: the lowest rank with an error, and whether any particle
  // moved beyond the skin (as -1, so that MIN reduces both).
  int verdict[2] = {error.empty() ? size_ : rank_, -(moved || options_.skin == 0)}, all[2];
  check(MPI_Allreduce(verdict, all, 2, MPI_INT, MPI_MIN, comm_), "MPI_Allreduce");
  if (all[0] != size_) detail::throw_error_of(comm_, all[0], error, ErrorCode::invalid_input);
  residence_->accept(positions, carried);  // only once every rank agreed
  stats_.update_ms = elapsed_ms(start);
  if (all[1] < 0) {
    exchange();
    return true;
  }
  refresh_halos();
  build_local_engine(true);
  return false;
}

// Every rank counts the same exchanges, so all move the cuts together, before the migration
// that takes the particles to their new owners.
void DistributedEngine::exchange() {
  check_built("exchange");
  const auto start = Clock::now();
  stats_.bytes_sent = 0;
  const bool balancing =
      options_.balance == Balance::particles &&
      (stats_.exchanges == 0 ||
       (options_.rebalance_every > 0 && stats_.exchanges % options_.rebalance_every == 0));
  residence_->set_domains(detail::domains_of(decomposition_));
  residence_->wrap();
  if (balancing) {  // the quantiles on the host, from the wrapped positions
    if (detail::balance_cuts(decomposition_, comm_, residence_->current_positions(), global_size_,
                             halo_width_))
      ++stats_.balances;
    residence_->set_domains(detail::domains_of(decomposition_));
  }
  exchange_->migrate(*residence_, ids_, width_, stats_);
  build_halos();
  ++stats_.exchanges;
  stats_.exchange_ms = elapsed_ms(start);
  build_local_engine(false);
}

// Every image of every owned particle, shifted along the axes with images (Decomposition::images),
// within cutoff + skin of some domain (its own too, for an image shifted by a period) goes there:
// [id][image xyz][shift] records. Local axes get no shift and no test: the local engines image
// every point they hold along them.
//
// Why this is complete, in any cell: normal[k] is a unit vector, so for a target t and an image
// p' of a source, |u_k(p') - u_k(t)| <= |p' - t|. A pair within h = cutoff + skin therefore
// has, along every axis, the image within h of the slab of t's domain: h / w_k in fractional
// units on a periodic axis. Positions are wrapped (u_k in [0, w_k)) and domains are at least h
// wide along the axes with images, so w_k >= h and |S_k| <= 1 reaches every such image (as
// image_range() gives for w >= C). With orthogonal normals the domain is a box and the Euclidean
// distance to it is exact; with skewed ones the per-axis test alone is kept (a parallelepiped's
// corner and edge regions are larger than the rounded shell: extra halos, sources only,
// harmless). Local axes: write p' = q + L . cell, L the part of S along local axes. No local row
// moves u_a of another axis (g_a . row_k = 0; an open normal is orthogonal to the periodic rows),
// so q has the gaps of p' along the other axes and none along the local ones (wrapped there): q
// passes the test, is held here (owned or a halo), and the local engine finds (t, q, L).
// The residence plans and moves them where the positions live (the same records in the same
// order on the host and the GPU).
void DistributedEngine::build_halos() {
  halo_count_ =
      residence_->build_halos(*exchange_, ids_, detail::halo_reach(decomposition_, halo_width_));
  stats_.bytes_sent += exchange_->plan_bytes(halo_record);
}

// The same halos at their owners' new positions: 3 floats per record, in the plan's order.
void DistributedEngine::refresh_halos() {
  const auto start = Clock::now();
  residence_->refresh_halos(*exchange_);
  ++stats_.refreshes;
  stats_.bytes_sent = exchange_->plan_bytes(refresh_record);
  stats_.exchange_ms = elapsed_ms(start);
}

void DistributedEngine::build_local_engine(bool same_sources) {
  std::string error;
  ErrorCode code = ErrorCode::internal;
  const auto start = Clock::now();
  try {
    // As the halos: a hair wide is harmless.
    passes_->build(*residence_, ids_.size(), halo_count_, cutoff_, local_box_, same_sources,
                   detail::domains_of(decomposition_), rank_,
                   detail::halo_reach(decomposition_, halo_width_));
  } catch (const Error& e) {
    error = e.what();
    code = e.code();
  }
  agree(error, code);
  stats_.build_ms = elapsed_ms(start);
  stats_.owned = ids_.size();
  stats_.halos = halo_count_;
  stats_.boundary = passes_->owned_rows_only() ? passes_->boundary().size() : ids_.size();
}

// ---- what the engine holds ------------------------------------------------------------------

MemorySpace DistributedEngine::space() const {
  return residence_ ? residence_->space() : MemorySpace::host;
}

const std::vector<float>& DistributedEngine::positions() const {
  return residence_ ? residence_->positions() : no_floats;
}

const std::vector<float>& DistributedEngine::carried() const {
  return residence_ ? residence_->carried() : no_floats;
}

const std::vector<std::uint64_t>& DistributedEngine::halo_ids() const {
  return residence_ ? residence_->halo_ids() : no_ids;
}

const std::vector<std::int32_t>& DistributedEngine::halo_shifts() const {
  return residence_ ? residence_->halo_shifts() : no_shifts;
}

PositionsView DistributedEngine::owned_positions() const {
  if (!residence_) return {nullptr, 0, MemorySpace::host};
  return residence_->owned_positions(ids_.size());
}

const float* DistributedEngine::owned_carried() const {
  return residence_ ? residence_->owned_carried() : nullptr;
}

DistributedEngine::DeviceIds DistributedEngine::device_ids() const {
  return residence_ ? residence_->device_ids() : DeviceIds{};
}

bool DistributedEngine::owned_rows_only() const {
  return passes_->owned_rows_only();
}

const Engine& DistributedEngine::local_engine() const {
  return passes_->engine();
}

const Engine* DistributedEngine::halo_engine() const {
  return passes_->halo_engine();
}

const std::vector<std::uint32_t>& DistributedEngine::boundary() const {
  return passes_->boundary();
}

// ---- results ------------------------------------------------------------------------------------

ResultsView DistributedEngine::run(Kernel kernel, const KernelOptions& options) {
  check_built("run");
  refuse_inputs_without_fields(kernel);
  return passes_->run(kernel, options);
}

Results DistributedEngine::compute(Kernel kernel, const KernelOptions& options) {
  check_built("compute");
  refuse_inputs_without_fields(kernel);
  return passes_->compute(kernel, options);
}

// sph_force's fields: given where this call needs them (compute(): host arrays, which a method
// that works in device memory cannot take; run() of a device-resident engine: device arrays),
// and none null on a rank with owned particles. Collective.
void DistributedEngine::check_sph_fields(const SphFields& owned, bool device) {
  std::string error;
  ErrorCode code = ErrorCode::invalid_argument;
  if (!device && passes_->space() != MemorySpace::host) {
    error = "distributed sph_force: method '" + passes_->engine().method() +
            "' works in device memory: give device fields to run() of a device-resident engine "
            "(positions in device memory), not host fields to compute()";
    code = ErrorCode::unsupported;
  } else if (!ids_.empty() && (!owned.velocity || !owned.density || !owned.pressure)) {
    error =
        "distributed sph_force needs velocity, density and pressure of the owned particles "
        "(SphFields)";
  }
  agree(error, code);
}

// The owned particles' fields extended to owned + halos by the residence (host: one exchange of
// the three; device: on the GPU), then sph_force through the local passes (a host method's
// row schedule, or a GPU method's own pass over all rows).
ResultsView DistributedEngine::run(Kernel kernel, const KernelOptions& options,
                                   const SphFields& owned) {
  check_built("run");
  if (kernel != Kernel::sph_force) return run(kernel, options);
  check_sph_fields(owned, space() == MemorySpace::device);
  KernelOptions with_fields = options;
  with_fields.sph = residence_->sph_fields(*exchange_, owned);
  return passes_->run(kernel, with_fields);
}

Results DistributedEngine::compute(Kernel kernel, const KernelOptions& options,
                                   const SphFields& owned) {
  check_built("compute");
  if (kernel != Kernel::sph_force) return compute(kernel, options);
  check_sph_fields(owned, false);
  KernelOptions with_fields = options;
  with_fields.sph = residence_->sph_fields(*exchange_, owned);
  return passes_->compute(kernel, with_fields);
}

// Record sizes are agreed by the width alone (the halo counts are the plan's): check it, and the
// owned values, on every rank. Collective.
void DistributedEngine::check_field_width(const char* call, const float* owned, std::size_t width) {
  check_built(call);
  const std::uint64_t w = width;
  std::uint64_t widths[2] = {w, ~w}, agreed[2];
  check(MPI_Allreduce(widths, agreed, 2, MPI_UINT64_T, MPI_MAX, comm_), "MPI_Allreduce");
  std::string error;
  if (agreed[0] != w || ~agreed[1] != w)
    error = std::string("distributed ") + call + ": width " + std::to_string(width) +
            " differs between ranks";
  else if (width > 0 && !ids_.empty() && owned == nullptr)
    error = std::string("distributed ") + call + ": null owned values";
  agree(error, ErrorCode::invalid_argument);
}

std::vector<float> DistributedEngine::halo_fields(const float* owned, std::size_t width) {
  check_field_width("halo_fields", owned, width);
  std::vector<float> local(width * (ids_.size() + halo_count_));
  if (width > 0) residence_->halo_fields_on_host(*exchange_, owned, width, local.data());
  return local;
}

void DistributedEngine::halo_fields(const float* owned, std::size_t width, float* local) {
  check_field_width("halo_fields", owned, width);
  std::string error;
  ErrorCode code = ErrorCode::unsupported;
  if (space() != MemorySpace::device) {
    error =
        "distributed halo_fields: device arrays need a device-resident engine (built from device "
        "positions); give host arrays to halo_fields(owned, width)";
  } else if (width > 0 && ids_.size() + halo_count_ > 0 && local == nullptr) {
    error = "distributed halo_fields: null local values";
    code = ErrorCode::invalid_argument;
  }
  agree(error, code);
  if (width > 0) residence_->halo_fields(*exchange_, owned, width, local);
}

// The local passes' rows with global indices: a local source is owned below owned(), else halo
// j - owned(). A pair's S is the halo's (axes with images) plus the local engine's (local axes,
// relative to the positions it was given): r = (x_j + S_halo . cell) + S_local . cell - x_i.
DistributedList DistributedEngine::neighbours(const ListOptions& options) {
  check_built("neighbours");
  if (options.cutoffs && options.cutoffs->active())
    throw Error(ErrorCode::unsupported,
                "DistributedEngine::neighbours: per-pair cutoffs are not taken here (each rank's "
                "particles are a subset); list at the largest cutoff and filter the rows");
  const std::vector<std::int32_t>& halo_shifts = this->halo_shifts();
  const detail::LocalList local = passes_->neighbours(options, halo_shifts);
  const std::vector<std::uint64_t>& halo_ids = this->halo_ids();
  const std::size_t n = ids_.size();
  DistributedList out;
  out.targets = ids_;
  out.offsets.assign(n + 1, 0);
  // A full list keeps every local entry, a half list about half of them: no regrowth.
  const std::uint64_t kept = options.half ? local.sources.size() / 2 : local.sources.size();
  out.indices.reserve(kept);
  if (options.distances) out.distances.reserve(kept);
  if (options.vectors) out.vectors.reserve(3 * kept);
  if (options.shifts) out.shifts.reserve(3 * kept);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::uint64_t e = local.offsets[i]; e < local.offsets[i + 1]; ++e) {
      const std::uint32_t j = local.sources[e];
      const std::uint64_t id = j < n ? ids_[j] : halo_ids[j - n];
      const std::int32_t* s = &local.shifts[3 * e];
      if (options.half) {
        const Shift shift{s[0], s[1], s[2]};
        if (id < ids_[i] || (id == ids_[i] && !shift.positive())) continue;
      }
      out.indices.push_back(id);
      if (options.distances) out.distances.push_back(local.distances[e]);
      if (options.vectors)
        out.vectors.insert(out.vectors.end(), &local.vectors[3 * e], &local.vectors[3 * e] + 3);
      if (options.shifts) out.shifts.insert(out.shifts.end(), s, s + 3);
    }
    out.offsets[i + 1] = out.indices.size();
  }
  return out;
}

}  // namespace raycut::mpi
