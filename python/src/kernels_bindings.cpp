// The kernel calls of Engine: compute (the parameters and per-particle inputs of raycut's kernel
// catalogue, checked and passed to run()), results, and the catalogue itself.
#include <nanobind/stl/string.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"
#include "errors.hpp"
#include "raycut/kernels.hpp"
#include "raycut/tools/device_array.hpp"

namespace raycut_py {

namespace {

// The results of the last run() of a kernel, taken out of the engine under its lock: host
// copies of device results (`to_host`), or the engine's own arrays moved out (no copy: a later
// run() sizes new ones, so these stay as they are).
struct TakenResults {
  std::size_t n = 0;
  MemorySpace space = MemorySpace::host;
  bool copied = false;
  raycut::Results copies;
  raycut::OwnedResults owned;
};

TakenResults take_results(raycut::Engine& engine, bool to_host) {  // the lock held
  TakenResults taken;
  taken.n = engine.size();
  taken.space = engine.space();
  taken.copied = taken.space == MemorySpace::device && to_host;
  if (taken.copied)
    taken.copies = engine.results();
  else
    taken.owned = engine.take_results();
  return taken;
}

// The arrays `kernel` produces (raycut::produces), empty ones for N = 0; with the GIL.
nb::dict results_dict(TakenResults& t, raycut::Kernel kernel) {
  const raycut::KernelProduces produces = raycut::produces(kernel);
  const std::size_t n = t.n;
  nb::dict out;
  if (t.copied) {
    raycut::Results& r = t.copies;
    if (produces.count) out["count"] = host_array(std::move(r.count), {n}, index_dtype(n));
    if (produces.energy) out["energy"] = host_array(std::move(r.energy), {n});
    if (produces.force) out["force"] = host_array(std::move(r.force), {n, 3});
    if (produces.virial) out["virial"] = host_array(std::move(r.virial), {n, 6});
    if (produces.density) out["density"] = host_array(std::move(r.density), {n});
    return out;
  }
  const raycut::ResultsView& v = t.owned.view;
  auto put = [&](const char* name, const void* data, std::vector<std::size_t> shape,
                 nb::dlpack::dtype dtype) {
    out[name] = wrap(data, std::move(shape), dtype, t.owned.owner, t.space);
  };
  if (produces.count) put("count", v.count, {n}, index_dtype(n));
  if (produces.energy) put("energy", v.energy, {n}, dtype_of<float>());
  if (produces.force) put("force", v.force, {n, 3}, dtype_of<float>());
  if (produces.virial) put("virial", v.virial, {n, 6}, dtype_of<float>());
  if (produces.density) put("density", v.density, {n}, dtype_of<float>());
  return out;
}

// A per-particle float input of a kernel (raycut::KernelInput: sph_force's velocity, density,
// pressure, coulomb_dsf's charge) where the method works: read in place there, copied to the
// device (raycut::DeviceArray) from the host. `source` is read with the GIL held; the rest
// (checked against the engine's size) under the engine's lock, since another thread may build
// it with another N in between.
struct KernelInput {
  const raycut::KernelInput* spec = nullptr;
  const float* data = nullptr;
  std::optional<raycut::DeviceArray> device_copy;
  FloatInput source;
};

void check_kernel_input(KernelInput& out, const raycut::Engine& engine) {
  const raycut::KernelInput& spec = *out.spec;
  const std::string name(spec.name);
  // One value (or vector) per source, or per target: the targets are the queries with query
  // points, the sources otherwise.
  const std::size_t n = spec.end == raycut::InputEnd::sources ? engine.sources() : engine.size();
  const std::size_t components = spec.components;
  const std::vector<std::size_t>& shape = out.source.shape;
  const bool ok = components > 1 ? shape.size() == 2 && shape[0] == n && shape[1] == components
                                 : shape.size() == 1 && shape[0] == n;
  const char* per = spec.end == raycut::InputEnd::queries ? " per query" : " per particle";
  if (!ok)
    value_error(name + " must have shape " +
                (components > 1 ? "(" + std::to_string(n) + ", " + std::to_string(components) + ")"
                                : "(" + std::to_string(n) + ",)") +
                " (one " + (components > 1 ? "vector" : "value") + per + "), got " +
                describe_shape(shape));
  out.data = out.source.data;
  if (out.source.space == MemorySpace::host) {
    // Host values are checked here (device ones are read in place, unchecked): a zero or
    // non-finite density, a non-finite pressure, velocity or charge gives non-finite results.
    for (std::size_t k = 0; k < n * components; ++k) {
      const float value = out.data[k];
      if (!std::isfinite(value) || (spec.positive && !(value > 0.0f)))
        value_error(name + "[" + std::to_string(k / components) + "] = " + number(value) +
                    (spec.positive ? ": must be finite and > 0" : ": must be finite"));
    }
  }
  if (out.source.space == engine.space()) return;
  if (engine.space() == MemorySpace::host)
    value_error(name + " is in device memory but method '" + engine.method() +
                "' works on the host: pass it on the host");
  out.device_copy.emplace(std::vector<float>(out.data, out.data + n * components));
  out.data = out.device_copy->data();
}

// Sets the parameter `name` (of any built-in kernel: one call may pass every kernel's) in options.
void set_kernel_parameter(raycut::KernelOptions& options, const std::string& name,
                          nb::handle value) {
  bool found = false;
  std::vector<std::string_view> known;  // each name once (kernels share parameters)
  raycut::for_each_kernel([&](auto spec) {
    for (const raycut::KernelParameter& p : decltype(spec)::parameters) {
      if (std::find(known.begin(), known.end(), p.name) == known.end()) known.push_back(p.name);
      if (found || p.name != name) continue;
      found = true;
      if (p.flag)
        options.*p.flag = nb::cast<bool>(value);
      else
        options.*p.value = nb::cast<float>(value);
    }
  });
  if (found) return;
  std::string list;
  for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
  value_error("unknown kernel parameter '" + name + "' (known: " + list + ")");
}

}  // namespace

nb::dict results(PyEngine& locked_engine, std::string_view kernel_name, bool to_host) {
  const raycut::Kernel kernel = raycut::parse_kernel(kernel_name);
  TakenResults taken;
  {
    Exclusive hold(locked_engine.mutex);
    taken = take_results(locked_engine.engine, to_host);
  }
  return results_dict(taken, kernel);
}

nb::dict compute(PyEngine& locked_engine, std::string_view kernel_name, nb::dict parameters,
                 nb::dict inputs, bool to_host) {
  const raycut::Kernel kernel = raycut::parse_kernel(kernel_name);
  raycut::KernelOptions options;
  for (auto [key, value] : parameters)
    set_kernel_parameter(options, nb::cast<std::string>(key), value);
  std::deque<KernelInput> given;  // stable addresses, no moves
  raycut::visit_kernel(kernel, [&](auto spec) {
    using Spec = decltype(spec);
    for (auto [key, value] : inputs) {
      const std::string name = nb::cast<std::string>(key);
      const raycut::KernelInput* found = nullptr;
      std::string known;
      for (const raycut::KernelInput& input : Spec::inputs) {
        if (input.name == name) found = &input;
        known += (known.empty() ? "" : ", ") + std::string(input.name);
      }
      if (!found)
        value_error("kernel " + std::string(Spec::name) + " reads no input '" + name +
                    "' (its inputs: " + (known.empty() ? "none" : known) + ")");
      if (value.is_none()) continue;
      KernelInput& in = given.emplace_back();
      in.spec = found;
      in.source = float_input(value, found->name.data());
    }
  });
  TakenResults taken;
  {
    Exclusive hold(locked_engine.mutex);
    raycut::Engine& engine = locked_engine.engine;
    for (KernelInput& in : given) {
      check_kernel_input(in, engine);
      in.spec->field(options) = in.data;
    }
    engine.run(kernel, options);
    taken = take_results(engine, to_host);
  }
  return results_dict(taken, kernel);
}

nb::list kernel_catalogue() {
  nb::list out;
  const raycut::KernelOptions defaults;
  raycut::for_each_kernel([&](auto spec) {
    using Spec = decltype(spec);
    nb::list parameters, inputs, outputs;
    for (const raycut::KernelParameter& p : Spec::parameters) {
      nb::dict d;
      d["name"] = std::string(p.name);
      d["type"] = p.flag ? "bool" : "float";
      if (p.flag)
        d["default"] = defaults.*p.flag;
      else
        d["default"] = static_cast<double>(defaults.*p.value);
      d["min"] = p.min;
      d["max"] = p.max;
      parameters.append(d);
    }
    for (const raycut::KernelInput& in : Spec::inputs) {
      nb::dict d;
      d["name"] = std::string(in.name);
      d["components"] = in.components;
      d["end"] = in.end == raycut::InputEnd::both
                     ? "both"
                     : (in.end == raycut::InputEnd::sources ? "sources" : "queries");
      d["positive"] = in.positive;
      inputs.append(d);
    }
    for (const raycut::KernelOutputField& field : raycut::kernel_output_fields)
      if (Spec::outputs.*field.produced)
        outputs.append(nb::make_tuple(std::string(field.name), field.components));
    nb::dict k;
    k["name"] = std::string(Spec::name);
    k["parameters"] = parameters;
    k["inputs"] = inputs;
    k["outputs"] = outputs;
    out.append(k);
  });
  return out;
}

}  // namespace raycut_py
