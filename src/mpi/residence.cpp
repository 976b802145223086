// The two residences (residence.hpp): host arrays, or the GPU's (device_residence.hpp) with host
// copies made when asked.
#include "mpi/residence.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "raycut/error.hpp"

namespace raycut::mpi::detail {
namespace {

// [id][image xyz][shift]: a halo record of a new plan.
constexpr std::size_t halo_record =
    sizeof(std::uint64_t) + 3 * sizeof(float) + 3 * sizeof(std::int32_t);

class HostResidence final : public Residence {
 public:
  MemorySpace space() const override { return MemorySpace::host; }

  void adopt(const float* xyz, const float* carried, const std::uint64_t*, std::size_t n,
             std::size_t width) override {
    width_ = width;
    xyz_.assign(xyz, xyz + 3 * n);
    if (carried)
      carried_.assign(carried, carried + width * n);
    else
      carried_.clear();
  }

  const std::vector<float>& positions() const override { return xyz_; }
  const std::vector<float>& carried() const override { return carried_; }
  const std::vector<std::uint64_t>& halo_ids() const override { return halo_ids_; }
  const std::vector<std::int32_t>& halo_shifts() const override { return halo_shifts_; }
  PositionsView owned_positions(std::size_t owned) const override {
    return {xyz_.data(), owned, MemorySpace::host};
  }
  const float* owned_carried() const override { return carried_.data(); }
  PositionsView local_positions(std::size_t count) override {
    return {local_xyz_.data(), count, MemorySpace::host};
  }
  DistributedEngine::DeviceIds device_ids() const override { return {}; }

  Moves check_moves(const float* xyz, const float*, double distance) override {
    const std::size_t n = owned();
    double moved2 = 0;
    for (std::size_t i = 0; i < n; ++i) {
      double d2 = 0;
      for (int c = 0; c < 3; ++c) {
        const float v = xyz[3 * i + c];
        if (!std::isfinite(v)) return {i, false};
        const double d = static_cast<double>(v) - reference_[3 * i + c];
        d2 += d * d;
      }
      moved2 = std::max(moved2, d2);
    }
    return {n, moved2 > distance * distance};
  }
  void accept(const float* xyz, const float* carried) override {
    std::copy(xyz, xyz + xyz_.size(), xyz_.begin());
    if (carried) std::copy(carried, carried + carried_.size(), carried_.begin());
  }

  void set_domains(const Domains& domains) override { domains_ = domains; }
  void wrap() override {
    const auto n = static_cast<std::ptrdiff_t>(owned());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < n; ++i) domains_.wrap(&xyz_[3 * i]);
  }
  const std::vector<float>& current_positions() override {
    return xyz_;
  }
  void find_owners(int rank, int size, Leaving& leaving) override {
    leaving_on_host(domains_, rank, size, xyz_, carried_, width_, leaving);
  }
  void keep_staying(const std::vector<std::uint32_t>& gone, const std::vector<float>& xyz,
                    const std::vector<float>& carried, const std::vector<std::uint64_t>&) override {
    remove_rows(xyz_, 3, gone);
    remove_rows(carried_, width_, gone);
    xyz_.insert(xyz_.end(), xyz.begin(), xyz.end());
    carried_.insert(carried_.end(), carried.begin(), carried.end());
  }

  std::size_t build_halos(Exchange& exchange, const std::vector<std::uint64_t>& ids,
                          double reach) override {
    HaloPlan& plan = exchange.plan();
    const std::size_t n = owned();
    plan_halos_on_host(domains_, exchange.rank(), exchange.size(), reach, xyz_, plan);
    plan.recv_counts = exchange.counts(plan.send_counts);
    const std::uint64_t received = plan.received();
    std::vector<std::byte> send(plan.index.size() * halo_record), recv(received * halo_record);
    std::byte* at = send.data();
    for (std::size_t k = 0; k < plan.index.size(); ++k) {
      float image[3];  // x + S . cell
      domains_.image(&xyz_[3 * plan.index[k]], &plan.shift[3 * k], image);
      put(at, &ids[plan.index[k]], 1);
      put(at, image, 3);
      put(at, &plan.shift[3 * k], 3);
    }
    exchange.along_plan_on_host(send.data(), recv.data(), halo_record);
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
    reference_ = xyz_;
    return received;
  }

  void refresh_halos(Exchange& exchange) override {
    const HaloPlan& plan = exchange.plan();
    std::vector<float> send(3 * plan.index.size());
    for (std::size_t k = 0; k < plan.index.size(); ++k)
      domains_.image(&xyz_[3 * plan.index[k]], &plan.shift[3 * k], &send[3 * k]);
    std::copy(xyz_.begin(), xyz_.end(), local_xyz_.begin());
    exchange.along_plan_on_host(send.data(), local_xyz_.data() + xyz_.size(), 3 * sizeof(float));
  }

  void halo_fields(Exchange& exchange, const float* owned_values, std::size_t width,
                   float* local) override {
    const std::size_t n = owned();
    std::copy(owned_values, owned_values + width * n, local);
    const HaloPlan& plan = exchange.plan();
    std::vector<float> send(width * plan.index.size());
    for (std::size_t k = 0; k < plan.index.size(); ++k)
      std::copy_n(owned_values + width * plan.index[k], width, &send[width * k]);
    exchange.along_plan_on_host(send.data(), local + width * n, width * sizeof(float));
  }
  void halo_fields_on_host(Exchange& exchange, const float* owned_values, std::size_t width,
                           float* local) override {
    halo_fields(exchange, owned_values, width, local);
  }

  // The three fields in one exchange: 5 floats per particle.
  SphInputs sph_fields(Exchange& exchange, const SphFields& fields) override {
    const std::size_t n = owned(), m = n + halo_ids_.size();
    std::vector<float> packed(5 * n), local(5 * m);
    for (std::size_t i = 0; i < n; ++i) {
      std::copy_n(fields.velocity + 3 * i, 3, &packed[5 * i]);
      packed[5 * i + 3] = fields.density[i];
      packed[5 * i + 4] = fields.pressure[i];
    }
    halo_fields(exchange, packed.data(), 5, local.data());
    velocity_.resize(3 * m);
    density_.resize(m);
    pressure_.resize(m);
    for (std::size_t i = 0; i < m; ++i) {
      std::copy_n(&local[5 * i], 3, &velocity_[3 * i]);
      density_[i] = local[5 * i + 3];
      pressure_[i] = local[5 * i + 4];
    }
    return {velocity_.data(), density_.data(), pressure_.data()};
  }

 private:
  std::size_t owned() const {
    return xyz_.size() / 3;
  }

  std::size_t width_ = 0;
  std::vector<float> xyz_, carried_;
  std::vector<float> reference_;  // the owned positions at the last exchange: the skin's
  std::vector<float> local_xyz_;  // owned then halos: what the local engines are built over
  std::vector<std::uint64_t> halo_ids_;
  std::vector<std::int32_t> halo_shifts_;
  std::vector<float> velocity_, density_, pressure_;  // sph_fields()'s
  Domains domains_{};
};

// The GPU's arrays (DeviceResidence); host copies made when asked (positions(), carried(),
// halo_ids()) or needed (Balance::particles).
class DeviceResident final : public Residence {
 public:
  explicit DeviceResident(std::unique_ptr<DeviceResidence> device) : device_(std::move(device)) {}

  MemorySpace space() const override { return MemorySpace::device; }

  // Planned on the host like any exchange (from host copies); the GPU keeps them after it.
  void adopt(const float* xyz, const float* carried, const std::uint64_t* ids, std::size_t n,
             std::size_t width) override {
    device_->adopt(xyz, carried, ids, n, width, xyz_, carried_);
    if (width == 0) carried_.clear();
    host_positions_ = host_carried_ = host_halos_ = true;
  }

  const std::vector<float>& positions() const override {
    if (!host_positions_) {
      device_->download_reference(xyz_);
      host_positions_ = true;
    }
    return xyz_;
  }
  const std::vector<float>& carried() const override {
    if (!host_carried_) {
      device_->download_carried(carried_);
      host_carried_ = true;
    }
    return carried_;
  }
  const std::vector<std::uint64_t>& halo_ids() const override {
    fetch_halos();
    return halo_ids_;
  }
  const std::vector<std::int32_t>& halo_shifts() const override {
    fetch_halos();
    return halo_shifts_;
  }
  PositionsView owned_positions(std::size_t owned) const override {
    return {device_->local(), owned, MemorySpace::device};
  }
  const float* owned_carried() const override { return device_->carried(); }
  PositionsView local_positions(std::size_t count) override {
    return {device_->local(), count, MemorySpace::device};
  }
  DistributedEngine::DeviceIds device_ids() const override {
    return {device_->ids(), device_->halo_ids(), device_->halo_shifts()};
  }

  // The same steps on the GPU, in one pass: copy, finite check, skin test.
  Moves check_moves(const float* xyz, const float* carried, double distance) override {
    const auto taken = device_->take(xyz, carried, static_cast<float>(distance));
    return {taken.first_bad, taken.moved};
  }
  void accept(const float*, const float*) override {}

  void set_domains(const Domains& domains) override { device_->set_domains(domains); }
  void wrap() override {
    host_positions_ = host_carried_ = false;
    device_->wrap();
  }
  const std::vector<float>& current_positions() override {
    device_->download(xyz_, carried_);
    return xyz_;
  }
  void find_owners(int rank, int size, Leaving& leaving) override {
    device_->find_owners(rank, size, leaving);
  }
  void keep_staying(const std::vector<std::uint32_t>&, const std::vector<float>& xyz,
                    const std::vector<float>& carried,
                    const std::vector<std::uint64_t>& ids) override {
    device_->keep_staying(xyz, carried, ids);
  }

  // Planned, gathered and received on the GPU, each column along the plan by the payload
  // transport (GPU to GPU, or staged); the halos' ids and shifts come to the host when asked.
  std::size_t build_halos(Exchange& exchange, const std::vector<std::uint64_t>&,
                          double reach) override {
    HaloPlan& plan = exchange.plan();
    device_->plan_halos(exchange.rank(), exchange.size(), reach, plan.send_counts);
    plan.recv_counts = exchange.counts(plan.send_counts);
    std::string error;
    DeviceResidence::HaloSlots slots{};
    try {
      slots = device_->receive_halos(plan.received());
    } catch (const Error& e) {  // no room on this rank: every rank stops before the sends
      error = e.what();
    }
    exchange.agree(error, ErrorCode::out_of_memory);
    along_plan(exchange, device_->gather_ids(), sizeof(std::uint64_t), slots.ids);
    along_plan(exchange, device_->gather(), 3 * sizeof(float), slots.xyz);
    along_plan(exchange, device_->plan_shifts(), 3 * sizeof(std::int32_t), slots.shifts);
    halos_ = plan.received();
    host_halos_ = false;
    return halos_;
  }

  void refresh_halos(Exchange& exchange) override {  // gathered on the GPU
    along_plan(exchange, device_->gather(), 3 * sizeof(float),
               device_->local() + 3 * device_->owned());
  }

  void halo_fields(Exchange& exchange, const float* owned_values, std::size_t width,
                   float* local) override {
    const std::size_t n = device_->owned();
    device_->copy(local, owned_values, n * width * sizeof(float));
    along_plan(exchange, device_->gather_fields(owned_values, width), width * sizeof(float),
               local + width * n);
  }
  // The plan is on the GPU: through it, owned values in, owned + halos out.
  void halo_fields_on_host(Exchange& exchange, const float* owned_values, std::size_t width,
                           float* local) override {
    const std::size_t n = device_->owned();
    float* in = device_->scratch(width * (2 * n + halos_));
    device_->copy(in, owned_values, width * n * sizeof(float));
    halo_fields(exchange, in, width, in + width * n);
    device_->copy(local, in + width * n, width * (n + halos_) * sizeof(float));
  }

  // A rank that neither sends nor receives halos takes no part in the transports' exchanges
  // (they move between pairs with something to move): it passes the owned fields as given.
  SphInputs sph_fields(Exchange& exchange, const SphFields& owned_fields) override {
    if (halos_ == 0 && exchange.plan().sent() == 0)
      return {owned_fields.velocity, owned_fields.density, owned_fields.pressure};
    const std::size_t local = device_->owned() + halos_;
    float* velocity = device_->scratch(5 * local);
    float* density = velocity + 3 * local;
    float* pressure = density + local;
    halo_fields(exchange, owned_fields.velocity, 3, velocity);
    halo_fields(exchange, owned_fields.density, 1, density);
    halo_fields(exchange, owned_fields.pressure, 1, pressure);
    return {velocity, density, pressure};
  }

 private:
  void fetch_halos() const {
    if (!host_halos_) {
      device_->download_halos(halo_ids_, halo_shifts_);
      host_halos_ = true;
    }
  }

  // Per halo record `bytes` from `send` (device, the plan's order) to `recv` (device, the halos'
  // order), along the plan of the last exchange: by the payload transport, GPU to GPU, or
  // staged through the host. Collective over the ranks that send or receive: a rank with
  // neither takes no part (one rank with every periodic axis local: no transport call at all).
  void along_plan(Exchange& exchange, const void* send, std::size_t bytes, void* recv) {
    const HaloPlan& plan = exchange.plan();
    if (plan.sent() == 0 && plan.received() == 0) return;
    if (exchange.payload().space() == MemorySpace::device) {
      const auto send_counts = scaled(plan.send_counts, bytes);
      const auto recv_counts = scaled(plan.recv_counts, bytes);
      exchange.payload().exchange(static_cast<const std::byte*>(send), send_counts.data(),
                                  offsets_of(plan.send_counts, bytes).data(),
                                  static_cast<std::byte*>(recv), recv_counts.data(),
                                  offsets_of(plan.recv_counts, bytes).data());
      return;
    }
    const std::size_t sent_bytes = plan.sent() * bytes, received_bytes = plan.received() * bytes;
    std::byte* sent = device_->staging(0, sent_bytes);
    std::byte* received = device_->staging(1, received_bytes);
    device_->copy(sent, send, sent_bytes);
    exchange.along_plan_on_host(sent, received, bytes);
    device_->copy(recv, received, received_bytes);
  }

  std::unique_ptr<DeviceResidence> device_;
  std::size_t halos_ = 0;
  // Host copies, current while their flags say so.
  mutable std::vector<float> xyz_, carried_;
  mutable std::vector<std::uint64_t> halo_ids_;
  mutable std::vector<std::int32_t> halo_shifts_;
  mutable bool host_positions_ = true, host_carried_ = true, host_halos_ = true;
};

}  // namespace

std::unique_ptr<Residence> make_host_residence() {
  return std::make_unique<HostResidence>();
}

// Asked for by methods that work on the device only, which builds without CUDA do not have.
std::unique_ptr<Residence> make_device_resident() {
#if defined(RAYCUT_HAVE_CUDA)
  return std::make_unique<DeviceResident>(make_device_residence());
#else
  throw Error(ErrorCode::internal, "a device-resident engine in a build without CUDA");
#endif
}

}  // namespace raycut::mpi::detail
