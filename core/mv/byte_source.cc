#include "core/mv/byte_source.h"

#include <algorithm>
#include <cstring>

namespace slapse {

int MemoryByteSource::Read(uint8_t* buf, int size) {
  if (size <= 0) return 0;
  const size_t n = std::min(static_cast<size_t>(size), data_.size() - pos_);
  std::memcpy(buf, data_.data() + pos_, n);
  pos_ += n;
  return static_cast<int>(n);
}

}  // namespace slapse
