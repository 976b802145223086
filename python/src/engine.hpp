// What the bindings of Engine and VerletList share: the lock that serialises calls on one object
// from several Python threads, and the Python Engine (raycut::Engine with its lock).
#pragma once

#include <nanobind/nanobind.h>

#include <mutex>
#include <string_view>

#include "raycut/engine.hpp"

namespace nb = nanobind;

namespace raycut_py {

// Calls on one Engine or VerletList from several Python threads are serialised by the object's
// mutex; calls on different objects run in parallel (the GIL is released while the library
// works). The GIL is released before the mutex is taken, and taken again only after the mutex
// is released: a thread never waits for the mutex while holding the GIL, nor for the GIL while
// holding the mutex, so the two cannot deadlock.
struct Exclusive {
  nb::gil_scoped_release release;  // first: released before locking, taken after unlocking
  std::lock_guard<std::mutex> lock;
  explicit Exclusive(std::mutex& mutex) : lock(mutex) {}
};

// raycut::Engine with its lock (what the Python class Engine holds).
struct PyEngine {
  raycut::Engine engine;
  std::mutex mutex;
  explicit PyEngine(std::string_view method) : engine(method) {}
};

// A value of the engine read under its lock.
template <class F>
auto locked(PyEngine& e, F&& read) {
  Exclusive hold(e.mutex);
  return read(e.engine);
}

inline const char* space_name(raycut::MemorySpace space) {
  return space == raycut::MemorySpace::host ? "host" : "device";
}

}  // namespace raycut_py
