// raycut: particle interactions within a cutoff on CPU and GPU. Subcommands: methods, check,
// bench, generate. Errors are one line on stderr and exit code 2.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <map>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/generators.hpp"
#include "raycut/io.hpp"

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

PointCloud suite_cloud(const std::string& suite, int param, int p, std::uint64_t seed) {
  return suite == "uniform" ? uniform_suite(param, p, seed) : surface_suite(param, p, seed);
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
  cmd->add_option("--family", o->family, "Test family (see `raycut check --help`)");
  cmd->add_option("--suite", o->suite, "Benchmark suite instead of a family")
      ->check(CLI::IsMember({"uniform", "surface"}));
  cmd->add_option("-n,--n", o->n, "Number of particles (families)");
  cmd->add_option("--cutoff", o->cutoff, "Cutoff the family is made for");
  cmd->add_option("--param", o->param, "beta (uniform) or alpha (surface)");
  cmd->add_option("--p", o->p, "Mean particles per cell");
  cmd->add_option("--seed", o->seed, "Random seed");
  cmd->add_option("-o,--out", o->out, "Output file (.csv or .xyz)")->required();
  return [o] {
    const PointCloud cloud = o->suite == "uniform" ? uniform_suite(o->param, o->p, o->seed)
                             : o->suite == "surface"
                                 ? surface_suite(o->param, o->p, o->seed)
                                 : make_family(o->family, o->n, o->cutoff, o->seed);
    const bool csv = o->out.size() >= 4 && o->out.compare(o->out.size() - 4, 4, ".csv") == 0;
    csv ? write_csv(o->out, cloud) : write_xyz(o->out, cloud);
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
  std::map<std::string, Command> commands = {
      {"methods", add_methods(app)}, {"check", add_check(app)},
      {"bench", add_bench(app)},     {"update-bench", add_update_bench(app)},
      {"sph", add_sph(app)},         {"generate", add_generate(app)}};
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
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
  } catch (const std::exception& e) {
    std::cerr << "raycut: " << e.what() << "\n";
    return 2;
  }
}
