// Velocity Verlet's two halves on the GPU, for lj_md --device (verlet.cu): arrays in device
// memory, 3 floats a particle, unit mass. What an MD code's own integrator kernels do beside a
// device-resident raycut::mpi::DistributedEngine.
#pragma once

#include <cstddef>

namespace lj_md {

// v_out = v + half f, x_out = x + dt v_out.
void kick_drift(const float* x, const float* v, const float* f, std::size_t n, float half, float dt,
                float* x_out, float* v_out);
// v_out = v + half f.
void kick(const float* v, const float* f, std::size_t n, float half, float* v_out);

// A device array of floats, grown as needed (contents not kept).
class DeviceFloats {
 public:
  DeviceFloats() = default;
  ~DeviceFloats();
  DeviceFloats(const DeviceFloats&) = delete;
  DeviceFloats& operator=(const DeviceFloats&) = delete;
  float* resize(std::size_t count);
  float* data() const { return data_; }
  // count floats from the host, or from device memory, after a resize(count).
  void upload(const float* host, std::size_t count);
  void copy(const float* device, std::size_t count);
  void download(float* host, std::size_t count) const;

 private:
  float* data_ = nullptr;
  std::size_t capacity_ = 0;
};

// Whether a CUDA device is there to run on.
bool have_device();

}  // namespace lj_md
