// MPEG-2 video syntax the reader inspects in packets (ISO/IEC 13818-2 6.2.3.1):
// the picture coding extension, the one home of where picture_structure sits.
#pragma once

#include <cstddef>
#include <cstdint>

namespace slapse {

// A picture coding extension starts with 00 00 01 B5 and its extension id 8
// (the high nibble of byte 4); picture_structure is the low two bits of its
// byte 6: 1 top field, 2 bottom field, 3 frame picture.
constexpr size_t kMpeg2PictureStructureByte = 6;
constexpr int kMpeg2TopField = 1, kMpeg2BottomField = 2;

// Offset of the first picture coding extension at or after `from` in
// data[0, size) whose picture_structure byte is inside; `size` when there is
// none.
inline size_t FindMpeg2PictureCodingExtension(const uint8_t* data, size_t size, size_t from = 0) {
  for (size_t i = from; i + kMpeg2PictureStructureByte < size; ++i) {
    if (data[i] == 0 && data[i + 1] == 0 && data[i + 2] == 1 && data[i + 3] == 0xB5 &&
        (data[i + 4] >> 4) == 8) {
      return i;
    }
  }
  return size;
}

}  // namespace slapse
