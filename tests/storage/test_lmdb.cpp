#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <vector>

#include "core/error.h"
#include "storage/lmdb_env.h"
#include "test_util.h"

namespace brickyard::lmdb {
namespace {

TEST(LmdbEnv, PutsAreVisibleZeroCopyAfterCommitInKeyOrder) {
  testing::TempDir dir;
  Env env(dir.path().string(), {});
  Database db = env.open_database("bricks", true);
  BatchWriter writer(env);
  for (const char* k : {"b", "c", "a"}) writer.put(db, as_bytes(k), as_bytes(std::string("value-") + k));
  {
    ReadTxn txn(env);
    EXPECT_FALSE(txn.get(db, as_bytes("a")).has_value());  // nothing committed yet
  }
  writer.commit();
  ReadTxn txn(env);
  auto v = txn.get(db, as_bytes("a"));
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(v->data()), v->size()), "value-a");
  std::string order;
  txn.for_each(db, [&](Bytes key, Bytes) {
    order += char(key[0]);
    return true;
  });
  EXPECT_EQ(order, "abc");
  EXPECT_EQ(txn.count(db), 3u);
  EXPECT_TRUE(env.has_database("bricks"));
  EXPECT_FALSE(env.has_database("tets"));
}

TEST(LmdbEnv, GrowsTheMapWhenItFillsAndKeepsEveryRecord) {
  testing::TempDir dir;
  EnvOptions options;
  options.map_size = 256 << 10;  // 256 KiB
  Env env(dir.path().string(), options);
  Database db = env.open_database("bricks", true);
  BatchWriter writer(env, 1 << 20);
  const std::vector<std::byte> value(16 << 10, std::byte{7});
  for (int i = 0; i < 200; ++i) writer.put(db, as_bytes(fmt::format("{:08}", i)), value);  // 3.2 MB
  writer.commit();
  EXPECT_GT(env.map_size(), uint64_t(3) << 20);
  ReadTxn txn(env);
  EXPECT_EQ(txn.count(db), 200u);
  EXPECT_EQ(txn.get(db, as_bytes("00000199"))->size(), value.size());
}

TEST(LmdbEnv, AFullMapWithoutGrowthIsAResourceErrorNamingTheStore) {
  testing::TempDir dir;
  EnvOptions options;
  options.map_size = 128 << 10;
  options.growth = false;
  Env env(dir.path().string(), options);
  Database db = env.open_database("bricks", true);
  BatchWriter writer(env, 64 << 20);
  const std::vector<std::byte> value(16 << 10, std::byte{1});
  for (int i = 0; i < 64; ++i) writer.put(db, as_bytes(fmt::format("{:08}", i)), value);
  try {
    writer.commit();
    FAIL() << "a 1 MiB batch fitted in a 128 KiB map";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::resource);
    EXPECT_EQ(e.file(), dir.path().string());
    EXPECT_NE(std::string(e.what()).find("growth is disabled"), std::string::npos) << e.what();
  }
  ReadTxn txn(env);
  EXPECT_EQ(txn.count(db), 0u);  // the failed batch left nothing behind
}

TEST(LmdbEnv, ErrorsNameThePathAndDatabase) {
  testing::TempDir dir;
  EnvOptions ro;
  ro.read_only = true;
  try {
    Env env(dir.file("missing"), ro);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_EQ(e.file(), dir.file("missing"));
  }
  {
    Env env(dir.path().string(), {});
    env.open_database("manifest", true);
  }
  Env env(dir.path().string(), ro);
  try {
    env.open_database("nodes", false);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), Errc::not_found);
    EXPECT_NE(std::string(e.what()).find("'nodes'"), std::string::npos) << e.what();
  }
  bool other = true;
  EXPECT_EQ(env.database_names(&other), std::vector<std::string>{"manifest"});
  EXPECT_FALSE(other);
}

TEST(LmdbEnv, ReadTransactionsWorkFromOtherThreads) {
  testing::TempDir dir;
  Env env(dir.path().string(), {});
  Database db = env.open_database("bricks", true);
  BatchWriter writer(env);
  writer.put(db, as_bytes("k"), as_bytes("v"));
  writer.commit();
  ReadTxn txn(env);  // begun here, used on another thread (MDB_NOTLS)
  std::string seen;
  std::thread t([&] {
    auto v = txn.get(db, as_bytes("k"));
    seen.assign(reinterpret_cast<const char*>(v->data()), v->size());
  });
  t.join();
  EXPECT_EQ(seen, "v");
}

}  // namespace
}  // namespace brickyard::lmdb
