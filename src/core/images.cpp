#include "core/images.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "core/method.hpp"
#include "core/validation.hpp"
#include "raycut/box.hpp"
#include "raycut/detail/images.hpp"
#include "raycut/host_memory.hpp"

namespace raycut::detail {
namespace {

// Images are kept a little beyond the cutoff: f is computed in double (error ~1e-16), the
// predicate in float on the rounded points; this margin covers both with room to spare.
constexpr double reach_margin = 1e-4;

[[noreturn]] void refuse(const std::string& what) {
  throw Error(ErrorCode::invalid_argument, what);
}

// offsets (S + 1 entries, 0 to total, non-decreasing), or {0, total} for one system.
std::vector<std::uint64_t> checked_offsets(const std::vector<std::uint64_t>& offsets,
                                           std::size_t systems, std::size_t total, const char* name,
                                           const char* what) {
  if (offsets.empty()) return {0, total};
  if (offsets.size() != systems + 1)
    refuse(std::string(name) + " has " + std::to_string(offsets.size()) + " entries; " +
           std::to_string(systems + 1) + " expected (one per system, plus one)");
  if (offsets.front() != 0)
    refuse(std::string(name) + "[0] must be 0, got " + std::to_string(offsets.front()));
  for (std::size_t s = 0; s + 1 < offsets.size(); ++s)
    if (offsets[s + 1] < offsets[s])
      refuse(std::string(name) + " decreases at system " + std::to_string(s) + ": " +
             std::to_string(offsets[s]) + " then " + std::to_string(offsets[s + 1]));
  if (offsets.back() != total)
    refuse(std::string(name) + " must end at the number of " + what + " (" + std::to_string(total) +
           "), got " + std::to_string(offsets.back()));
  return offsets;
}

// A system's frame; errors name the system in a batch.
ImageFrame frame_of(const Box& box, double cutoff, std::size_t system, bool batch) {
  ImageFrame frame;
  std::memset(static_cast<void*>(&frame), 0, sizeof frame);  // padding too: compared bytewise
  try {
    const auto g = reciprocal_rows(box);  // validates the box
    image_range(box, cutoff);             // refuses cells far too thin for the cutoff
    for (int k = 0; k < 3; ++k) {
      frame.pbc[k] = box.pbc[k];
      for (int c = 0; c < 3; ++c) {
        frame.cell[k][c] = box.cell[k][c];
        frame.reciprocal[k][c] = g[k][c];
      }
      if (box.pbc[k]) frame.reach[k] = cutoff / face_width(box, k) * (1 + reach_margin);
    }
  } catch (const Error& e) {
    if (!batch) throw;
    throw Error(e.code(), "system " + std::to_string(system) + ": " + e.what());
  }
  return frame;
}

class HostImagePoints final : public ImagePoints {
 public:
  MemorySpace space() const override { return MemorySpace::host; }
  void expand(const ImagePlan& plan, const float* sources, const float* queries, void*) override;

 private:
  std::vector<float> xyz_;
  std::vector<PointImage> image_;
  std::vector<std::uint32_t> system_;
  std::vector<WrappedPoint> wrapped_;
  std::vector<std::uint64_t> image_offset_;
  std::vector<std::uint32_t> image_counts_;  // by source (ImageTables::image_counts)
  // What decides the pairs in double: the caller's positions, kept while the build lives.
  std::vector<float> sources_, queries_;
  std::vector<double> sources64_;
  std::vector<double> cells_;
  ExactImages exact_;
};

template <class Real>
[[noreturn]] void refuse_wrap(std::size_t index, const Real* x, const char* what) {
  refuse(std::string(what) + " " + std::to_string(index) + " at (" + std::to_string(x[0]) + ", " +
         std::to_string(x[1]) + ", " + std::to_string(x[2]) +
         ") lies more than 2^31 boxes away: its image shift leaves the int32 range");
}

void HostImagePoints::expand(const ImagePlan& plan, const float* sources, const float* queries,
                             void*) {
  const double* float64 = float64_sources_;
  const std::uint32_t systems = plan.systems();
  const std::size_t n = plan.source_count(), targets = plan.target_count();
  const bool with_queries = plan.has_queries();
  std::vector<ImageFrame> frames = plan.frames;
  // Batches: each system in its own frame. float64 sources too (one system as well): their
  // float points then span the system rather than its distance from the origin, so the band
  // decided in double, and the cells it widens, stay narrow (geographic or far-offset clouds).
  if (plan.own_frames || float64)
    for (std::uint32_t s = 0; s < systems; ++s) {
      if (plan.sources[s] < plan.sources[s + 1])
        float64 ? system_origin(frames[s], float64 + 3 * plan.sources[s])
                : system_origin(frames[s], sources + 3 * plan.sources[s]);
      else if (with_queries && plan.queries[s] < plan.queries[s + 1])
        system_origin(frames[s], queries + 3 * plan.queries[s]);
    }

  // Every particle wrapped, and its images counted, then placed after the targets (and sources).
  wrapped_.resize(n);
  image_offset_.assign(n + 1, 0);
  for (std::uint32_t s = 0; s < systems; ++s)
    for (std::uint64_t p = plan.sources[s]; p < plan.sources[s + 1]; ++p) {
      wrapped_[p] =
          float64 ? wrap_point(frames[s], float64 + 3 * p) : wrap_point(frames[s], sources + 3 * p);
      if (!wrapped_[p].ok) refuse_wrap(p, sources + 3 * p, "particle");
      image_offset_[p + 1] = image_count(frames[s], wrapped_[p], false);
    }
  for (std::size_t p = 0; p < n; ++p) image_offset_[p + 1] += image_offset_[p];
  const std::uint64_t first_image = targets + (with_queries ? n : 0);
  const std::uint64_t total = first_image + image_offset_[n];
  if (std::string why = too_many_points(total, targets); !why.empty()) refuse(why);

  // Refused before anything is allocated when the points and the CPU method's structure over
  // them (which the engine builds next) exceed the memory budget: a box far thinner than the
  // cutoff makes ~(4/3) pi (C / L)^3 images per particle.
  const double point_bytes = 3 * sizeof(float) + sizeof(PointImage) +
                             (systems > 1 ? sizeof(std::uint32_t) : 0) + host_build_bytes_per_point;
  require_host_memory(point_bytes * static_cast<double>(total), [&] {
    return "periodic images and the method's structure over them: " + std::to_string(total) +
           " points for " + std::to_string(targets) + " targets (~" + number(point_bytes) +
           " B each; a box far thinner than the cutoff makes many images)";
  });
  try {
    xyz_.resize(3 * total);
    image_.resize(total);
    if (systems > 1) system_.resize(total);
  } catch (const std::bad_alloc&) {
    throw Error(ErrorCode::out_of_memory,
                "not enough host memory for " + std::to_string(total) + " points with images (" +
                    format_bytes(32.0 * static_cast<double>(total)) + ")");
  }
  const auto place = [&](std::uint64_t k, const float* p, std::uint32_t source, std::uint32_t s,
                         const std::int32_t t[3]) {
    std::copy_n(p, 3, &xyz_[3 * k]);
    image_[k] = {source, {t[0], t[1], t[2]}};
    if (systems > 1) system_[k] = s;
  };
  // A wrapped particle or query at point k.
  const auto place_wrapped = [&](std::uint64_t k, const ImageFrame& frame, const WrappedPoint& w,
                                 std::uint32_t source, std::uint32_t s) {
    float p[3];
    for (int c = 0; c < 3; ++c) p[c] = static_cast<float>(w.x[c] - frame.origin[c]);
    const std::int32_t t[3] = {-w.shift[0], -w.shift[1], -w.shift[2]};
    place(k, p, source, s, t);
  };

  for (std::uint32_t s = 0; s < systems; ++s) {
    if (with_queries) {
      for (std::uint64_t q = plan.queries[s]; q < plan.queries[s + 1]; ++q) {
        const WrappedPoint w = wrap_point(frames[s], queries + 3 * q);
        if (!w.ok) refuse_wrap(q, queries + 3 * q, "query point");
        place_wrapped(q, frames[s], w, not_a_source, s);
      }
    }
    for (std::uint64_t p = plan.sources[s]; p < plan.sources[s + 1]; ++p) {
      const std::uint64_t k = with_queries ? targets + p : p;
      place_wrapped(k, frames[s], wrapped_[p], static_cast<std::uint32_t>(p), s);
      std::uint64_t next = first_image + image_offset_[p];
      const WrappedPoint& w = wrapped_[p];
      for_each_image(frames[s], w, false, [&](const int nshift[3], const float position[3]) {
        const std::int32_t t[3] = {nshift[0] - w.shift[0], nshift[1] - w.shift[1],
                                   nshift[2] - w.shift[2]};
        place(next++, position, static_cast<std::uint32_t>(p), s, t);
      });
    }
  }

  sources_.assign(sources, sources + 3 * n);
  sources64_.assign(float64, float64 ? float64 + 3 * n : float64);
  queries_.assign(queries, queries + (with_queries ? 3 * plan.queries.back() : 0));
  cells_.resize(9 * std::size_t{systems});
  for (std::uint32_t s = 0; s < systems; ++s)
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < 3; ++c) cells_[9 * s + 3 * k + c] = plan.frames[s].cell[k][c];
  float extent = 0;
  for (const float v : xyz_) extent = std::max(extent, std::fabs(v));
  exact_.sources = sources_.data();
  exact_.sources64 = float64 ? sources64_.data() : nullptr;
  exact_.queries = with_queries ? queries_.data() : nullptr;
  exact_.image = image_.data();
  exact_.system = systems > 1 ? system_.data() : nullptr;
  exact_.cells = cells_.data();
  set_float_band(exact_, plan.cutoff, rounding_bound(extent));
  image_counts_.resize(n);
  for (std::size_t p = 0; p < n; ++p)
    image_counts_[p] = static_cast<std::uint32_t>(image_offset_[p + 1] - image_offset_[p]);
  publish(plan, xyz_.data(), total, image_.data(), system_.data(), &exact_, image_counts_.data());
}

}  // namespace

ImagePlan plan_images(const Systems& systems, std::size_t sources, double cutoff) {
  const std::size_t count = systems.offsets.empty() ? 1 : systems.offsets.size() - 1;
  if (!systems.offsets.empty() && systems.offsets.size() < 2)
    refuse("batch offsets need at least 2 entries (0 and N), got 1");
  ImagePlan plan;
  plan.sources = checked_offsets(systems.offsets, count, sources, "batch offsets", "particles");
  if (systems.has_queries()) {
    if (systems.queries.size > 0 && systems.queries.xyz == nullptr)
      refuse("query positions pointer is null for M = " + std::to_string(systems.queries.size));
    if (count > 1 && systems.query_offsets.empty())
      refuse("a batch with query points needs query_offsets (one range of queries per system)");
    plan.queries = checked_offsets(systems.query_offsets, count, systems.queries.size,
                                   "query_offsets", "query points");
  } else if (!systems.query_offsets.empty()) {
    refuse("query_offsets given without query points");
  }
  if (!systems.boxes.empty() && systems.boxes.size() != 1 && systems.boxes.size() != count)
    refuse("Systems::boxes has " + std::to_string(systems.boxes.size()) + " boxes for " +
           std::to_string(count) + " systems (1 for all, or one per system)");
  plan.frames.reserve(count);
  for (std::size_t s = 0; s < count; ++s) {
    const Box& box =
        systems.boxes.empty() ? systems.box : systems.boxes[systems.boxes.size() == 1 ? 0 : s];
    plan.frames.push_back(frame_of(box, cutoff, s, count > 1));
  }
  plan.own_frames = count > 1;
  plan.cutoff = cutoff;
  return plan;
}

double rounding_bound(double extent) {
  return 2 * std::ldexp(extent, -24);
}

void set_float_band(ExactImages& exact, double cutoff, double rounding) {
  const double slack = float_band_slack(cutoff, rounding);
  const double c2 = cutoff * cutoff;
  const auto in = static_cast<float>(c2 - slack), out = static_cast<float>(c2 + slack);
  exact.exact_vectors = rounding > std::ldexp(cutoff, -16);
  exact.float_in = exact.exact_vectors                     ? 0.0f
                   : static_cast<double>(in) <= c2 - slack ? in
                                                           : std::nextafter(in, 0.0f);
  exact.float_out = static_cast<double>(out) >= c2 + slack ? out : std::nextafter(out, INFINITY);
  exact.cutoff_squared = c2;
  exact.rounding = rounding;
}

double band_reach(const ExactImages& exact) {
  return std::sqrt(static_cast<double>(exact.float_out)) * (1 + 1e-6);
}

void ImagePoints::expand_reusing(const ImagePlan&, const float*, const float*, void*) {
  throw Error(ErrorCode::internal, "this expansion records no plan to reuse");
}

std::string too_many_points(std::uint64_t points, std::size_t targets) {
  if (points < not_a_source) return {};
  return "periodic images: " + std::to_string(points) + " points for " + std::to_string(targets) +
         " targets exceed the 2^32 - 1 that 32-bit indices address " +
         "(a box far thinner than the cutoff makes many images per particle)";
}

std::unique_ptr<ImagePoints> make_host_image_points() {
  return std::make_unique<HostImagePoints>();
}

}  // namespace raycut::detail
