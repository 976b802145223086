// Times methods on the benchmark suites of spec/BENCHMARKS.md through the public API only, and
// writes one CSV row per (configuration, method, timer):
//   suite,method,param,p,N,cutoff,pairs,build_ms,compute_ms,total_ms,total_ms_min,total_ms_max,
//   reps,timer,gpu,driver,cuda,optix
// Positions are generated on the host and copied to the device before timing (generation and
// upload are not timed). Per method: one warm-up build + run, one count run for `pairs`, then
// `reps` timed build + run(lj); times are medians, total min/max over the repetitions. `timer`
// is `events` (CUDA events inside the method) or `host` (wall clock around each synchronised
// phase, as the paper's code measures).
//
//   bench_grid --suite uniform --params 2,4,8,16,32 --ps 1,2,4,8,16,32 --methods grid,grid-paper
//              --reps 5 --out results.csv
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#if defined(BENCH_HAVE_OPTIX)
#include <optix.h>
#endif

#include "raycut/engine.hpp"
#include "raycut/generators.hpp"

namespace {

struct Options {
  std::string suite = "uniform";
  std::vector<int> params = {2, 4, 8, 16, 32};
  std::vector<int> ps = {1, 2, 4, 8, 16, 32};
  std::vector<std::string> methods = {"grid", "grid-paper"};
  int reps = 5;
  std::size_t few_reps_above = 0;  // N above which `few_reps` repetitions are run (0: never)
  int few_reps = 5;
  std::string out = "bench_grid.csv";
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

std::vector<int> split_ints(const std::string& s) {
  std::vector<int> out;
  for (const auto& item : split(s)) out.push_back(std::stoi(item));
  return out;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "missing value after " << arg << "\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (arg == "--suite")
      o.suite = value();
    else if (arg == "--params")
      o.params = split_ints(value());
    else if (arg == "--ps")
      o.ps = split_ints(value());
    else if (arg == "--methods")
      o.methods = split(value());
    else if (arg == "--reps")
      o.reps = std::stoi(value());
    else if (arg == "--few-reps-above")
      o.few_reps_above = std::stoull(value());
    else if (arg == "--few-reps")
      o.few_reps = std::stoi(value());
    else if (arg == "--out")
      o.out = value();
    else {
      std::cerr << "usage: bench_grid [--suite uniform|surface] [--params 2,4,..] [--ps 1,2,..]\n"
                   "       [--methods grid,grid-paper] [--reps 5] [--few-reps-above N]\n"
                   "       [--few-reps R] [--out file.csv]\n";
      std::exit(arg == "--help" ? 0 : 2);
    }
  }
  if (o.suite != "uniform" && o.suite != "surface") {
    std::cerr << "unknown suite '" << o.suite << "' (uniform, surface)\n";
    std::exit(2);
  }
  return o;
}

void check(cudaError_t status, const char* what) {
  if (status != cudaSuccess) {
    std::cerr << what << ": " << cudaGetErrorString(status) << "\n";
    std::exit(1);
  }
}

struct Environment {
  std::string gpu, driver, cuda, optix;
};

std::string version_string(int v) {  // 13000 -> 13.0
  return std::to_string(v / 1000) + "." + std::to_string((v % 1000) / 10);
}

Environment environment() {
  Environment env;
  cudaDeviceProp prop{};
  check(cudaGetDeviceProperties(&prop, 0), "cudaGetDeviceProperties");
  env.gpu = prop.name;
  std::replace(env.gpu.begin(), env.gpu.end(), ',', ' ');
  int driver = 0, runtime = 0;
  check(cudaDriverGetVersion(&driver), "cudaDriverGetVersion");
  check(cudaRuntimeGetVersion(&runtime), "cudaRuntimeGetVersion");
  env.cuda = version_string(runtime);
  env.driver = "cuda-" + version_string(driver);
  // The kernel-module version, when the driver exposes it.
  if (std::ifstream f("/sys/module/nvidia/version"); f) {
    std::string v;
    if (std::getline(f, v) && !v.empty()) env.driver = v;
  }
#if defined(BENCH_HAVE_OPTIX)
  env.optix = std::to_string(OPTIX_VERSION / 10000) + "." +
              std::to_string((OPTIX_VERSION % 10000) / 100) + "." +
              std::to_string(OPTIX_VERSION % 100);
#else
  env.optix = "none";
#endif
  return env;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

struct Samples {
  std::vector<double> build, compute, total;
  void add(double b, double c) {
    build.push_back(b);
    compute.push_back(c);
    total.push_back(b + c);
  }
};

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  const Environment env = environment();
  const bool exists = std::ifstream(o.out).good();
  std::ofstream csv(o.out, std::ios::app);
  if (!exists)
    csv << "suite,method,param,p,N,cutoff,pairs,build_ms,compute_ms,total_ms,total_ms_min,"
           "total_ms_max,reps,timer,gpu,driver,cuda,optix\n";

  for (int param : o.params) {
    for (int p : o.ps) {
      const std::size_t n = raycut::suite_size(param, p);
      const raycut::PointCloud cloud =
          o.suite == "uniform" ? raycut::uniform_suite(param, p) : raycut::surface_suite(param, p);
      float* device_xyz = nullptr;
      const std::size_t bytes = cloud.xyz.size() * sizeof(float);
      if (cudaMalloc(&device_xyz, std::max<std::size_t>(bytes, 4)) != cudaSuccess) {
        (void)cudaGetLastError();
        std::cerr << "# skipped " << o.suite << " " << param << " p=" << p << " N=" << n
                  << ": positions do not fit on the device\n";
        continue;
      }
      check(cudaMemcpy(device_xyz, cloud.xyz.data(), bytes, cudaMemcpyHostToDevice), "upload");
      const raycut::PositionsView view{device_xyz, n, raycut::MemorySpace::device};
      const int reps = (o.few_reps_above > 0 && n > o.few_reps_above) ? o.few_reps : o.reps;

      for (const std::string& method : o.methods) {
        Samples events, host;
        unsigned long long pairs = 0;
        try {
          raycut::Engine engine(method);
          engine.build(view, cloud.cutoff);  // warm-up
          engine.run(raycut::Kernel::lj);
          engine.run(raycut::Kernel::count);
          for (std::uint32_t c : engine.results().count) pairs += c;
          for (int r = 0; r < reps; ++r) {
            engine.build(view, cloud.cutoff);
            engine.run(raycut::Kernel::lj);
            const raycut::Timings& t = engine.last_timings();
            host.add(t.build_ms, t.compute_ms);
            events.add(t.device_build_ms, t.device_compute_ms);
          }
        } catch (const raycut::Error& e) {
          std::cerr << "# skipped " << method << " " << o.suite << " " << param << " p=" << p
                    << " N=" << n << ": " << e.what() << "\n";
          continue;
        }
        for (const auto& [timer, s] : {std::pair<const char*, const Samples&>{"events", events},
                                       std::pair<const char*, const Samples&>{"host", host}}) {
          char line[512];
          std::snprintf(line, sizeof line,
                        "%s,%s,%d,%d,%zu,%.9g,%llu,%.4f,%.4f,%.4f,%.4f,%.4f,%d,%s,%s,%s,%s,%s\n",
                        o.suite.c_str(), method.c_str(), param, p, n,
                        static_cast<double>(cloud.cutoff), pairs, median(s.build),
                        median(s.compute), median(s.total),
                        *std::min_element(s.total.begin(), s.total.end()),
                        *std::max_element(s.total.begin(), s.total.end()), reps, timer,
                        env.gpu.c_str(), env.driver.c_str(), env.cuda.c_str(), env.optix.c_str());
          csv << line;
          if (std::string(timer) == "host") std::cout << line << std::flush;
        }
        csv.flush();
      }
      check(cudaFree(device_xyz), "cudaFree");
    }
  }
  return 0;
}
