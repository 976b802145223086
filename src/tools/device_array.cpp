// DeviceArray over the library's device services: the same allocator the engine frees with.
#include "raycut/tools/device_array.hpp"

#include <utility>

#include "core/device_services.hpp"

namespace raycut {

DeviceArray::DeviceArray(const std::vector<float>& values) : size_(values.size()) {
  const detail::DeviceServices* device = detail::device_services();
  if (!device)
    throw Error(ErrorCode::unsupported, "device arrays need CUDA; raycut was built without it");
  if (size_ > 0)
    data_ =
        static_cast<float*>(device->upload(values.data(), values.size() * sizeof(float)).release());
}

DeviceArray::~DeviceArray() {
  if (data_) detail::device_services()->free(data_);  // data_ was made by the same services
}

DeviceArray::DeviceArray(DeviceArray&& o) noexcept
    : data_(std::exchange(o.data_, nullptr)), size_(std::exchange(o.size_, 0)) {}

DeviceArray& DeviceArray::operator=(DeviceArray&& o) noexcept {
  std::swap(data_, o.data_);
  std::swap(size_, o.size_);
  return *this;
}

}  // namespace raycut
