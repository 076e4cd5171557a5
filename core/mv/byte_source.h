// Byte sources for streams that do not come from a file or URL (uploads).
#pragma once

#include <cstdint>
#include <string>

namespace slapse {

class ByteSource {
 public:
  virtual ~ByteSource() = default;
  // Copies up to `size` bytes into `buf`. Returns the number of bytes copied
  // (> 0), 0 at end of stream, or -1 when the source failed. May block.
  virtual int Read(uint8_t* buf, int size) = 0;
};

// A byte source over a string held in memory.
class MemoryByteSource : public ByteSource {
 public:
  explicit MemoryByteSource(std::string data) : data_(std::move(data)) {}
  int Read(uint8_t* buf, int size) override;

 private:
  std::string data_;
  size_t pos_ = 0;
};

}  // namespace slapse
