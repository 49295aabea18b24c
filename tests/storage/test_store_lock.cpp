// One writer per store: the lock beside the store's directory, refused to a second writer with
// the holder's pid, released (and its file removed) by the holder.

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "storage/store_lock.h"
#include "test_util.h"

namespace brickyard {
namespace {

namespace fs = std::filesystem;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(StoreWriteLock, ASecondWriterIsRefusedWithTheHoldersPid) {
  testing::TempDir dir;
  const std::string store = dir.file("s");
  {
    StoreWriteLock first(store);
    EXPECT_EQ(first.path(), (fs::weakly_canonical(dir.path()) / ".s.lock").string());
    EXPECT_FALSE(fs::exists(store));  // beside the store: nothing is created in its place
    EXPECT_EQ(store_writer_pid(store), int64_t(::getpid()));
    try {
      StoreWriteLock second(store);
      FAIL() << "two writers held " << store;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), Errc::io);
      EXPECT_EQ(e.file(), store);
      EXPECT_TRUE(contains(e.what(), "another writer (pid " + std::to_string(::getpid()) + ") holds this store"))
          << e.what();
    }
  }
  EXPECT_FALSE(fs::exists(dir.file(".s.lock")));
  EXPECT_FALSE(store_writer_pid(store).has_value());
  EXPECT_NO_THROW(StoreWriteLock again(store));
}

TEST(StoreWriteLock, OneStoreHasOneLockWhateverPathNamesIt) {
  testing::TempDir dir;
  fs::create_directories(dir.file("s"));
  fs::create_directory_symlink(dir.file("s"), dir.file("link"));
  StoreWriteLock held(dir.file("s"));
  EXPECT_THROW(StoreWriteLock other(dir.file("link")), Error);
  EXPECT_THROW(StoreWriteLock other(dir.file("s/")), Error);
  EXPECT_THROW(StoreWriteLock other(dir.file("./s")), Error);
  EXPECT_EQ(store_sibling(dir.file("link"), "rebuilding"), (fs::weakly_canonical(dir.path()) / ".s.rebuilding").string());
}

TEST(StoreWriteLock, AStaleLockFileOfAKilledWriterDoesNotLockTheStore) {
  testing::TempDir dir;
  // What a writer killed with SIGKILL leaves: the file with its pid, no lock on it.
  std::ofstream(dir.file(".s.lock")) << "999999\n";
  EXPECT_FALSE(store_writer_pid(dir.file("s")).has_value());
  EXPECT_NO_THROW(StoreWriteLock taken(dir.file("s")));
  EXPECT_FALSE(fs::exists(dir.file(".s.lock")));
}

}  // namespace
}  // namespace brickyard
