// ParaView output of an SPH run: one VTK XML PolyData file (.vtp) per saved frame with the points,
// a vertex cell per point (so ParaView draws them without a filter) and the point arrays velocity,
// density and pressure; and a .pvd collection that lists the frames with their times.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace raycut::sph {

enum class VtkEncoding {
  binary,  // format="appended", encoding="raw", header_type="UInt64": 40 bytes per particle
  ascii,   // format="ascii": readable, about 4x larger and slower; for debugging
};

class VtkSeries {
 public:
  // Frames go to dir/basename_000000.vtp, dir/basename_000001.vtp, ... and the collection to
  // dir/basename.pvd. Creates dir if needed. Throws raycut::Error (io) naming the path.
  VtkSeries(std::string dir, std::string basename, VtkEncoding encoding = VtkEncoding::binary);

  // Writes the next frame: xyz and vel are (n, 3) row-major, rho and p have n values; all must be
  // non-null when n > 0. The .pvd is rewritten after every frame, so an interrupted run still
  // opens in ParaView up to its last frame. Throws raycut::Error (io, or invalid_argument for null
  // arrays or a time that is not finite).
  void write_frame(double time, const float* xyz, const float* vel, const float* rho,
                   const float* p, std::size_t n);

  // Paths written so far, in order.
  const std::vector<std::string>& frame_paths() const { return frame_paths_; }
  std::string pvd_path() const;

 private:
  void write_pvd() const;

  std::string dir_;
  std::string basename_;
  VtkEncoding encoding_;
  std::vector<double> times_;
  std::vector<std::string> frame_paths_;
};

// Writes one frame as a standalone .vtp file (what VtkSeries::write_frame does per frame).
void write_vtp(const std::string& path, const float* xyz, const float* vel, const float* rho,
               const float* p, std::size_t n, VtkEncoding encoding = VtkEncoding::binary);

}  // namespace raycut::sph
