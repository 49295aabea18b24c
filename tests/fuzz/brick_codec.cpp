// Brick records (storage/brick_codec.h): decode_brick over untrusted record bytes, as a store
// whose record was damaged or forged hands them over; and, for inputs with the round-trip bit
// set, encode_brick over arbitrary voxels, which must decode back to the same bytes.
//
// Input: 8 bytes of parameters (value type, codec and shuffle, brick size, apron, level, x, y,
// z: the brick format of the store and the key asked for), then the record (or the voxels).

#include <cstring>
#include <vector>

#include "storage/brick_codec.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::Prefix in(data, size);
  BrickFormat format;
  format.type = ValueType(1 + in.u8() % 3);
  const uint8_t codec = in.u8();
  format.codec = Codec(codec % 3);
  format.shuffle = codec & 0x10;
  const bool round_trip = codec & 0x80;
  static constexpr int kSizes[] = {8, 16, 32};
  format.brick_size = kSizes[in.u8() % 3];
  format.apron = in.u8() % 3;
  BrickKey key;
  key.level = in.u8() % 20;
  key.x = in.u8();
  key.y = in.u8();
  key.z = in.u8();
  const auto* bytes = reinterpret_cast<const std::byte*>(in.rest());
  std::vector<std::byte> out(format.bytes());
  return fuzz::run_one([&] {
    if (!round_trip) {
      decode_brick(format, key, {bytes, in.rest_size()}, out);
      return;
    }
    std::vector<std::byte> voxels(format.bytes());
    for (size_t i = 0; i < voxels.size() && in.rest_size(); ++i) voxels[i] = bytes[i % in.rest_size()];
    const auto record = encode_brick(format, key, voxels, 0.0f, 1.0f);
    decode_brick(format, key, record, out);
    if (std::memcmp(out.data(), voxels.data(), out.size()) != 0) {
      std::fprintf(stderr, "fuzz: a brick does not decode to the voxels it was encoded from\n");
      std::abort();
    }
  });
}
