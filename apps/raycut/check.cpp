// raycut check: every chosen method against the brute-force oracle on generated families or a
// file: neighbour sets, counts and smooth-kernel sums. Exit 1 on any mismatch. In a periodic box
// (--cell/--pbc, or an extended-XYZ file's Lattice and pbc) the oracle gets the same box, list
// entries are compared with their image shifts, and the half list is compared too.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/compare.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/io.hpp"

namespace raycut::cli {
namespace {

struct CheckOptions {
  std::vector<std::string> methods = {"default"};
  std::vector<std::string> families = {"all"};
  std::vector<std::size_t> sizes = {2000};
  float cutoff = 1.0f;
  std::uint64_t seed = 1;
  std::string input;
  std::string oracle = "auto";
  BoxOptions box;
  bool quiet = false;
};

// Whether the smooth kernel can be evaluated in float at this cutoff (validate_kernel_range):
// outside, its results are refused, not compared.
bool smooth_in_range(float cutoff) {
  try {
    validate_kernel_range(Kernel::smooth, {}, cutoff);
    return true;
  } catch (const Error&) {
    return false;
  }
}

// Builds over the cloud in its box (a box without a periodic axis is a plain build: methods
// without boxes check such files as before).
void build_in_box(Engine& engine, const PositionsView& view, const PointCloud& cloud) {
  engine.build(view, cloud.cutoff, cloud.box);
}

// The row of an input or a method that is not compared, and why, under it.
void print_not_compared(const PointCloud& cloud, const std::string& method, const char* status,
                        const Error& e) {
  std::printf("%-18s %8zu %7g  %-16s %12s %10s %10s  %s\n", cloud.name.c_str(), cloud.size(),
              cloud.cutoff, method.c_str(), "-", "-", "-", status);
  std::printf("    %s\n", e.what());
  std::fflush(stdout);
}

int run_check(const CheckOptions& o) {
  const auto methods = resolve_methods(o.methods);
  std::vector<PointCloud> inputs;
  if (!o.input.empty()) {
    PointCloud cloud = read_positions(o.input);
    cloud.box = resolve_box(o.box, cloud.box);  // --cell / --pbc override the file's
    cloud.cutoff = o.cutoff;
    inputs.push_back(std::move(cloud));
  } else {
    const Box box = resolve_box(o.box);  // before any generation: bad options fail at once
    std::vector<std::string> families = o.families;
    if (std::find(families.begin(), families.end(), "all") != families.end())
      families = family_names();
    // Positions, the oracle's neighbour list and every method's results: ~128 bytes a particle.
    for (const auto& f : families)
      for (std::size_t n : o.sizes) {
        require_particles_fit(n, 128, "check: family " + f);
        inputs.push_back(make_family(f, n, o.cutoff, o.seed));
        inputs.back().box = box;
      }
  }

  std::printf(
      "smooth-err: |smooth - its float64 sum over the oracle's pairs| / the float bound "
      "2 ((n + 1) 2^-24 sum|term| + n term_error) per target and value; ok <= 1\n");
  std::printf("%-18s %8s %7s  %-16s %12s %10s %10s  %s\n", "input", "N", "cutoff", "method",
              "pairs", "bad-tgts", "smooth-err", "status");
  int failures = 0, skipped = 0, refused = 0, compared = 0;
  Progress progress("check", inputs.size() * methods.size(), o.quiet);
  std::uint64_t steps = 0;
  for (const auto& cloud : inputs) {
    const bool periodic = cloud.box.periodic();
    if (periodic)
      std::printf("%s: periodic box %s\n", cloud.name.c_str(), describe_box(cloud.box).c_str());
    const std::string oracle_name = o.oracle != "auto" ? o.oracle
                                    : (cuda_device_available() && cloud.size() > 20000)
                                        ? "brute-force-gpu"
                                        : "brute-force";
    Engine oracle(oracle_name);
    const PositionsView view{cloud.xyz.data(), cloud.size(), MemorySpace::host};
    try {
      build_in_box(oracle, view, cloud);
    } catch (const Error& e) {
      // A family whose own scale does not fit the box (huge-scale in a small cell: too many
      // images) is refused by the oracle as by every method: say so and check the others.
      if (!periodic || e.code() != ErrorCode::invalid_argument) throw;
      ++refused;
      print_not_compared(cloud, oracle_name, "refused", e);
      continue;
    }
    // In a box an entry is (j, S): the same j through two images is two entries.
    ListOptions full;
    full.shifts = periodic;
    ListOptions half = full;
    half.half = true;
    const NeighbourList want_list = oracle.neighbours(full);
    const NeighbourList want_half = periodic ? oracle.neighbours(half) : NeighbourList{};
    Results want_count;  // the list's row lengths: no third O(N^2) pass
    for (std::size_t i = 0; i < cloud.size(); ++i)
      want_count.count.push_back(
          static_cast<std::uint32_t>(want_list.offsets[i + 1] - want_list.offsets[i]));
    const bool smooth = smooth_in_range(cloud.cutoff);
    const SmoothReference want_smooth =
        smooth ? smooth_reference(cloud.xyz.data(), cloud.cutoff, want_list, cloud.box)
               : SmoothReference{};
    for (const auto& method : methods) {
      progress.update(steps++);
      Engine engine(method);
      NeighbourComparison diff, half_diff;
      bool counts_ok = false;
      double err = 0;
      try {
        build_in_box(engine, view, cloud);
        diff = compare_neighbours(engine.neighbours(full), want_list);
        if (periodic) half_diff = compare_neighbours(engine.neighbours(half), want_half);
        counts_ok = engine.compute(Kernel::count).count == want_count.count;
        if (smooth) err = smooth_bound_ratio(engine.compute(Kernel::smooth), want_smooth);
      } catch (const Error& e) {
        // Methods without periodic boxes (docs/methods.md) refuse them: a row saying so, not a
        // mismatch and not the end of the check.
        if (!periodic || e.code() != ErrorCode::unsupported) throw;
        ++skipped;
        print_not_compared(cloud, method, "unsupported", e);
        continue;
      }
      ++compared;
      const bool ok = diff.equal() && half_diff.equal() && counts_ok && err <= 1;  // false for NaN
      failures += !ok;
      char err_text[16] = "n/a";  // smooth out of float range at this cutoff: not compared
      if (smooth) std::snprintf(err_text, sizeof err_text, "%.2e", err);
      std::printf("%-18s %8zu %7g  %-16s %12llu %10zu %10s  %s\n", cloud.name.c_str(), cloud.size(),
                  cloud.cutoff, method.c_str(), static_cast<unsigned long long>(diff.pairs),
                  diff.differing_targets, err_text, ok ? "ok" : "MISMATCH");
      if (!diff.equal()) std::printf("    first difference: %s\n", diff.first_difference.c_str());
      if (!half_diff.equal())
        std::printf("    the half list differs (%zu targets); first difference: %s\n",
                    half_diff.differing_targets, half_diff.first_difference.c_str());
      if (!counts_ok) std::printf("    the count kernel differs from the oracle\n");
      std::fflush(stdout);
    }
  }
  progress.done();
  if (compared == 0 && skipped > 0)
    throw Error(ErrorCode::unsupported,
                "check: none of the methods asked for supports periodic boxes (see `raycut "
                "methods` and docs/methods.md); nothing was compared");
  if (compared == 0 && refused > 0)
    throw Error(ErrorCode::invalid_argument,
                "check: every input was refused in this box (above); nothing was compared");
  char skipped_text[160] = "";
  if (skipped)
    std::snprintf(skipped_text, sizeof skipped_text, " (%d skipped: no periodic boxes)", skipped);
  if (refused)
    std::snprintf(skipped_text + std::strlen(skipped_text),
                  sizeof skipped_text - std::strlen(skipped_text),
                  " (%d input(s) refused in this box)", refused);
  std::printf("%s: %d mismatch(es) over %zu input(s) x %zu method(s)%s\n",
              failures ? "FAILED" : "passed", failures, inputs.size(), methods.size(),
              skipped_text);
  return failures ? 1 : 0;
}

}  // namespace

Command add_check(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "check", "Compare methods with the brute-force oracle on test families or a file");
  auto o = std::make_shared<CheckOptions>();
  std::string family_help = "Input families, or all:";
  for (const auto& f : family_names()) family_help += " " + f;
  cmd->add_option(
         "-m,--methods", o->methods,
         "Methods to check (names from `raycut methods`; default = the available "
         "non-oracle methods, GPU ones only when there is a GPU; all = every available one)")
      ->delimiter(',');
  cmd->add_option("-f,--family", o->families, family_help)->delimiter(',');
  cmd->add_option("-n,--n", o->sizes, "Particle counts (comma-separated)")
      ->delimiter(',')
      ->check(count_option());
  cmd->add_option("-c,--cutoff", o->cutoff, "Cutoff radius")->check(cutoff_option());
  cmd->add_option("--seed", o->seed, "Random seed of the families")->check(seed_option());
  cmd->add_option(
         "-i,--input", o->input,
         "Positions file (.csv, .xyz) instead of families; an extended XYZ's Lattice and pbc are "
         "its periodic box (--cell/--pbc override them)")
      ->check(CLI::ExistingFile);
  // Only the brute forces are references: a faster method checked against itself (or another
  // method under test) would prove nothing.
  cmd->add_option("--oracle", o->oracle,
                  "auto (GPU brute force above 20,000 particles when there is a GPU), "
                  "brute-force or brute-force-gpu")
      ->check(one_of({"auto", "brute-force", "brute-force-gpu"},
                     "the oracles; the methods under test are not references"));
  add_box_options(*cmd, o->box);
  cmd->add_flag("-q,--quiet", o->quiet, "No progress line on stderr (runs longer than 3 s)");
  return [o] { return run_check(*o); };
}

}  // namespace raycut::cli
