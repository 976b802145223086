// raycut: particle interactions within a cutoff on CPU and GPU. Subcommands: methods, check,
// bench, update-bench, sph, generate, neighbours; --version. Every error (bad usage, a bad input
// file, an output file that cannot be written in full, not enough memory) is one line on stderr and
// exit code 2; a check that finds a mismatch exits 1.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <map>
#include <new>

#include <unistd.h>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/host_memory.hpp"
#include "raycut/tools/files.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/io.hpp"

namespace raycut::cli {

std::vector<std::string> resolve_methods(const std::vector<std::string>& names) {
  const auto all = list_methods();
  std::vector<std::string> out;
  for (const auto& name : names) {
    if (name == "all" || name == "default") {
      // default: the oracles left out, and the CPU methods too when there is a GPU.
      const bool gpu = cuda_device_available();
      for (const auto& m : all) {
        if (!m.available) continue;
        if (name == "default" && (m.name.rfind("brute-force", 0) == 0 ||
                                  (gpu && Engine(m.name).space() != MemorySpace::device)))
          continue;
        out.push_back(m.name);
      }
      continue;
    }
    Engine probe(name == "auto" ? auto_method() : name);  // throws for unknown/unavailable
    out.push_back(probe.method());
  }
  return out;
}

Progress::Progress(std::string what, std::uint64_t total, bool quiet)
    : what_(std::move(what)),
      total_(total),
      quiet_(quiet),
      terminal_(isatty(2) != 0),
      interval_(terminal_ ? 0.5 : 10.0) {
  if (const char* text = std::getenv("RAYCUT_PROGRESS_SECONDS")) {
    char* end = nullptr;
    const double seconds = std::strtod(text, &end);
    if (end == text || *end != '\0' || !(seconds >= 0) || !std::isfinite(seconds))
      throw Error(ErrorCode::invalid_argument, std::string("RAYCUT_PROGRESS_SECONDS=") + text +
                                                   ": expected a number of seconds >= 0");
    first_ = interval_ = seconds;
  }
}

double Progress::elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

std::string Progress::eta(std::uint64_t done) const {
  if (done == 0 || done > total_) return "ETA unknown";
  const double left = elapsed() / static_cast<double>(done) * static_cast<double>(total_ - done);
  char text[48];
  std::snprintf(text, sizeof text, "ETA %.0f s", left);
  return text;
}

void Progress::update(std::uint64_t done) {
  const double t = elapsed();
  if (quiet_ || t < first_ || t - last_ < interval_) return;
  last_ = t;
  const double percent = total_ ? 100.0 * static_cast<double>(done) / total_ : 100.0;
  std::fprintf(stderr, "%s%s: %.0f%% (%llu/%llu), %.0f s, %s%s", terminal_ ? "\r" : "",
               what_.c_str(), percent, static_cast<unsigned long long>(done),
               static_cast<unsigned long long>(total_), t, eta(done).c_str(),
               terminal_ ? "   " : "\n");
  std::fflush(stderr);
  printed_ = true;
}

void Progress::done() {
  if (printed_ && terminal_) std::fputc('\n', stderr);
  printed_ = false;
}

std::uint64_t suite_particles(int param, int p) {
  std::uint64_t n = 0;
  const auto side = static_cast<std::uint64_t>(param);
  if (param < 1 || p < 1 || __builtin_mul_overflow(side, side, &n) ||
      __builtin_mul_overflow(n, side, &n) ||
      __builtin_mul_overflow(n, static_cast<std::uint64_t>(p), &n))
    throw Error(ErrorCode::invalid_argument,
                "suite param = " + std::to_string(param) + ", p = " + std::to_string(p) +
                    ": p * param^3 particles is not a count raycut can hold (needs param, p >= 1 "
                    "and p * param^3 < 2^64)");
  return n;
}

void require_particles_fit(std::uint64_t n, double bytes_per_particle, const std::string& what) {
  require_host_memory(static_cast<double>(n) * bytes_per_particle,
                      what + ": N = " + std::to_string(n) + " particles (~" +
                          std::to_string(static_cast<int>(bytes_per_particle)) + " bytes each)");
}

PointCloud suite_cloud(const std::string& suite, int param, int p, std::uint64_t seed,
                       double bytes_per_particle) {
  require_particles_fit(
      suite_particles(param, p), bytes_per_particle,
      suite + " suite param=" + std::to_string(param) + " p=" + std::to_string(p));
  return suite == "uniform" ? uniform_suite(param, p, seed) : surface_suite(param, p, seed);
}

namespace {

// The option's text as a float, whole: false for "0.1abc", "", or a value out of float range.
bool parse_float_option(const std::string& text, float& value) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  return !text.empty() && ec == std::errc() && ptr == end && std::isfinite(value);
}

CLI::Validator validator(std::function<bool(const std::string&)> ok, std::string wanted) {
  return CLI::Validator(
      [ok = std::move(ok), wanted](std::string& text) -> std::string {
        if (ok(text)) return "";
        return "must be " + wanted + ", got '" + io::printable(text) + "'";
      },
      wanted, "");
}

}  // namespace

CLI::Validator positive_finite() {
  return validator(
      [](const std::string& t) {
        float v = 0;
        return parse_float_option(t, v) && v > 0;
      },
      "a finite number > 0");
}

CLI::Validator non_negative_finite() {
  return validator(
      [](const std::string& t) {
        float v = 0;
        return parse_float_option(t, v) && v >= 0;
      },
      "a finite number >= 0");
}

CLI::Validator positive_integer() {
  return validator(
      [](const std::string& t) {
        int v = 0;
        const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        return !t.empty() && ec == std::errc() && ptr == t.data() + t.size() && v > 0;
      },
      "a whole number in [1, 2147483647]");
}

CLI::Validator count_option() {
  return validator(
      [](const std::string& t) {
        std::uint64_t v = 0;
        const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        return !t.empty() && ec == std::errc() && ptr == t.data() + t.size();
      },
      "a whole number >= 0");
}

CLI::Validator cutoff_option() {
  const std::string wanted = "a finite number > 0";
  return CLI::Validator(
      [wanted](std::string& text) -> std::string {
        double v = 0;
        const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
        const bool number = !text.empty() && ptr == text.data() + text.size() &&
                            (ec == std::errc() || ec == std::errc::result_out_of_range);
        // Checked as given (a double, or beyond one): 1e-50 and 1e39 are numbers out of range,
        // not "0" or "inf" as they would be in float.
        if (!number || text[0] == '-' || (ec == std::errc() && !(std::isfinite(v) && v > 0)))
          return "must be " + wanted + ", got '" + io::printable(text) + "'";
        if (ec == std::errc() && v >= 0x1p-60 && v <= 0x1p60) return "";
        return "must be in the supported range [2^-60, 2^60] = [8.67e-19, 1.15e18], got '" +
               io::printable(text) + "'";
      },
      wanted + " in [2^-60, 2^60]", "");
}

CLI::Validator seed_option() {
  return validator(
      [](const std::string& t) {
        std::uint64_t v = 0;
        const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        return !t.empty() && ec == std::errc() && ptr == t.data() + t.size();
      },
      "a whole number in [0, 2^64 - 1 = 18446744073709551615]");
}

CLI::Validator one_of(std::vector<std::string> names, std::string what) {
  std::string list;
  for (const auto& name : names) list += (list.empty() ? "" : ", ") + name;
  return validator(
      [names = std::move(names)](const std::string& t) {
        return std::find(names.begin(), names.end(), t) != names.end();
      },
      "one of " + list + " (" + what + ")");
}

namespace {

// Values of a multi-token option: each token split at spaces and commas.
std::vector<std::string> option_values(const std::vector<std::string>& tokens) {
  std::vector<std::string> values;
  for (const auto& token : tokens) {
    std::string value;
    for (char ch : token + " ") {
      if (ch == ' ' || ch == ',' || ch == '\t') {
        if (!value.empty()) values.push_back(value);
        value.clear();
      } else {
        value += ch;
      }
    }
  }
  return values;
}

std::string joined(const std::vector<std::string>& tokens) {
  std::string text;
  for (const auto& t : tokens) text += (text.empty() ? "" : " ") + t;
  return io::printable(text);
}

}  // namespace

void add_box_options(CLI::App& cmd, BoxOptions& o) {
  cmd.add_option("--cell", o.cell,
                 "Periodic box: the cell rows a b c as 9 numbers \"ax ay az bx by bz cx cy cz\", "
                 "or 3 side lengths of an orthorhombic box; periodic on every axis unless --pbc")
      ->expected(1, 9);
  cmd.add_option("--pbc", o.pbc,
                 "Which cell rows repeat: 3 of T/F/true/false/1/0 (\"T T F\", 1 1 0); one value "
                 "for all three; default T T T with --cell")
      ->expected(1, 3);
}

Box resolve_box(const BoxOptions& o, const Box& base) {
  Box box = base;
  if (!o.cell.empty()) {
    const auto values = option_values(o.cell);
    double v[9] = {};
    bool ok = values.size() == 9 || values.size() == 3;
    for (std::size_t k = 0; ok && k < values.size(); ++k) {
      const std::string& t = values[k];
      const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v[k]);
      ok = ec == std::errc() && ptr == t.data() + t.size() && std::isfinite(v[k]);
    }
    if (!ok)
      throw Error(ErrorCode::invalid_argument,
                  "--cell: must be 9 finite numbers, the cell rows \"ax ay az bx by bz cx cy cz\", "
                  "or 3, the sides of an orthorhombic box; got '" +
                      joined(o.cell) + "'");
    box = values.size() == 3 ? Box::orthorhombic(v[0], v[1], v[2]) : Box{};
    if (values.size() == 9)
      for (int k = 0; k < 9; ++k) box.cell[k / 3][k % 3] = v[k];
    box.pbc[0] = box.pbc[1] = box.pbc[2] = true;
  }
  if (!o.pbc.empty()) {
    const auto values = option_values(o.pbc);
    bool flags[3] = {};
    bool ok = values.size() == 1 || values.size() == 3;
    for (std::size_t k = 0; ok && k < values.size(); ++k) {
      std::string w = values[k];
      std::transform(w.begin(), w.end(), w.begin(),
                     [](unsigned char c) { return std::tolower(c); });
      ok = w == "t" || w == "true" || w == "1" || w == "f" || w == "false" || w == "0";
      flags[k] = w == "t" || w == "true" || w == "1";
    }
    if (!ok)
      throw Error(ErrorCode::invalid_argument,
                  "--pbc: must be 3 of T/F/true/false/1/0, one per cell row (e.g. \"T T F\"), or "
                  "one for all three; got '" +
                      joined(o.pbc) + "'");
    if (values.size() == 1) flags[1] = flags[2] = flags[0];
    if (o.cell.empty() && base.is_open())
      throw Error(ErrorCode::invalid_argument,
                  "--pbc: needs a cell: give --cell (or an extended-XYZ input with a Lattice)");
    for (int k = 0; k < 3; ++k) box.pbc[k] = flags[k];
  }
  if (o.given()) {
    try {
      validate(box);
    } catch (const Error& e) {
      throw Error(ErrorCode::invalid_argument,
                  std::string(o.cell.empty() ? "--pbc (with the input's Lattice)" : "--cell") +
                      ": " + e.what());
    }
  }
  return box;
}

std::string describe_box(const Box& box) {
  char text[256];
  const auto& c = box.cell;
  const bool diagonal =
      c[0][1] == 0 && c[0][2] == 0 && c[1][0] == 0 && c[1][2] == 0 && c[2][0] == 0 && c[2][1] == 0;
  if (diagonal)
    std::snprintf(text, sizeof text, "%gx%gx%g", c[0][0], c[1][1], c[2][2]);
  else
    std::snprintf(text, sizeof text, "[[%g %g %g] [%g %g %g] [%g %g %g]]", c[0][0], c[0][1],
                  c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1], c[2][2]);
  return std::string(text) + " (pbc " + (box.pbc[0] ? "T" : "F") + " " + (box.pbc[1] ? "T" : "F") +
         " " + (box.pbc[2] ? "T" : "F") + ")";
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

namespace {

Command add_methods(CLI::App& app) {
  app.add_subcommand("methods", "List the interaction methods and whether they run here");
  return [] {
    for (const auto& m : list_methods())
      std::printf("%-16s %-11s %s%s%s\n", m.name.c_str(), m.available ? "available" : "unavailable",
                  m.summary.c_str(), m.available ? "" : " -- ", m.why_unavailable.c_str());
    std::printf("auto -> %s\n", auto_method().c_str());
    return 0;
  };
}

Command add_generate(CLI::App& app) {
  auto* cmd = app.add_subcommand("generate", "Write a generated input to .csv or .xyz");
  struct Options {
    std::string family = "uniform", suite, out;
    std::size_t n = 1000;
    float cutoff = 1.0f;
    int param = 8, p = 1;
    std::uint64_t seed = 1;
  };
  auto o = std::make_shared<Options>();
  cmd->add_option("-f,--family", o->family, "Test family (see `raycut check --help`)");
  cmd->add_option("--suite", o->suite, "Benchmark suite instead of a family")
      ->check(CLI::IsMember({"uniform", "surface"}));
  cmd->add_option("-n,--n", o->n, "Number of particles (families)")->check(count_option());
  cmd->add_option("-c,--cutoff", o->cutoff, "Cutoff the family is made for")
      ->check(positive_finite());
  cmd->add_option("--param", o->param, "beta (uniform) or alpha (surface)")
      ->check(positive_integer());
  cmd->add_option("--p", o->p, "Mean particles per cell")->check(positive_integer());
  cmd->add_option("--seed", o->seed, "Random seed")->check(seed_option());
  cmd->add_option("-o,--out", o->out, "Output file (.csv or .xyz, any case)")->required();
  return [o] {
    check_positions_extension(o->out);
    // Positions, and the text written from them in chunks: ~16 bytes a particle.
    constexpr double bytes_per_particle = 16;
    if (o->suite.empty()) require_particles_fit(o->n, bytes_per_particle, "generate " + o->family);
    const PointCloud cloud =
        !o->suite.empty() ? suite_cloud(o->suite, o->param, o->p, o->seed, bytes_per_particle)
                          : make_family(o->family, o->n, o->cutoff, o->seed);
    const auto bad =
        std::find_if(cloud.xyz.begin(), cloud.xyz.end(), [](float x) { return !std::isfinite(x); });
    if (bad != cloud.xyz.end()) {
      char cutoff[32];
      std::snprintf(cutoff, sizeof cutoff, "%g", static_cast<double>(o->cutoff));
      throw Error(ErrorCode::invalid_argument,
                  "generate: family " + o->family + " at --cutoff " + cutoff +
                      " gives non-finite coordinates (particle index " +
                      std::to_string((bad - cloud.xyz.begin()) / 3) +
                      "): its domain does not fit in float; use a smaller cutoff");
    }
    write_positions(o->out, cloud);
    std::printf("wrote %zu particles (cutoff %g) to %s\n", cloud.size(), cloud.cutoff,
                o->out.c_str());
    return 0;
  };
}

}  // namespace
}  // namespace raycut::cli

int main(int argc, char** argv) {
  using namespace raycut::cli;
  CLI::App app{
      "raycut: particle interactions within a cutoff radius, on CPU, CUDA grids and OptiX ray "
      "tracing"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("raycut ") + RAYCUT_VERSION);
  std::map<std::string, Command> commands = {{"methods", add_methods(app)},
                                             {"check", add_check(app)},
                                             {"bench", add_bench(app)},
                                             {"update-bench", add_update_bench(app)},
                                             {"sph", add_sph(app)},
                                             {"generate", add_generate(app)},
                                             {"neighbours", add_neighbours(app)}};
  // CLI11 says only "A subcommand is required" for a misspelt one: name it.
  if (argc > 1 && argv[1][0] != '-' && commands.count(argv[1]) == 0) {
    std::string known;
    for (const auto& [name, command] : commands) known += (known.empty() ? "" : ", ") + name;
    std::cerr << "raycut: unknown subcommand '" << raycut::io::printable(argv[1])
              << "' (known: " << known << "; see --help)\n";
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "raycut: " << e.what() << " (see --help)\n";
    return 2;
  }
  try {
    return commands.at(app.get_subcommands().front()->get_name())();
  } catch (const raycut::Error& e) {
    std::cerr << "raycut: " << raycut::to_string(e.code()) << ": " << e.what() << "\n";
    return 2;
  } catch (const std::bad_alloc&) {
    std::cerr << "raycut: out of memory: a host allocation failed (std::bad_alloc); try fewer "
                 "particles\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "raycut: " << e.what() << "\n";
    return 2;
  }
}
