// Measures the alternatives of the `grid` method (src/cuda/grid.cu, GridPolicy) side by side,
// through the internal Method interface: the numbers behind the defaults in docs/grid.md.
//
//   grid_tune --suite uniform --params 32 --ps 1,8,32 --variants k1,k2,k3,k2-nocull,k2-compact
//
// A variant is k<cells per cutoff>, optionally followed by -nocull (scan whole rows),
// -dense or -compact (force the cell table), -counting, -bycell, -radix or -oneblock (how the dense
// table is built), -g<lanes per target>, -x<x split>, -regs<1|2> (the thread kernel's register
// budget: the compiler's default, or as many as it wants); `paper` is grid-paper, `auto` the grid
// with its automatic choices (auto-radix: with a suffix). One CSV row per (configuration, variant)
// on stdout, CUDA-event medians in ms (build_host_ms: host clock around build + synchronise);
// `pairs` (count kernel) must be the same on every row of a configuration.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cuda/grid_policy.hpp"
#include "cuda/methods.hpp"
#include "raycut/tools/generators.hpp"

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

std::unique_ptr<raycut::detail::Method> make_variant(const std::string& name) {
  namespace cuda = raycut::detail::cuda;
  if (name == "paper") return cuda::make_grid_paper();
  cuda::GridPolicy o;
  if (name.size() >= 2 && name[0] == 'k')
    o.cell_width = static_cast<cuda::CellWidth>(std::stoi(name.substr(1)));
  else if (name.rfind("auto", 0) != 0)
    throw std::runtime_error("bad variant " + name);
  if (name.find("-nocull") != std::string::npos) o.cull = false;
  if (name.find("-dense") != std::string::npos) o.layout = cuda::TableLayout::dense;
  if (name.find("-compact") != std::string::npos) o.layout = cuda::TableLayout::compact;
  if (name.find("-counting") != std::string::npos)
    o.dense_build = cuda::DenseBuild::counting_by_particle;
  if (name.find("-radix") != std::string::npos) o.dense_build = cuda::DenseBuild::radix;
  if (name.find("-oneblock") != std::string::npos) o.dense_build = cuda::DenseBuild::one_block;
  if (name.find("-bycell") != std::string::npos) o.dense_build = cuda::DenseBuild::counting_by_cell;
  if (const auto r = name.find("-regs"); r != std::string::npos)
    o.registers = static_cast<cuda::RegisterBudget>(std::stoi(name.substr(r + 5)));
  if (const auto x = name.find("-x"); x != std::string::npos)
    o.x_split = std::stoi(name.substr(x + 2));
  if (const auto g = name.find("-g"); g != std::string::npos)
    o.lanes = cuda::lanes_per_target(std::stoi(name.substr(g + 2)));
  return cuda::make_grid_with(o);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::string suite = "uniform";
  std::vector<std::string> params = {"32"}, ps = {"32"}, variants = {"k1", "k2"};
  int reps = 5;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i], v = argv[i + 1];
    if (a == "--suite") suite = v;
    if (a == "--params") params = split(v);
    if (a == "--ps") ps = split(v);
    if (a == "--variants") variants = split(v);
    if (a == "--reps") reps = std::stoi(v);
  }
  std::cout << "suite,param,p,N,variant,pairs,build_ms,compute_ms,total_ms,build_host_ms\n";
  for (const auto& param_s : params) {
    for (const auto& p_s : ps) {
      const int param = std::stoi(param_s), p = std::stoi(p_s);
      const raycut::PointCloud cloud =
          suite == "uniform" ? raycut::uniform_suite(param, p) : raycut::surface_suite(param, p);
      const std::size_t n = cloud.size();
      float* xyz = nullptr;
      if (cudaMalloc(&xyz, cloud.xyz.size() * sizeof(float)) != cudaSuccess) return 1;
      cudaMemcpy(xyz, cloud.xyz.data(), cloud.xyz.size() * sizeof(float), cudaMemcpyHostToDevice);
      for (const auto& variant : variants) {
        try {
          auto m = make_variant(variant);
          m->build(xyz, n, cloud.cutoff);
          m->compute(raycut::Kernel::count, {});
          m->synchronize();
          unsigned long long pairs = 0;
          for (auto c : m->results().count) pairs += c;
          std::vector<double> b, c, t, h;
          for (int r = 0; r < reps; ++r) {
            const auto start = std::chrono::steady_clock::now();
            m->build(xyz, n, cloud.cutoff);
            m->synchronize();
            h.push_back(
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                    .count());
            b.push_back(m->device_build_ms());
            m->compute(raycut::Kernel::lj, {});
            m->synchronize();
            c.push_back(m->device_compute_ms());
            t.push_back(b.back() + c.back());
          }
          std::printf("%s,%d,%d,%zu,%s,%llu,%.4f,%.4f,%.4f,%.4f\n", suite.c_str(), param, p, n,
                      variant.c_str(), pairs, median(b), median(c), median(t), median(h));
          std::fflush(stdout);
        } catch (const std::exception& e) {
          std::printf("%s,%d,%d,%zu,%s,error: %s\n", suite.c_str(), param, p, n, variant.c_str(),
                      e.what());
        }
      }
      cudaFree(xyz);
    }
  }
  return 0;
}
