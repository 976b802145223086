// What raycut's own engines built over an Engine reach beyond its public interface: the
// distributed engine's local engine, over positions that engine has checked already.
#pragma once

#include "raycut/engine.hpp"

namespace raycut::detail {

struct EngineAccess {
  // Engine::update without its finiteness pass (a kernel and a read-back on the device):
  // `positions` are known to be finite.
  static void update_checked(Engine& engine, PositionsView positions) {
    engine.update(positions, true);
  }
};

}  // namespace raycut::detail
