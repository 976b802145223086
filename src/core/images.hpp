// Periodic boxes, batches and query points at the engine level (docs/periodic.md): the
// caller's particles become one set of points that any method with a pair pass builds over as
// if it were an open cloud, with tables that map each point back to the caller's source and
// image shift (detail/images.hpp applies them in every traversal). So every such method gets
// thin boxes, self-images, unwrapped positions, batches and query sets from one implementation.
//
// The points, in this order (deterministic):
//   targets  the caller's particles (or the query points), each wrapped into its system's cell;
//   sources  with query points only: the caller's particles, wrapped;
//   images   for each particle in the caller's order, its images n != 0 (n in lexicographic
//            order) that can lie within the cutoff of its cell (core/image_frame.hpp).
// Point k has image[k] = {source (the caller's index; not_a_source for a query), shift T_k},
// the point being x_source + T_k . cell (minus its system's frame origin); a pair (i, k) has
// S = T_k - T_i. Batches add system[k]; each system sits in its own frame, near the origin.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/image_frame.hpp"
#include "core/method.hpp"
#include "raycut/engine.hpp"

namespace raycut::detail {

// What the expansion needs, checked and derived on the host from Systems.
struct ImagePlan {
  std::vector<ImageFrame> frames;      // per system
  std::vector<std::uint64_t> sources;  // S + 1 offsets of the systems' particles
  std::vector<std::uint64_t> queries;  // S + 1 offsets of their queries; empty: none
  bool own_frames = false;             // batches: each system in its own frame
  double cutoff = 0;
  std::uint32_t systems() const { return static_cast<std::uint32_t>(frames.size()); }
  bool has_queries() const { return !queries.empty(); }
  std::size_t source_count() const { return sources.back(); }
  std::size_t target_count() const { return has_queries() ? queries.back() : sources.back(); }
};

// Validates `systems` for `sources` particles (offsets, box count, each Box) and the cutoff
// against each box (image counts); throws Error(invalid_argument) naming what is wrong.
ImagePlan plan_images(const Systems& systems, std::size_t sources, double cutoff);

// The points a method builds over, owned by the engine while the build lives; expand() reuses
// the buffers of the previous call (they only grow), so a step loop allocates once.
class ImagePoints {
 public:
  virtual ~ImagePoints() = default;
  virtual MemorySpace space() const = 0;
  // `sources` (and `queries`) in space(); GPU work queued on `stream` (a cudaStream_t). The
  // device expansion checks that the sources are finite (throw_non_finite) in its first pass.
  virtual void expand(const ImagePlan& plan, const float* sources, const float* queries,
                      void* stream) = 0;
  const Points& points() const { return points_; }
  // The caller's positions in double, of which the next expand()'s sources are the float
  // rounding (Engine::build(Float64Positions)); null: the sources as given. The host expansion
  // wraps and decides pairs from them; the device one searches the floats.
  void set_float64_sources(const double* xyz) { float64_sources_ = xyz; }

  // Engine::set_reuse_plan (the device expansion; the host one never records). set_recording()
  // forgets the plan recorded last; with recording on, expand() keeps its sizes (room for 1/8 more
  // images, the float band's extent) and says so in Points::reuse; the engine then gives the
  // method's parking place. expand_reusing() expands into those sizes with no read-back: image
  // slots past the real ones hold the parking place, and what no longer fits goes to a device word
  // (Points::reuse.misfit) that the method checks too; finish_reusing() queues that word's copy to
  // the host after the method's build.
  virtual void set_recording(bool) {}
  virtual void set_parking(const ParkingPlace&) {}
  virtual bool recorded() const { return false; }  // a recorded plan, with its parking place
  virtual void expand_reusing(const ImagePlan& plan, const float* sources, const float* queries,
                              void* stream);
  virtual void finish_reusing(void*) {}
  // Whether the last expand_reusing() found that the plan no longer fits (the plan is then
  // forgotten): false while the device has not yet said (wait: waits for it), and while `stream` is
  // being captured into a CUDA graph (a captured build's verdict reaches only its list's count).
  virtual bool reused_plan_outgrown(void* /*stream*/, bool /*wait*/) { return false; }

 protected:
  // What points() hands the method after an expansion into these arrays.
  void publish(const ImagePlan& plan, const float* xyz, std::size_t size, const PointImage* image,
               const std::uint32_t* system, const ExactImages* exact,
               const std::uint32_t* image_counts = nullptr, Points::PlanReuse reuse = {}) {
    points_.xyz = xyz;
    points_.size = size;
    points_.targets = plan.target_count();
    points_.images = {image, nullptr, !plan.has_queries(), exact, image_counts};
    points_.systems = plan.systems();
    points_.system = plan.systems() > 1 ? system : nullptr;
    points_.reuse = reuse;
  }
  const double* float64_sources_ = nullptr;

 private:
  Points points_;
};

// The float band of points with images (ExactImages), set the same way by the host and the
// device expansions.
//
// How far a float point may lie from its real position when its coordinates are at most
// `extent` in magnitude: the float rounding (half an ulp, <= 2^-24 extent), doubled for the
// double arithmetic before it (x - W . cell, far below a float ulp for any position the int32
// shifts allow).
double rounding_bound(double extent);
// exact's band [float_in, float_out) of r2 around C^2 where the float predicate may misjudge a
// pair (float_band_slack), rounded outwards to floats; its cutoff_squared, rounding and
// exact_vectors (points off by more than 2^-16 C: every pair from the double vector, and
// float_in 0).
void set_float_band(ExactImages& exact, double cutoff, double rounding);
// The radius within which a search must offer candidates for the band decision to see every
// pair it may take: sqrt(float_out), with a margin above the float rounding of a distance.
// Cells at least this wide (CPU cell list, GPU grid).
double band_reach(const ExactImages& exact);

// The expansion on the host (positions in host memory).
std::unique_ptr<ImagePoints> make_host_image_points();

// Why `points` points cannot be indexed with 32 bits (empty when they can), for the error.
std::string too_many_points(std::uint64_t points, std::size_t targets);

}  // namespace raycut::detail
