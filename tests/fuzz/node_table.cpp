// A grid store's node table (storage/store.h): Store's open (load_node_table) and every read
// that trusts it (read_brick, read_page) over untrusted node records, as a store whose `nodes`
// database was damaged or forged hands them over (table chunks written without a checksum are
// read unchecked).
//
// The target builds three small stores once (u8, u16, f32; 20^3 voxels in 8^3 bricks, three
// levels) with the real builder. Input: one byte choosing the store and the mode, then node
// records (16 bytes each: min, max, constant value as floats, flags) written over the store's
// real table from its first record on (level 0 first); in "exact" mode (bit 7) the rest is
// level 0's chunk as it is, whatever its size. Then the store is opened and every brick read.

#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/lmdb_env.h"
#include "storage/store.h"
#include "tests/fuzz/fuzz_util.h"

using namespace brickyard;

namespace {

/// The key of a node-table chunk, as storage/store.cpp writes it: big-endian level, chunk.
std::array<std::byte, 8> node_chunk_key(uint32_t level, uint32_t chunk) {
  std::array<std::byte, 8> k{};
  for (int i = 0; i < 4; ++i) {
    k[size_t(i)] = std::byte((level >> (24 - 8 * i)) & 0xff);
    k[size_t(4 + i)] = std::byte((chunk >> (24 - 8 * i)) & 0xff);
  }
  return k;
}

struct Fixture {
  std::string dir;
  GridLayout layout;
  std::vector<std::vector<std::byte>> table;  // per level, the records as built (no checksum)
};

const Fixture& fixture(int which) {
  static std::map<int, Fixture> fixtures;
  auto it = fixtures.find(which);
  if (it != fixtures.end()) return it->second;
  static constexpr ValueType kTypes[] = {ValueType::u8, ValueType::u16, ValueType::f32};
  Fixture f;
  f.dir = (fuzz::temp_dir() / ("store-" + std::to_string(which))).string();
  auto source = make_field_source(make_field("sphere"), Vec3s(20), kTypes[which]);
  BuildOptions options;
  options.brick_size = 8;
  options.apron = 1;
  options.check_disk = false;
  options.map_size = uint64_t(16) << 20;
  build_store(*source, f.dir, options);
  {
    const Store store(f.dir);
    f.layout = store.layout();
    for (int l = 0; l < f.layout.levels; ++l) {
      const auto& records = store.nodes().level(l);
      const auto* p = reinterpret_cast<const std::byte*>(records.data());
      f.table.emplace_back(p, p + records.size() * sizeof(NodeRecord));
    }
  }
  return fixtures.emplace(which, std::move(f)).first->second;
}

void write_table(const Fixture& f, const std::vector<std::vector<std::byte>>& chunks) {
  lmdb::EnvOptions options;
  options.no_sync = true;
  options.map_size = uint64_t(16) << 20;
  lmdb::Env env(f.dir, options);
  const lmdb::Database nodes = env.open_database(kNodesDb, false);
  lmdb::BatchWriter writer(env);
  for (size_t l = 0; l < chunks.size(); ++l) {
    const auto key = node_chunk_key(uint32_t(l), 0);
    writer.put(nodes, lmdb::Bytes(key.data(), key.size()), lmdb::Bytes(chunks[l].data(), chunks[l].size()));
  }
  writer.commit();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::Prefix in(data, size);
  const uint8_t mode = in.u8();
  const Fixture& f = fixture(mode % 3);
  std::vector<std::vector<std::byte>> chunks = f.table;
  const auto* bytes = reinterpret_cast<const std::byte*>(in.rest());
  if (mode & 0x80) {
    chunks[0].assign(bytes, bytes + in.rest_size());
  } else {
    size_t pos = 0;
    for (auto& chunk : chunks)
      for (size_t i = 0; i < chunk.size() && pos < in.rest_size(); ++i) chunk[i] = bytes[pos++];
  }
  write_table(f, chunks);
  return fuzz::run_one([&] {
    const Store store(f.dir);
    std::vector<std::byte> out(store.format().bytes());
    const auto txn = store.begin_read();
    for (int l = 0; l < f.layout.levels; ++l)
      for (int64_t i = 0; i < f.layout.brick_count(l); ++i) {
        const BrickKey key = f.layout.key_at(l, i);
        // A damaged brick is drawn around, one at a time: every brick is read.
        fuzz::run_one([&] { store.read_brick(txn, key, out); });
        fuzz::run_one([&] { store.read_page(txn, PageKey{RecordKind::brick, key.code()}, out); });
      }
  });
}
