// The owned particles' SPH state of a device-resident raycut::mpi::SphSolver (sph.cpp), in
// device memory: positions, velocities, densities, pressures, the fixed flags of the weakly
// compressible mode, and their packing into the floats the engine carries on migration. The
// per-particle steps are sph::device's (src/sph/device_steps.cu), the single solver's. Defined in
// sph_device.cu, only in builds with CUDA; host-only interface, default stream.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "sph/physics.hpp"

namespace raycut::mpi::detail {

class SphDevice {
 public:
  virtual ~SphDevice() = default;
  // Host arrays in: n particles (3, 3 and, when `with_fixed`, 1 float each).
  virtual void upload(const std::vector<float>& x, const std::vector<float>& v,
                      const std::vector<float>& fixed, bool with_fixed) = 0;
  // After an exchange: the engine's owned positions and carried floats (device, width() each).
  virtual void take(const float* positions, const float* carried, std::size_t n) = 0;
  // Velocity (and fixed flag) packed, width() floats per particle, for update()/build().
  virtual const float* pack() = 0;
  virtual std::size_t width() const = 0;
  virtual std::size_t size() const = 0;
  virtual float* x() = 0;
  virtual float* v() = 0;
  virtual float* rho() = 0;
  virtual float* p() = 0;
  virtual const float* fixed() const = 0;  // null without fixed particles
  // sph::device's steps over the owned particles: rho, p from the engine's neighbour sums
  // (device, or null: none); walls, gravity and the Euler step with the force pass's forces
  // (synchronised: the step's work is done when it returns).
  virtual void density_and_pressure(const float* neighbour_density,
                                    const sph::StepConstants& c) = 0;
  virtual void integrate(const float* force, const sph::StepConstants& c) = 0;
  // x, v, rho, p to the host.
  virtual void download(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                        std::vector<float>& p) const = 0;
};

std::unique_ptr<SphDevice> make_sph_device();

}  // namespace raycut::mpi::detail
