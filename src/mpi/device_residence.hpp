// The device side of a device-resident DistributedEngine (positions given in device memory):
// what the local engine is built over and what a step touches, kept on the GPU so that a step
// with a skin is the plain engine's build + pass plus a displacement test and the halo refresh.
// Exchanges (migration, new halo sets: rare with a skin) stay planned on the host, from a copy of
// the owned positions (docs/distributed.md, "The device-resident path"). Defined in
// device_residence.cu, only in builds with CUDA; host-only interface. Every call queues on the
// legacy default stream, the local engines' (DistributedEngine never sets a stream).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace raycut::mpi::detail {

class DeviceResidence {
 public:
  virtual ~DeviceResidence() = default;

  // build(): copies of the owned positions and carried floats given in device memory (width
  // floats per particle), and the same to the host (planned on there, then upload()ed).
  virtual void adopt(const float* xyz, const float* carried, std::size_t owned, std::size_t width,
                     std::vector<float>& host_xyz, std::vector<float>& host_carried) = 0;
  // After an exchange: the local positions (owned, then halos; 3 floats each), the owned
  // particles' carried floats, and the halo plan (per record the owned index and the image shift
  // S, 3 int32, in send order; images are x + S . cell, cell rows as in Decomposition::cell).
  // The owned positions become the skin's reference.
  virtual void upload(const std::vector<float>& local_xyz, std::size_t owned,
                      const std::vector<float>& carried, const std::vector<std::uint32_t>& index,
                      const std::vector<std::int32_t>& shift,
                      const std::array<std::array<double, 3>, 3>& cell) = 0;
  // Before an exchange: the owned positions and carried floats to the host.
  virtual void download(std::vector<float>& xyz, std::vector<float>& carried) const = 0;
  // update(): the new owned positions (device, 3 per owned particle) and carried floats
  // (device, or null: kept), in one pass that also finds the first non-finite coordinate and
  // whether a particle is more than `distance` from its place at the last upload(). With a
  // non-finite coordinate nothing is taken (the engine keeps its positions).
  struct Taken {
    std::size_t first_bad;  // index of the first owned particle with a non-finite coordinate,
                            // or owned() when none
    bool moved;             // some particle moved more than `distance`
  };
  virtual Taken take(const float* xyz, const float* carried, float distance) = 0;
  // The plan's halo records at the owned particles' current positions (3 floats each, x + S .
  // cell in double rounded to float, as the host makes its halo copies), in a device buffer.
  virtual const float* gather() = 0;
  // Received halo positions from the host (3 floats per halo) into the local array.
  virtual void upload_halos(const float* xyz) = 0;
  // The gathered records to the host (3 floats each).
  virtual void download_gathered(std::vector<float>& xyz) const = 0;

  virtual std::size_t owned() const = 0;
  // Owned positions then halos: 3 (owned + halos) floats.
  virtual float* local() = 0;
  virtual const float* carried() const = 0;
};

// Only in builds with CUDA (device_residence.cu).
std::unique_ptr<DeviceResidence> make_device_residence();

}  // namespace raycut::mpi::detail
