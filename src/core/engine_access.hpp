// What raycut's own engines built over an Engine reach beyond its public interface: the
// distributed engine's local engine, over positions that engine has checked already.
#pragma once

#include "core/method.hpp"
#include "raycut/engine.hpp"

namespace raycut::detail {

struct EngineAccess {
  // Engine::update without its finiteness pass (a kernel and a read-back on the device):
  // `positions` are known to be finite.
  static void update_checked(Engine& engine, PositionsView positions) {
    engine.update(positions, true);
  }
  // A built-in kernel over mapped rows (Method::compute_rows) of a built engine of a CPU method
  // with particles; the caller validated the kernel's options (validate_kernel_range).
  static void compute_rows(const Engine& engine, Kernel kernel, const KernelOptions& options,
                           const RowMap& rows, const KernelOutputs& out) {
    engine.impl("compute_rows").compute_rows(kernel, options, rows, out);
  }
  // A neighbour list's count or fill pass over mapped rows (Method::list_rows), the same engines.
  template <class ListPass>
  static void list_rows(const Engine& engine, const RowMap& rows, const ListPass& pass) {
    engine.impl("list_rows").list_rows(rows, pass);
  }
};

}  // namespace raycut::detail
