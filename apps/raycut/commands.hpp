// The subcommands of the raycut tool. Each registers its options on a CLI11 subcommand and
// returns the process exit code when run: 0 success, 1 a check failed, 2 bad usage or input.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "raycut/generators.hpp"

namespace raycut::cli {

using Command = std::function<int()>;

Command add_check(CLI::App& app);
Command add_bench(CLI::App& app);
Command add_update_bench(CLI::App& app);
Command add_sph(CLI::App& app);

// Expands "all" / "default" and checks the names; throws raycut::Error for unknown ones.
std::vector<std::string> resolve_methods(const std::vector<std::string>& names);

// A configuration of the "uniform" or "surface" suite.
PointCloud suite_cloud(const std::string& suite, int param, int p, std::uint64_t seed);

// The median of samples (mean of the middle two for an even count).
double median(std::vector<double> samples);

}  // namespace raycut::cli
