#pragma once
// Damage a store behind the library's back, as a failing disk or a stray write would: the
// tests of what verify, the cache, the back ends and the commands make of it.

#include <gtest/gtest.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "storage/lmdb_env.h"

namespace brickyard::testing {

/// Flips the last byte of a record's stored bytes (its compressed payload), so that decoding
/// it fails its checksum (or LZ4 itself). `database` is one of the store's (storage/store.h:
/// bricks, octree, tets), `key_code` the record's key before its big-endian encoding.
inline void damage_record(const std::string& store, const std::string& database, uint64_t key_code) {
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(database, false);
  std::array<std::byte, 8> key;
  for (int i = 0; i < 8; ++i) key[size_t(i)] = std::byte(key_code >> (56 - 8 * i));
  std::vector<std::byte> value;
  {
    lmdb::ReadTxn txn(env);
    const auto v = txn.get(db, key);
    ASSERT_TRUE(v.has_value()) << store << " has no record " << key_code << " in " << database;
    value.assign(v->begin(), v->end());
  }
  value.back() ^= std::byte{0x5a};
  lmdb::BatchWriter writer(env);
  writer.put(db, key, std::move(value));
  writer.commit();
}

}  // namespace brickyard::testing
