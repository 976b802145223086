// The distributed engine: domain decomposition, migration, halos with periodic images across
// split axes, and Engines per rank over owned and halo particles, periodic along the axes with
// one domain (docs/distributed.md).
#include "raycut/mpi/distributed.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>
#include <type_traits>
#include <vector>

#include <omp.h>

#include "core/engine_access.hpp"
#include "mpi/device_residence.hpp"
#include "mpi/mpi_check.hpp"
#include "raycut/mpi/pairs.hpp"
#include "raycut/pairs.hpp"

namespace raycut::mpi {
namespace {

using Clock = std::chrono::steady_clock;

// Owned particles per rank: the halo plan's and the migration's indices are 32-bit.
constexpr std::uint64_t max_owned = std::numeric_limits<std::uint32_t>::max();
double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

const char* axis_name(int axis) {
  return axis == 0 ? "x" : axis == 1 ? "y" : "z";
}

std::string dims_text(const std::array<int, 3>& d) {
  return "[" + std::to_string(d[0]) + " " + std::to_string(d[1]) + " " + std::to_string(d[2]) + "]";
}

template <class T>
void put(std::byte*& at, const T* values, std::size_t n) {
  std::memcpy(at, values, n * sizeof(T));
  at += n * sizeof(T);
}
template <class T>
void take(const std::byte*& at, T* values, std::size_t n) {
  std::memcpy(values, at, n * sizeof(T));
  at += n * sizeof(T);
}

std::vector<std::uint64_t> offsets_of(const std::vector<std::uint64_t>& counts,
                                      std::uint64_t scale) {
  std::vector<std::uint64_t> offsets(counts.size());
  std::uint64_t at = 0;
  for (std::size_t r = 0; r < counts.size(); ++r) {
    offsets[r] = at;
    at += counts[r] * scale;
  }
  return offsets;
}

std::vector<std::uint64_t> scaled(const std::vector<std::uint64_t>& counts, std::uint64_t scale) {
  std::vector<std::uint64_t> out(counts);
  for (auto& c : out) c *= scale;
  return out;
}

// The unit vector of a row (zero stays zero).
std::array<double, 3> unit(const std::array<double, 3>& v) {
  const double norm = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return norm > 0 ? std::array<double, 3>{v[0] / norm, v[1] / norm, v[2] / norm} : v;
}

double dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// The box's part of the decomposition (Decomposition in the header): normals, periods, rows.
// Validates the box first.
void set_geometry(Decomposition& dec, const Box& box) {
  validate(box);
  const auto g = reciprocal_rows(box);
  dec.aligned = true;
  bool open_cartesian = true;  // every open e_k orthogonal to every periodic row
  for (int k = 0; k < 3; ++k) {
    dec.periodic[k] = box.pbc[k];
    for (int c = 0; c < 3; ++c) dec.cell[k][c] = box.cell[k][c];
    if (!box.pbc[k]) continue;
    for (int c = 0; c < 3; ++c) {
      if (c != k && box.cell[k][c] != 0) dec.aligned = false;
      if (c != k && !box.pbc[c] && box.cell[k][c] != 0) open_cartesian = false;
    }
    if (!(box.cell[k][k] > 0)) dec.aligned = false;
  }
  for (int k = 0; k < 3; ++k) {
    std::array<double, 3> e = {0, 0, 0};
    e[k] = 1;
    if (box.pbc[k] && dec.aligned) {
      dec.normal[k] = e;  // exactly: u_k = x_k, as orthorhombic boxes always had it
      dec.length[k] = box.cell[k][k];
    } else if (box.pbc[k]) {
      dec.normal[k] = unit(g[k]);
      dec.length[k] = face_width(box, k);
    } else {
      // The reciprocal row of a completion row is that row (unit, orthogonal to the others).
      dec.normal[k] = open_cartesian ? e : unit(g[k]);
      dec.length[k] = 0;
    }
  }
  dec.orthogonal = true;
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b)
      if (std::abs(dot(dec.normal[a], dec.normal[b])) > 1e-12) dec.orthogonal = false;
}

// Decomposition's arithmetic as plain data (domains.hpp), over its cuts in place.
detail::Domains domains_of(const Decomposition& dec) {
  detail::Domains d{};
  for (int a = 0; a < 3; ++a) {
    d.dims[a] = dec.dims[a];
    d.periodic[a] = dec.periodic[a];
    d.images[a] = dec.images(a);
    d.crossed[a] = dec.halo_axis(a);
    d.length[a] = dec.length[a];
    for (int c = 0; c < 3; ++c) {
      d.normal[a][c] = dec.normal[a][c];
      d.cell[a][c] = dec.cell[a][c];
    }
    d.cuts[a] = dec.cuts[a].data();
  }
  d.aligned = dec.aligned;
  d.orthogonal = dec.orthogonal;
  return d;
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

// The device side of a device-resident engine: asked for by methods that work on the device
// only, which builds without CUDA do not have.
std::unique_ptr<detail::DeviceResidence> device_residence() {
#if defined(RAYCUT_HAVE_CUDA)
  return detail::make_device_residence();
#else
  throw Error(ErrorCode::internal, "a device-resident engine in a build without CUDA");
#endif
}

// Halo candidates a little beyond the halo width: extra halos are harmless (they are sources
// only), missing ones are not, and the slab and distance tests round in double at the scale of
// the coordinates.
double reach_of(const Decomposition& dec, double halo_width) {
  double scale = halo_width;
  for (const auto& cuts : dec.cuts)
    for (double c : cuts) scale = std::max(scale, std::abs(c));
  return halo_width + 1e-5 * scale;
}

}  // namespace

// ---- decomposition ----------------------------------------------------------------------------

// One implementation, the exchange's (domains.hpp); loops over particles make their Domains once.
double Decomposition::coordinate(int axis, const float* xyz) const {
  return domains_of(*this).coordinate(axis, xyz);
}

int Decomposition::slab(int axis, double u) const {
  return domains_of(*this).slab(axis, u);
}

int Decomposition::owner(const float* xyz) const {
  return domains_of(*this).owner(xyz);
}

std::array<int, 3> Decomposition::coords(int domain) const {
  int c[3];
  domains_of(*this).coords(domain, c);
  return {c[0], c[1], c[2]};
}

// Where halo records go: per destination rank, the owned particle and the image shift, in the
// order they were sent (a refresh resends positions in the same order). A device-resident
// engine keeps index and shift on the GPU (DeviceResidence::plan_halos), the counts here.
struct DistributedEngine::HaloPlan {
  std::vector<std::uint64_t> send_counts, recv_counts;  // halos per rank
  std::vector<std::uint32_t> index;                     // owned index per record, by rank
  std::vector<std::int32_t> shift;                      // 3 per record
  std::uint64_t sent() const {
    return std::accumulate(send_counts.begin(), send_counts.end(), 0ull);
  }
  std::uint64_t received() const {
    return std::accumulate(recv_counts.begin(), recv_counts.end(), 0ull);
  }
};

// ---- construction -----------------------------------------------------------------------------

namespace {

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
  // Collective (MPI_Comm_dup): only once every rank got this far.
  const bool host_given = options_.transport && options_.transport->space() == MemorySpace::host;
  host_transport_ = host_given ? options_.transport : make_host_transport(comm_);
  transport_ = options_.transport ? options_.transport : host_transport_;
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
  engine_ = std::make_unique<Engine>(options_.method);  // an unknown method throws here
  // Does the method take periodic boxes and query points (one refusal covers both)? One point
  // asked of itself: grid-paper and the OptiX methods refuse with unsupported (every rank alike:
  // the method is the same).
  auto probe_engine = std::make_unique<Engine>(engine_->method());
  const float origin[3] = {0, 0, 0};
  Systems probe;
  probe.queries = {origin, 1, MemorySpace::host};
  try {
    probe_engine->build({origin, 1, MemorySpace::host}, 1.0f, probe);
    takes_boxes_ = true;
  } catch (const Error& e) {
    if (e.code() != ErrorCode::unsupported) throw;
  }
  split_ = options_.owned_rows_only && takes_boxes_;
  if (split_) halo_engine_ = std::move(probe_engine);
  plan_ = std::make_unique<HaloPlan>();
}

DistributedEngine::~DistributedEngine() = default;

void DistributedEngine::check_built(const char* call) const {
  if (!built_)
    throw Error(ErrorCode::invalid_argument,
                std::string("DistributedEngine::") + call + "() called before build()");
}

// Every rank throws when any rank found an error: the first failing rank's message, so that no
// rank is left waiting in a collective the others have abandoned.
void DistributedEngine::agree(const std::string& local_error, ErrorCode code) {
  int failed = local_error.empty() ? size_ : rank_;
  int first = size_;
  check(MPI_Allreduce(&failed, &first, 1, MPI_INT, MPI_MIN, comm_), "MPI_Allreduce");
  if (first != size_) throw_error_of(first, local_error, code);
}

// The error of rank `first` (the lowest that failed), thrown on every rank.
void DistributedEngine::throw_error_of(int first, const std::string& local_error, ErrorCode code) {
  std::string message = local_error;
  int header[2] = {static_cast<int>(message.size()), static_cast<int>(code)};
  MPI_Bcast(header, 2, MPI_INT, first, comm_);
  message.resize(static_cast<std::size_t>(header[0]));
  MPI_Bcast(message.data(), header[0], MPI_CHAR, first, comm_);
  throw Error(static_cast<ErrorCode>(header[1]), "rank " + std::to_string(first) + ": " + message);
}

void DistributedEngine::exchange_counts(const std::vector<std::uint64_t>& send,
                                        std::vector<std::uint64_t>& recv) {
  recv.assign(static_cast<std::size_t>(size_), 0);
  check(MPI_Alltoall(send.data(), 1, MPI_UINT64_T, recv.data(), 1, MPI_UINT64_T, comm_),
        "MPI_Alltoall");
}

// ---- build ------------------------------------------------------------------------------------

void DistributedEngine::build(PositionsView positions, const std::uint64_t* ids, float cutoff,
                              const Box& box, const float* carried, std::size_t width) {
  built_ = false;
  std::string error;
  ErrorCode code = ErrorCode::invalid_argument;
  std::array<double, 6> bounds = {std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity(),
                                  std::numeric_limits<double>::infinity()};  // min, -max
  const bool on_device = positions.space == MemorySpace::device;
  std::vector<float> staged_xyz, staged_carried;  // device positions: the host copies planned on
  try {
    if (positions.size > 0 && (positions.xyz == nullptr || ids == nullptr))
      throw Error(ErrorCode::invalid_argument, "distributed build: null positions or ids");
    if (positions.size > max_owned)
      throw Error(ErrorCode::unsupported, "distributed build: " + std::to_string(positions.size) +
                                              " particles given on one rank, more than 2^32 - 1 "
                                              "(the exchange's indices are 32-bit)");
    if (positions.size > 0 && width > 0 && carried == nullptr)
      throw Error(ErrorCode::invalid_argument, "distributed build: null carried values");
    if (on_device) {
      if (engine_->space() != MemorySpace::device)
        throw Error(ErrorCode::unsupported,
                    "distributed build: positions in device memory, but method '" +
                        engine_->method() + "' works on the host; give host positions");
      // Planned on the host like any exchange (from host copies); device_ keeps them after it.
      device_ = device_residence();
      device_->adopt(positions.xyz, carried, ids, positions.size, width, staged_xyz,
                     staged_carried);
      positions.xyz = staged_xyz.data();
      carried = width > 0 ? staged_carried.data() : nullptr;
    } else {
      device_.reset();
    }
    if (!(cutoff > 0) || !std::isfinite(cutoff))
      throw Error(ErrorCode::invalid_argument,
                  "cutoff must be finite and > 0, got " + std::to_string(cutoff));
    set_geometry(decomposition_, box);  // validates the box
    local_box_ = box;
    for (int a = 0; a < 3; ++a) {
      decomposition_.local[a] =
          box.pbc[a] && decomposition_.dims[a] == 1 && options_.local_images && takes_boxes_;
      local_box_.pbc[a] = decomposition_.local[a];
    }
    const detail::Domains domains = domains_of(decomposition_);
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
  Decomposition& dec = decomposition_;
  for (int a = 0; a < 3; ++a) {
    double lo = 0;
    const double along = dot(dec.cell[a], dec.normal[a]);  // the open row's extent along u_a
    if (dec.periodic[a] || along > 0) {
      if (!dec.periodic[a]) dec.length[a] = along;
    } else {  // an open axis with no length: the particles' extent now
      const bool any = global_size_ > 0;
      lo = any ? global[a] : 0;
      dec.length[a] = any ? -global[3 + a] - global[a] : 0;
    }
    // Equal slabs; Balance::particles moves the inner cuts at the first exchange. Either way the
    // region must hold dims equal slabs of cutoff + skin.
    const double width = dec.length[a] / dec.dims[a];
    dec.cuts[a].resize(static_cast<std::size_t>(dec.dims[a]) + 1);
    for (int i = 0; i <= dec.dims[a]; ++i) dec.cuts[a][i] = lo + i * width;
    dec.cuts[a].back() = lo + dec.length[a];
    if (dec.halo_axis(a) && !(width >= halo_width_)) {
      // Orthorhombic axes by coordinate, triclinic ones by cell row and face width.
      const std::string axis = dec.aligned ? axis_name(a)
                                           : std::string("cell row ") + "abc"[a] + " (normal " +
                                                 std::to_string(dec.normal[a][0]) + ", " +
                                                 std::to_string(dec.normal[a][1]) + ", " +
                                                 std::to_string(dec.normal[a][2]) + ")";
      throw Error(ErrorCode::invalid_argument,
                  "distributed engine: domains along " + axis + " are " + std::to_string(width) +
                      " wide (" + std::to_string(dec.dims[a]) + " over " +
                      (dec.periodic[a] ? "face width " : "") + std::to_string(dec.length[a]) +
                      "), less than cutoff + skin = " + std::to_string(halo_width_) +
                      "; use fewer domains along that axis (DistributedOptions::dims) or a "
                      "larger box");
    }
  }

  split_ = halo_engine_ && !device_;
  ids_.assign(ids, ids + positions.size);
  xyz_.assign(positions.xyz, positions.xyz + 3 * positions.size);
  if (carried)
    carried_.assign(carried, carried + width * positions.size);
  else
    carried_.clear();
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
  const double half_skin = 0.5 * static_cast<double>(options_.skin);
  int moved = 0;  // some owned particle more than skin / 2 from its place at the last exchange
  if (device_) {  // the same steps on the GPU, in one pass: copy, finite check, skin test
    if (error.empty()) {
      const auto taken = device_->take(positions, carried, static_cast<float>(half_skin));
      if (taken.first_bad < n)
        error = "distributed update: particle " + std::to_string(ids_[taken.first_bad]) +
                " has a non-finite coordinate";
      moved = taken.moved;
    }
  } else {
    double moved2 = 0;
    for (std::size_t i = 0; error.empty() && i < n; ++i) {
      double d2 = 0;
      for (int c = 0; c < 3; ++c) {
        const float v = positions[3 * i + c];
        if (!std::isfinite(v)) {
          error = "distributed update: particle " + std::to_string(ids_[i]) +
                  " has a non-finite coordinate";
          break;
        }
        const double d = static_cast<double>(v) - xyz_at_exchange_[3 * i + c];
        d2 += d * d;
      }
      moved2 = std::max(moved2, d2);
    }
    moved = moved2 > half_skin * half_skin;
  }
  // One collective for both verdicts: the lowest rank with an error, and whether any particle
  // moved beyond the skin (as -1, so that MIN reduces both).
  int verdict[2] = {error.empty() ? size_ : rank_, -(moved || options_.skin == 0)}, all[2];
  check(MPI_Allreduce(verdict, all, 2, MPI_INT, MPI_MIN, comm_), "MPI_Allreduce");
  if (all[0] != size_) throw_error_of(all[0], error, ErrorCode::invalid_input);
  if (!device_) {  // taken only once every rank agreed
    std::copy(positions, positions + 3 * n, xyz_.begin());
    if (carried) std::copy(carried, carried + width_ * n, carried_.begin());
  }
  stats_.update_ms = elapsed_ms(start);
  if (all[1] < 0) {
    exchange();
    return true;
  }
  refresh_halos();
  build_local_engine(true);
  return false;
}

void DistributedEngine::exchange() {
  check_built("exchange");
  const auto start = Clock::now();
  stats_.bytes_sent = 0;
  // Every rank counts the same exchanges, so all move the cuts together, before the migration
  // that takes the particles to their new owners.
  const bool balancing =
      options_.balance == Balance::particles &&
      (stats_.exchanges == 0 ||
       (options_.rebalance_every > 0 && stats_.exchanges % options_.rebalance_every == 0));
  if (device_) {  // planned on the GPU, from the same arithmetic
    host_positions_ = host_carried_ = false;
    device_->set_domains(domains_of(decomposition_));
    device_->wrap();
    if (balancing) {  // the quantiles on the host, from the wrapped positions
      device_->download(xyz_, carried_);
      balance();
      device_->set_domains(domains_of(decomposition_));
    }
  } else {
    const detail::Domains domains = domains_of(decomposition_);
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(ids_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i) domains.wrap(&xyz_[3 * i]);
    if (balancing) balance();
  }
  migrate();
  build_halos();
  if (!device_) xyz_at_exchange_ = xyz_;
  ++stats_.exchanges;
  stats_.exchange_ms = elapsed_ms(start);
  build_local_engine(false);
}

// Balance::particles: the inner cuts of each split axis at the quantiles i / dims[a] of the
// particle count along u_a over all particles, each axis by its own marginal distribution (the
// grid stays Cartesian, so every domain keeps its neighbours; docs/distributed.md says what this
// does not balance). Found by bisection, every cut at once, over MPI_Allreduce of the counts
// below the probes: integer sums and the same arithmetic, so every rank gets the same cuts. Then
// each slab is kept at least h = cutoff + skin wide, which the halo test needs (one image per side,
// neighbours' slabs only): cut i at least h above cut i - 1 and, on a periodic axis, h above 0 and
// at most L - (dims - i) h (room that build()'s check of dims equal slabs leaves).
void DistributedEngine::balance() {
  Decomposition& dec = decomposition_;
  if (global_size_ == 0 || dec.domains() == 1) return;
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u[3];
  std::array<double, 6> bounds = {inf, inf, inf, inf, inf, inf}, global;  // min, -max
  const detail::Domains domains = domains_of(dec);
  for (int a = 0; a < 3; ++a) {
    if (dec.dims[a] == 1) continue;
    u[a].resize(ids_.size());
    for (std::size_t i = 0; i < ids_.size(); ++i) {
      u[a][i] = domains.coordinate(a, &xyz_[3 * i]);
      bounds[a] = std::min(bounds[a], u[a][i]);
      bounds[3 + a] = std::min(bounds[3 + a], -u[a][i]);
    }
    std::sort(u[a].begin(), u[a].end());
  }
  check(MPI_Allreduce(bounds.data(), global.data(), 6, MPI_DOUBLE, MPI_MIN, comm_),
        "MPI_Allreduce");
  struct Cut {
    int axis, index;
    std::uint64_t target;  // particles below the cut
    double low, high;      // count(u < low) < target <= count(u < high)
  };
  std::vector<Cut> cuts;
  for (int a = 0; a < 3; ++a)
    for (int i = 1; i < dec.dims[a]; ++i)
      cuts.push_back({a, i, global_size_ * i / dec.dims[a], dec.periodic[a] ? 0.0 : global[a],
                      dec.periodic[a] ? dec.length[a] : -global[3 + a]});
  std::vector<std::uint64_t> below(cuts.size()), total(cuts.size());
  for (int round = 0; round < 48; ++round) {  // 2^-48 of the range: below float resolution
    for (std::size_t k = 0; k < cuts.size(); ++k) {
      const auto& v = u[cuts[k].axis];
      const double mid = 0.5 * (cuts[k].low + cuts[k].high);
      below[k] = static_cast<std::uint64_t>(std::lower_bound(v.begin(), v.end(), mid) - v.begin());
    }
    check(MPI_Allreduce(below.data(), total.data(), static_cast<int>(cuts.size()), MPI_UINT64_T,
                        MPI_SUM, comm_),
          "MPI_Allreduce");
    for (std::size_t k = 0; k < cuts.size(); ++k)
      (total[k] < cuts[k].target ? cuts[k].low : cuts[k].high) = 0.5 * (cuts[k].low + cuts[k].high);
  }
  for (const Cut& cut : cuts) {  // by axis, then index: cut i - 1 is placed before cut i
    const int a = cut.axis, i = cut.index, d = dec.dims[a];
    double c = cut.high;
    if (i > 1 || dec.periodic[a]) c = std::max(c, dec.cuts[a][i - 1] + halo_width_);
    if (dec.periodic[a]) c = std::min(c, dec.length[a] - (d - i) * halo_width_);
    dec.cuts[a][i] = c;
  }
  ++stats_.balances;
}

namespace {

// Rows `gone` (ascending) removed from v (`width` values a row), the others kept in order.
template <class T>
void remove_rows(std::vector<T>& v, std::size_t width, const std::vector<std::uint32_t>& gone) {
  if (gone.empty() || width == 0) return;
  const std::size_t rows = v.size() / width;
  std::size_t to = width * gone[0];
  for (std::size_t k = 0; k < gone.size(); ++k) {
    const std::size_t from = gone[k] + 1, end = k + 1 < gone.size() ? gone[k + 1] : rows;
    std::copy(v.begin() + width * from, v.begin() + width * end, v.begin() + to);
    to += width * (end - from);
  }
  v.resize(to);
}

// migrate()'s owners on the host (the GPU's: DeviceResidence::find_owners): per rank the
// particles it owns, and the leaving ones grouped by owner in index order, with their positions
// and carried floats.
void leaving_on_host(const detail::Domains& domains, int rank, int size,
                     const std::vector<float>& xyz, const std::vector<float>& carried,
                     std::size_t width, detail::DeviceResidence::Leaving& leaving) {
  const std::size_t n = xyz.size() / 3;
  std::vector<int> dest(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i)
    dest[i] = domains.owner(&xyz[3 * i]);
  leaving.counts.assign(static_cast<std::size_t>(size), 0);
  for (int d : dest) ++leaving.counts[static_cast<std::size_t>(d)];
  std::vector<std::uint64_t> cursor(static_cast<std::size_t>(size), 0);
  std::uint64_t at = 0;
  for (int r = 0; r < size; ++r) {
    cursor[r] = at;
    if (r != rank) at += leaving.counts[r];
  }
  const std::size_t gone = n - leaving.counts[static_cast<std::size_t>(rank)];
  leaving.index.resize(gone);
  leaving.xyz.resize(3 * gone);
  leaving.carried.resize(width * gone);
  for (std::size_t i = 0; i < n; ++i) {
    if (dest[i] == rank) continue;
    const std::uint64_t j = cursor[static_cast<std::size_t>(dest[i])]++;
    leaving.index[j] = static_cast<std::uint32_t>(i);
    std::copy_n(&xyz[3 * i], 3, &leaving.xyz[3 * j]);
    std::copy_n(carried.begin() + width * i, width, leaving.carried.begin() + width * j);
  }
}

}  // namespace

// Every particle outside this rank's domain goes to its owner: [id][xyz][carried] records, by
// owner, in index order. The staying particles keep their order; the arrivals follow them in
// the order of their ranks. The owners are found where the positions live (leaving_on_host(), or
// the GPU's find_owners(): the same owners, the same order); the records cross on the host.
void DistributedEngine::migrate() {
  const std::size_t record = sizeof(std::uint64_t) + (3 + width_) * sizeof(float);
  detail::DeviceResidence::Leaving leaving;
  if (device_)
    device_->find_owners(rank_, size_, leaving);
  else
    leaving_on_host(domains_of(decomposition_), rank_, size_, xyz_, carried_, width_, leaving);
  std::vector<std::uint64_t> send_counts = leaving.counts;
  send_counts[static_cast<std::size_t>(rank_)] = 0;  // kept in place, not sent
  std::vector<std::uint64_t> recv_counts;
  exchange_counts(send_counts, recv_counts);
  const std::uint64_t received = std::accumulate(recv_counts.begin(), recv_counts.end(), 0ull);
  const std::uint64_t owning = leaving.counts[static_cast<std::size_t>(rank_)] + received;
  agree(owning > max_owned ? "distributed exchange: rank " + std::to_string(rank_) + " would own " +
                                 std::to_string(owning) +
                                 " particles, more than 2^32 - 1 (the exchange's indices are "
                                 "32-bit); use more ranks"
                           : std::string(),
        ErrorCode::out_of_memory);
  const std::size_t sent = leaving.index.size();
  std::vector<std::byte> send(sent * record), recv(received * record);
  std::byte* at = send.data();
  for (std::size_t j = 0; j < sent; ++j) {
    put(at, &ids_[leaving.index[j]], 1);
    put(at, &leaving.xyz[3 * j], 3);
    put(at, leaving.carried.data() + width_ * j, width_);
  }
  host_transport_->exchange(
      send.data(), scaled(send_counts, record).data(), offsets_of(send_counts, record).data(),
      recv.data(), scaled(recv_counts, record).data(), offsets_of(recv_counts, record).data());

  std::vector<std::uint32_t> gone = leaving.index;
  std::sort(gone.begin(), gone.end());
  remove_rows(ids_, 1, gone);
  std::vector<float> xyz(3 * received), carried(width_ * received);  // the arrivals'
  std::vector<std::uint64_t> ids(received);
  const std::byte* from = recv.data();
  for (std::uint64_t k = 0; k < received; ++k) {
    take(from, &ids[k], 1);
    take(from, &xyz[3 * k], 3);
    take(from, carried.data() + width_ * k, width_);
  }
  ids_.insert(ids_.end(), ids.begin(), ids.end());
  if (device_) {
    device_->keep_staying(xyz, carried, ids);
  } else {
    remove_rows(xyz_, 3, gone);
    remove_rows(carried_, width_, gone);
    xyz_.insert(xyz_.end(), xyz.begin(), xyz.end());
    carried_.insert(carried_.end(), carried.begin(), carried.end());
  }
  stats_.migrated_out = sent;
  stats_.bytes_sent += sent * record;
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
// The plan is made where the positions live (plan_halos_on_host(), or the GPU's plan_halos():
// the same records in the same order); a host-resident engine's records cross on the host, a
// device-resident engine's by the refreshes' transport (exchange_on_device).
void DistributedEngine::build_halos() {
  const double reach = reach_of(decomposition_, halo_width_);
  HaloPlan& plan = *plan_;
  const std::size_t record = sizeof(std::uint64_t) + 3 * sizeof(float) + 3 * sizeof(std::int32_t);
  if (device_) {
    // Planned, gathered and received on the GPU, each column along the plan by the refreshes'
    // transport (GPU to GPU, or staged); the halos' ids and shifts come to the host when asked.
    device_->plan_halos(rank_, size_, reach, plan.send_counts);
    exchange_counts(plan.send_counts, plan.recv_counts);
    std::string error;
    detail::DeviceResidence::HaloSlots slots{};
    try {
      slots = device_->receive_halos(plan.received());
    } catch (const Error& e) {  // no room on this rank: every rank stops before the sends
      error = e.what();
    }
    agree(error, ErrorCode::out_of_memory);
    exchange_on_device(device_->gather_ids(), sizeof(std::uint64_t), slots.ids);
    exchange_on_device(device_->gather(), 3 * sizeof(float), slots.xyz);
    exchange_on_device(device_->plan_shifts(), 3 * sizeof(std::int32_t), slots.shifts);
    halo_count_ = plan.received();
    host_halos_ = false;
    stats_.bytes_sent += (plan.sent() - plan.send_counts[rank_]) * record;
    return;
  }
  const std::size_t n = ids_.size();
  plan_halos_on_host(reach);
  const detail::Domains domains = domains_of(decomposition_);
  exchange_counts(plan.send_counts, plan.recv_counts);
  const std::uint64_t received = plan.received();
  std::vector<std::byte> send(plan.index.size() * record), recv(received * record);
  std::byte* at = send.data();
  for (std::size_t k = 0; k < plan.index.size(); ++k) {
    float image[3];  // x + S . cell
    domains.image(&xyz_[3 * plan.index[k]], &plan.shift[3 * k], image);
    put(at, &ids_[plan.index[k]], 1);
    put(at, image, 3);
    put(at, &plan.shift[3 * k], 3);
  }
  host_transport_->exchange(send.data(), scaled(plan.send_counts, record).data(),
                            offsets_of(plan.send_counts, record).data(), recv.data(),
                            scaled(plan.recv_counts, record).data(),
                            offsets_of(plan.recv_counts, record).data());

  halo_ids_.resize(received);
  halo_shifts_.resize(3 * received);
  local_xyz_.resize(3 * (n + received));
  std::copy(xyz_.begin(), xyz_.end(), local_xyz_.begin());
  const std::byte* from = recv.data();
  for (std::uint64_t k = 0; k < received; ++k) {
    take(from, &halo_ids_[k], 1);
    take(from, &local_xyz_[3 * (n + k)], 3);
    take(from, &halo_shifts_[3 * k], 3);
  }
  halo_count_ = received;
  host_halos_ = true;
  stats_.bytes_sent += (plan.index.size() - plan.send_counts[rank_]) * record;
}

// Per halo record `bytes` from `send` (device, the plan's order) to `recv` (device, the halos'
// order), along the plan of the last exchange: by the refreshes' transport, GPU to GPU, or
// staged through the host. Collective over the ranks that send or receive: a rank with neither
// takes no part (one rank with every periodic axis local: no transport call at all).
void DistributedEngine::exchange_on_device(const void* send, std::size_t bytes, void* recv) {
  const HaloPlan& plan = *plan_;
  if (plan.sent() == 0 && plan.received() == 0) return;
  const auto send_counts = scaled(plan.send_counts, bytes);
  const auto recv_counts = scaled(plan.recv_counts, bytes);
  const auto send_offsets = offsets_of(plan.send_counts, bytes);
  const auto recv_offsets = offsets_of(plan.recv_counts, bytes);
  if (transport_->space() == MemorySpace::device) {
    transport_->exchange(static_cast<const std::byte*>(send), send_counts.data(),
                         send_offsets.data(), static_cast<std::byte*>(recv), recv_counts.data(),
                         recv_offsets.data());
    return;
  }
  const std::size_t sent_bytes = plan.sent() * bytes, received_bytes = plan.received() * bytes;
  std::byte* sent = device_->staging(0, sent_bytes);
  std::byte* received = device_->staging(1, received_bytes);
  device_->copy(sent, send, sent_bytes);
  host_transport_->exchange(sent, send_counts.data(), send_offsets.data(), received,
                            recv_counts.data(), recv_offsets.data());
  device_->copy(recv, received, received_bytes);
}

// build_halos()'s plan on the host: detail::for_each_halo over the owned particles, in OpenMP
// threads. Threads take contiguous blocks of particles in order (a static schedule), so
// appending their per-rank routes in thread order gives the serial order: the same plan
// whatever the thread count (and the GPU's, which sorts the serial records by rank).
void DistributedEngine::plan_halos_on_host(double reach) {
  const detail::Domains domains = domains_of(decomposition_);
  const std::size_t n = ids_.size();
  bool any_crossed = false;  // else nothing is sent (one rank, every periodic axis local)
  for (int a = 0; a < 3; ++a) any_crossed = any_crossed || domains.crossed[a];
  struct Routes {
    std::vector<std::vector<std::uint32_t>> index;
    std::vector<std::vector<std::int32_t>> shift;
  };
  std::vector<Routes> routes(static_cast<std::size_t>(omp_get_max_threads()));
  const detail::Faces faces(domains, rank_);
#pragma omp parallel if (any_crossed)
  {
    Routes& mine = routes[static_cast<std::size_t>(omp_get_thread_num())];
    mine.index.resize(static_cast<std::size_t>(size_));
    mine.shift.resize(static_cast<std::size_t>(size_));
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < (any_crossed ? static_cast<std::ptrdiff_t>(n) : 0); ++i)
      detail::for_each_halo(domains, faces, rank_, reach, &xyz_[3 * i],
                            [&](int q, const std::int32_t* s) {
                              mine.index[q].push_back(static_cast<std::uint32_t>(i));
                              mine.shift[q].insert(mine.shift[q].end(), s, s + 3);
                            });
  }
  HaloPlan& plan = *plan_;
  plan.send_counts.assign(static_cast<std::size_t>(size_), 0);
  plan.index.clear();
  plan.shift.clear();
  for (int r = 0; r < size_; ++r)
    for (Routes& mine : routes) {
      if (mine.index.empty()) continue;  // a thread the team did not have
      plan.send_counts[r] += mine.index[r].size();
      plan.index.insert(plan.index.end(), mine.index[r].begin(), mine.index[r].end());
      plan.shift.insert(plan.shift.end(), mine.shift[r].begin(), mine.shift[r].end());
    }
}

// The same halos at their owners' new positions: 3 floats per record, in the plan's order.
void DistributedEngine::refresh_halos() {
  const auto start = Clock::now();
  const HaloPlan& plan = *plan_;
  const std::size_t record = 3 * sizeof(float);
  const std::size_t n = ids_.size();
  if (device_) {  // gathered on the GPU
    exchange_on_device(device_->gather(), record, device_->local() + 3 * n);
  } else {
    const detail::Domains domains = domains_of(decomposition_);
    std::vector<float> send(3 * plan.index.size());
    for (std::size_t k = 0; k < plan.index.size(); ++k)
      domains.image(&xyz_[3 * plan.index[k]], &plan.shift[3 * k], &send[3 * k]);
    std::copy(xyz_.begin(), xyz_.end(), local_xyz_.begin());
    host_transport_->exchange(
        reinterpret_cast<const std::byte*>(send.data()), scaled(plan.send_counts, record).data(),
        offsets_of(plan.send_counts, record).data(),
        reinterpret_cast<std::byte*>(local_xyz_.data() + 3 * n),
        scaled(plan.recv_counts, record).data(), offsets_of(plan.recv_counts, record).data());
  }
  ++stats_.refreshes;
  stats_.bytes_sent = (plan.sent() - plan.send_counts[rank_]) * record;
  stats_.exchange_ms = elapsed_ms(start);
}

// Owned rows only, exactly: the self pair (i, i, 0) must never reach a kernel (Lennard-Jones is
// infinite at r = 0), and a query point does not exclude itself. So the owned particles are
// never sources of the query engine: pairs among owned particles (and their images along local
// axes) come from an engine over them (which excludes (i, i, 0) by index, as a single rank
// does), pairs with halos (and their local images) from the owned particles near a face as
// queries over the halos only. Every pair of an owned target is in exactly one of the two; a
// particle's own images are halos or local images, so (i, i, S != 0) is kept. Counts and lists
// are then exact; kernel sums are two partial sums added.
//
// Only owned particles within cutoff + skin of a face that halos cross (Decomposition::halo_axis:
// not a local axis's, nor the outer face of an open end slab) are queries (the others meet no
// halo): every halo was outside the domain along such an axis at the exchange (local images do
// not move it along the others) and has moved at most skin / 2 since, so an owned particle within
// the cutoff of one is within cutoff + skin / 2 of such a face. The query engine's structure holds
// its queries too (they are candidates it rejects), so fewer queries is most of what makes this
// cheaper than all rows.
void DistributedEngine::select_boundary() {
  const detail::Domains domains = domains_of(decomposition_);
  const detail::Faces faces(domains, rank_);
  // As build_halos(): a hair wide is harmless.
  const double reach = reach_of(decomposition_, halo_width_);
  boundary_.clear();
  boundary_xyz_.clear();
  for (std::size_t i = 0; i < ids_.size(); ++i) {
    if (!faces.near(domains, &xyz_[3 * i], reach)) continue;
    boundary_.push_back(static_cast<std::uint32_t>(i));
    boundary_xyz_.insert(boundary_xyz_.end(), &xyz_[3 * i], &xyz_[3 * i] + 3);
  }
}

void DistributedEngine::build_local_engine(bool same_sources) {
  std::string error;
  ErrorCode code = ErrorCode::internal;
  const auto start = Clock::now();
  try {
    const std::size_t n = ids_.size(), h = halo_count_;
    const PositionsView local = local_positions(split_ ? n : n + h);
    if (same_sources)  // update() checked the owned positions; halos are their images
      raycut::detail::EngineAccess::update_checked(*engine_, local);
    else
      engine_->build(local, cutoff_, local_box_);
    if (split_) select_boundary();
    halo_engine_built_ = split_ && !boundary_.empty() && h > 0;
    if (halo_engine_built_) {  // with query points update() refuses: build again
      Systems systems = Systems::periodic(local_box_);
      systems.queries = {boundary_xyz_.data(), boundary_.size(), MemorySpace::host};
      halo_engine_->build({local_xyz_.data() + 3 * n, h, MemorySpace::host}, cutoff_, systems);
    }
  } catch (const Error& e) {
    error = e.what();
    code = e.code();
  }
  agree(error, code);
  stats_.build_ms = elapsed_ms(start);
  stats_.owned = ids_.size();
  stats_.halos = halo_count_;
  stats_.boundary = split_ ? boundary_.size() : ids_.size();
}

PositionsView DistributedEngine::local_positions(std::size_t count) {
  if (device_) return {device_->local(), count, MemorySpace::device};
  return {local_xyz_.data(), count, MemorySpace::host};
}

const std::vector<float>& DistributedEngine::positions() const {
  if (device_ && !host_positions_) {
    device_->download_reference(xyz_);
    host_positions_ = true;
  }
  return xyz_;
}

void DistributedEngine::fetch_halos() const {
  if (device_ && !host_halos_) {
    device_->download_halos(halo_ids_, halo_shifts_);
    host_halos_ = true;
  }
}

const std::vector<std::uint64_t>& DistributedEngine::halo_ids() const {
  fetch_halos();
  return halo_ids_;
}

const std::vector<std::int32_t>& DistributedEngine::halo_shifts() const {
  fetch_halos();
  return halo_shifts_;
}

const std::vector<float>& DistributedEngine::carried() const {
  if (device_ && !host_carried_) {
    device_->download_carried(carried_);
    host_carried_ = true;
  }
  return carried_;
}

PositionsView DistributedEngine::owned_positions() const {
  if (device_) return {device_->local(), ids_.size(), MemorySpace::device};
  return {xyz_.data(), ids_.size(), MemorySpace::host};
}

const float* DistributedEngine::owned_carried() const {
  return device_ ? device_->carried() : carried_.data();
}

// ---- results ------------------------------------------------------------------------------------

ResultsView DistributedEngine::run(Kernel kernel, const KernelOptions& options) {
  check_built("run");
  refuse_inputs_without_fields(kernel);
  if (split_ && halo_engine_built_) {  // two engines' rows added: on the host
    summed_ = compute(kernel, options);
    const auto data = [](const auto& v) { return v.empty() ? nullptr : v.data(); };
    return {data(summed_.count),  data(summed_.energy),  data(summed_.force),
            data(summed_.virial), data(summed_.density), MemorySpace::host};
  }
  engine_->run(kernel, options);
  return engine_->results_view();
}

Results DistributedEngine::compute(Kernel kernel, const KernelOptions& options) {
  check_built("compute");
  refuse_inputs_without_fields(kernel);
  Results r = engine_->compute(kernel, options);
  const std::size_t n = ids_.size();
  if (!split_) {  // rows past n are the halos'
    auto keep = [n](auto& v, std::size_t per) {
      if (!v.empty()) v.resize(per * n);
    };
    keep(r.count, 1);
    keep(r.energy, 1);
    keep(r.force, 3);
    keep(r.virial, 6);
    keep(r.density, 1);
  } else if (halo_engine_built_) {
    const Results halo = halo_engine_->compute(kernel, options);
    // Query row b is owned row boundary_[b].
    auto add = [this](auto& into, const auto& from, std::size_t per) {
      for (std::size_t b = 0; b < boundary_.size(); ++b)
        for (std::size_t k = 0; k < per; ++k) into[per * boundary_[b] + k] += from[per * b + k];
    };
    add(r.count, halo.count, halo.count.empty() ? 0 : 1);
    add(r.energy, halo.energy, halo.energy.empty() ? 0 : 1);
    add(r.force, halo.force, halo.force.empty() ? 0 : 3);
    add(r.virial, halo.virial, halo.virial.empty() ? 0 : 6);
    add(r.density, halo.density, halo.density.empty() ? 0 : 1);
  }
  return r;
}

// sph_force's fields: given where this call needs them (compute(): host arrays, which a method
// that works in device memory cannot take; run() of a device-resident engine: device arrays),
// and none null on a rank with owned particles. Collective.
void DistributedEngine::check_sph_fields(const SphFields& owned, bool device) {
  std::string error;
  ErrorCode code = ErrorCode::invalid_argument;
  if (!device && engine_->space() != MemorySpace::host) {
    error = "distributed sph_force: method '" + engine_->method() +
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

ResultsView DistributedEngine::run(Kernel kernel, const KernelOptions& options,
                                   const SphFields& owned) {
  check_built("run");
  if (kernel != Kernel::sph_force) return run(kernel, options);
  if (!device_) {  // the host path, its rows kept for the view
    summed_ = compute(kernel, options, owned);
    return {nullptr, nullptr, summed_.force.data(), nullptr, nullptr, MemorySpace::host};
  }
  check_sph_fields(owned, true);
  // One local engine over owned + halos (all rows): the fields in its order, on the GPU. A rank
  // that neither sends nor receives halos takes no part in the transports' exchanges (they move
  // between pairs with something to move), so it passes the owned fields as given.
  KernelOptions with_fields = options;
  with_fields.sph = {owned.velocity, owned.density, owned.pressure};
  if (halo_count_ > 0 || plan_->sent() > 0) {
    const std::size_t local = ids_.size() + halo_count_;
    float* velocity = device_->scratch(5 * local);
    float* density = velocity + 3 * local;
    float* pressure = density + local;
    device_halo_fields(owned.velocity, 3, velocity);
    device_halo_fields(owned.density, 1, density);
    device_halo_fields(owned.pressure, 1, pressure);
    with_fields.sph = {velocity, density, pressure};
  }
  engine_->run(kernel, with_fields);
  return engine_->results_view();
}

// halo_fields() of a device-resident engine, device arrays: the owned values, then the halos'
// copies sent along the same plan by the refreshes' transport (GPU to GPU, or staged).
void DistributedEngine::device_halo_fields(const float* owned, std::size_t width, float* local) {
  const std::size_t n = ids_.size();
  device_->copy(local, owned, n * width * sizeof(float));
  exchange_on_device(device_->gather_fields(owned, width), width * sizeof(float),
                     local + width * n);
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

void DistributedEngine::halo_fields(const float* owned, std::size_t width, float* local) {
  check_field_width("halo_fields", owned, width);
  std::string error;
  ErrorCode code = ErrorCode::unsupported;
  if (!device_) {
    error =
        "distributed halo_fields: device arrays need a device-resident engine (built from device "
        "positions); give host arrays to halo_fields(owned, width)";
  } else if (width > 0 && ids_.size() + halo_count_ > 0 && local == nullptr) {
    error = "distributed halo_fields: null local values";
    code = ErrorCode::invalid_argument;
  }
  agree(error, code);
  if (width > 0) device_halo_fields(owned, width, local);
}

DistributedEngine::DeviceIds DistributedEngine::device_ids() const {
  if (!device_) return {};
  return {device_->ids(), device_->halo_ids(), device_->halo_shifts()};
}

std::vector<float> DistributedEngine::halo_fields(const float* owned, std::size_t width) {
  check_field_width("halo_fields", owned, width);
  const std::size_t n = ids_.size(), h = halo_count_;
  std::vector<float> local(width * (n + h));
  if (width == 0) return local;
  if (device_) {  // the plan is on the GPU: through it, owned values in, owned + halos out
    float* in = device_->scratch(width * (2 * n + h));
    device_->copy(in, owned, width * n * sizeof(float));
    device_halo_fields(in, width, in + width * n);
    device_->copy(local.data(), in + width * n, local.size() * sizeof(float));
    return local;
  }
  std::copy(owned, owned + width * n, local.begin());
  const HaloPlan& plan = *plan_;
  std::vector<float> send(width * plan.index.size());
  for (std::size_t k = 0; k < plan.index.size(); ++k)
    std::copy_n(owned + width * plan.index[k], width, &send[width * k]);
  const std::size_t record = width * sizeof(float);
  host_transport_->exchange(
      reinterpret_cast<const std::byte*>(send.data()), scaled(plan.send_counts, record).data(),
      offsets_of(plan.send_counts, record).data(),
      reinterpret_cast<std::byte*>(local.data() + width * n),
      scaled(plan.recv_counts, record).data(), offsets_of(plan.recv_counts, record).data());
  return local;
}

Results DistributedEngine::compute(Kernel kernel, const KernelOptions& options,
                                   const SphFields& owned) {
  check_built("compute");
  if (kernel != Kernel::sph_force) return compute(kernel, options);
  const std::size_t n = ids_.size();
  check_sph_fields(owned, false);

  // The three fields in one exchange: 5 floats per particle.
  std::vector<float> packed(5 * n);
  for (std::size_t i = 0; i < n; ++i) {
    std::copy_n(owned.velocity + 3 * i, 3, &packed[5 * i]);
    packed[5 * i + 3] = owned.density[i];
    packed[5 * i + 4] = owned.pressure[i];
  }
  const std::vector<float> local = halo_fields(packed.data(), 5);
  const std::size_t m = local.size() / 5;
  std::vector<float> velocity(3 * m), density(m), pressure(m);
  for (std::size_t i = 0; i < m; ++i) {
    std::copy_n(&local[5 * i], 3, &velocity[3 * i]);
    density[i] = local[5 * i + 3];
    pressure[i] = local[5 * i + 4];
  }
  KernelOptions with_fields = options;
  with_fields.sph = {velocity.data(), density.data(), pressure.data()};

  // The single-rank kernel over the owned rows through raycut::mpi::for_each_pair (either
  // scheme): its sources in the local order of the fields.
  Results r;
  r.force.assign(3 * n, 0.0f);
  KernelOutputs out;
  out.force = r.force.data();
  if (n == 0) return r;  // a rank the particles left: no rows (and no output to point at)
  with_kernel(Kernel::sph_force, with_fields, squared_cutoff(cutoff_), out, [&](const auto& f) {
    if constexpr (std::is_same_v<std::decay_t<decltype(f)>, SphForceKernel>)
      for_each_pair(*this, f);
  });
  return r;
}

DistributedList DistributedEngine::neighbours(const ListOptions& options) {
  check_built("neighbours");
  ListOptions local = options;
  local.half = false;   // oriented here by global index
  local.shifts = true;  // along the local axes: added to the halo's
  local.coo = false;    // the local rows are read as CSR; DistributedList has global indices
  const NeighbourList list = engine_->neighbours(local);
  NeighbourList halo_list;
  if (halo_engine_built_) halo_list = halo_engine_->neighbours(local);
  const std::size_t n = ids_.size();
  const std::vector<std::uint64_t>& halo_ids = this->halo_ids();
  const std::vector<std::int32_t>& halo_shifts = this->halo_shifts();
  // Local slot j of the engine over owned (+ halos): owned below n, else halo j - n. A pair's S
  // is the halo's (axes with images) plus the engine's (local axes, relative to the positions it
  // was given): r = (x_j + S_halo . cell) + S_local . cell - x_i.
  DistributedList out;
  out.targets = ids_;
  out.offsets.assign(n + 1, 0);
  auto emit = [&](std::size_t i, const NeighbourList& from, std::uint64_t e, std::size_t j) {
    const std::uint64_t id = j < n ? ids_[j] : halo_ids[j - n];
    std::int32_t s[3];
    for (int c = 0; c < 3; ++c)
      s[c] = from.shifts[3 * e + c] + (j < n ? 0 : halo_shifts[3 * (j - n) + c]);
    if (options.half) {
      const Shift shift{s[0], s[1], s[2]};
      if (id < ids_[i] || (id == ids_[i] && !shift.positive())) return;
    }
    out.indices.push_back(id);
    if (options.distances) out.distances.push_back(from.distances[e]);
    if (options.vectors)
      out.vectors.insert(out.vectors.end(), &from.vectors[3 * e], &from.vectors[3 * e] + 3);
    if (options.shifts) out.shifts.insert(out.shifts.end(), s, s + 3);
  };
  std::size_t b = 0;  // the next query row: boundary_ ascends
  for (std::size_t i = 0; i < n; ++i) {
    for (std::uint64_t e = list.offsets[i]; e < list.offsets[i + 1]; ++e)
      emit(i, list, e, list.indices[e]);
    if (halo_engine_built_ && b < boundary_.size() && boundary_[b] == i) {
      for (std::uint64_t e = halo_list.offsets[b]; e < halo_list.offsets[b + 1]; ++e)
        emit(i, halo_list, e, n + halo_list.indices[e]);
      ++b;
    }
    out.offsets[i + 1] = out.indices.size();
  }
  return out;
}

}  // namespace raycut::mpi
