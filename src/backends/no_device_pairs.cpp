// raycut/device_pairs.hpp in a build without CUDA: every entry point says so.
#include <string>

#include "raycut/device_pairs.hpp"
#include "raycut/error.hpp"

namespace raycut {
namespace {
[[noreturn]] void no_cuda(const char* call) {
  throw Error(ErrorCode::unsupported,
              std::string(call) +
                  ": raycut was built without CUDA (stream-ordered pair lists "
                  "run on the GPU only)");
}
}  // namespace

void list_pairs_small_systems(const Context&, const DeviceSystems&, double, const PairOptions&,
                              const StaticPairs&) {
  no_cuda("list_pairs_small_systems");
}
std::int64_t read_pair_count(const Context&, const std::int64_t*) {
  no_cuda("read_pair_count");
}
StaticPairBuffer::StaticPairBuffer(std::size_t, const Context&) {
  no_cuda("StaticPairBuffer");
}
StaticPairBuffer::~StaticPairBuffer() = default;
StaticPairBuffer::StaticPairBuffer(StaticPairBuffer&&) noexcept = default;
StaticPairBuffer& StaticPairBuffer::operator=(StaticPairBuffer&&) noexcept = default;
void StaticPairBuffer::release() noexcept {}
std::int64_t* StaticPairBuffer::i() const {
  return nullptr;
}
std::int64_t* StaticPairBuffer::j() const {
  return nullptr;
}
std::int32_t* StaticPairBuffer::shifts() const {
  return nullptr;
}
std::int64_t* StaticPairBuffer::count() const {
  return nullptr;
}
StaticPairs StaticPairBuffer::view(std::int64_t) const {
  no_cuda("StaticPairBuffer::view");
}
std::int64_t list_pairs_small_systems_growing(const Context&, const DeviceSystems&, double,
                                              const PairOptions&, StaticPairBuffer&) {
  no_cuda("list_pairs_small_systems_growing");
}

DeviceVerletList::DeviceVerletList(const Context&, double, double, std::size_t,
                                   const PairOptions&) {
  no_cuda("DeviceVerletList");
}
DeviceVerletList::~DeviceVerletList() = default;
void DeviceVerletList::update(const DeviceSystems&) {
  no_cuda("DeviceVerletList::update");
}
void DeviceVerletList::reserve(std::size_t) {
  no_cuda("DeviceVerletList::reserve");
}

}  // namespace raycut
