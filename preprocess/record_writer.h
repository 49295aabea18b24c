#pragma once
/// @file record_writer.h
/// @brief The build's writer thread (internal to preprocess/builder.cpp): takes encoded records
/// off the compute threads and commits them to the store in batches, with the checkpoints in
/// order among them.

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "core/brick_key.h"
#include "core/timing.h"
#include "storage/store.h"

namespace brickyard::build_detail {

// Writer thread: takes encoded records off the compute threads and commits them in batches.
// Guarded by mutex_: queue_, queued_bytes_, closing_, error_. The StoreWriter is used by the
// writer thread only (until close() has joined it).
class RecordWriter {
 public:
  /// Records of time step `step`.
  RecordWriter(StoreWriter& store, size_t max_queued_bytes, int step)
      : store_(store), max_bytes_(max_queued_bytes), step_(step) {
    thread_ = std::thread([this] { run(); });
  }
  ~RecordWriter() {
    {
      std::lock_guard lock(mutex_);
      closing_ = true;
      abandon_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

  void push(const BrickKey& key, std::vector<std::byte>&& record) { enqueue({key, std::move(record), false}); }

  /// The build's state after every record pushed so far: committed with them, in order.
  void push_checkpoint(std::vector<std::byte>&& state) { enqueue({{}, std::move(state), true}); }

  /// Seconds the writer spent on the last checkpoint (compressing and committing it).
  double last_checkpoint_seconds() const { return last_checkpoint_seconds_.load(std::memory_order_relaxed); }

  /// Waits until every record is handed to the store; rethrows the writer's error.
  void close() {
    {
      std::lock_guard lock(mutex_);
      closing_ = true;
    }
    cv_.notify_all();
    thread_.join();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  struct Item {
    BrickKey key;
    std::vector<std::byte> record;
    bool checkpoint = false;
  };

  void enqueue(Item&& item) {
    std::unique_lock lock(mutex_);
    space_.wait(lock, [&] { return queued_bytes_ < max_bytes_ || error_; });
    if (error_) std::rethrow_exception(error_);
    queued_bytes_ += item.record.size();
    queue_.push_back(std::move(item));
    cv_.notify_one();
  }

  void run() {
    try {
      while (true) {
        Item item;
        {
          std::unique_lock lock(mutex_);
          cv_.wait(lock, [&] { return !queue_.empty() || closing_; });
          if (abandon_ || (queue_.empty() && closing_)) return;
          item = std::move(queue_.front());
          queue_.pop_front();
          queued_bytes_ -= item.record.size();
        }
        space_.notify_one();
        if (item.checkpoint) {
          const Stopwatch watch;
          store_.put_checkpoint(item.record);
          last_checkpoint_seconds_.store(watch.seconds(), std::memory_order_relaxed);
        } else {
          store_.put_brick(item.key, std::move(item.record), step_);
        }
      }
    } catch (...) {
      std::lock_guard lock(mutex_);
      error_ = std::current_exception();
      space_.notify_all();
    }
  }

  StoreWriter& store_;
  size_t max_bytes_;
  int step_;
  std::mutex mutex_;
  std::condition_variable cv_, space_;
  std::deque<Item> queue_;
  size_t queued_bytes_ = 0;
  bool closing_ = false, abandon_ = false;
  std::exception_ptr error_;
  std::atomic<double> last_checkpoint_seconds_{0};
  std::thread thread_;
};

}  // namespace brickyard::build_detail
