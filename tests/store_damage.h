#pragma once
// Damage a store behind the library's back, as a failing disk or a stray write would: the
// tests of what verify, the cache, the back ends and the commands make of it.

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "storage/lmdb_env.h"

namespace brickyard::testing {

/// A record's key as LMDB holds it: `code` big-endian (bricks, octree pages, clusters).
inline std::vector<std::byte> big_endian_key(uint64_t code) {
  std::vector<std::byte> key(8);
  for (int i = 0; i < 8; ++i) key[size_t(i)] = std::byte(code >> (56 - 8 * i));
  return key;
}

/// Flips bit `bit` of a record's stored bytes (counted from its first byte; past its end: the
/// last byte's lowest bit). Returns the record's size. `database` is one of the store's
/// (storage/store.h: manifest, nodes, bricks, octree, tet_clusters, tets).
inline size_t flip_record_bit(const std::string& store, const std::string& database, const std::vector<std::byte>& key,
                              uint64_t bit) {
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(database, false);
  std::vector<std::byte> value;
  {
    lmdb::ReadTxn txn(env);
    const auto v = txn.get(db, key);
    EXPECT_TRUE(v.has_value()) << store << " has no such record in " << database;
    if (!v) return 0;
    value.assign(v->begin(), v->end());
  }
  if (bit >= 8 * value.size()) bit = 8 * (value.size() - 1);
  value[size_t(bit / 8)] ^= std::byte(1u << (bit % 8));
  const size_t size = value.size();
  lmdb::BatchWriter writer(env);
  writer.put(db, key, std::move(value));
  writer.commit();
  return size;
}

/// Damages a record's compressed payload (its last byte), so that decoding it fails its
/// checksum (or LZ4 itself); `key_code` is the record's key before its big-endian encoding.
inline void damage_record(const std::string& store, const std::string& database, uint64_t key_code) {
  const std::vector<std::byte> key = big_endian_key(key_code);
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(database, false);
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
