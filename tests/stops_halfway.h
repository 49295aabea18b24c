#pragma once
// A build source that fails halfway, for tests of what an interrupted build leaves.

#include <memory>
#include <span>
#include <string>

#include "core/error.h"
#include "fields/field.h"
#include "preprocess/volume_source.h"

namespace brickyard::testing {

/// A u8 `size`^3 grid of a field whose reads fail past its first half of slices: the build it
/// feeds stops, leaving an incomplete store, as a killed import does.
class StopsHalfway final : public VolumeSource {
 public:
  explicit StopsHalfway(const std::string& field = "sphere", int64_t size = 32)
      : inner_(make_field_source(make_field(field), Vec3s(size), ValueType::u8)), stop_at_(size / 2) {}
  std::string name() const override { return "stops halfway"; }
  Vec3s dims() const override { return inner_->dims(); }
  ValueType type() const override { return inner_->type(); }
  void read_slab(int64_t z0, int64_t z1, std::span<std::byte> out) override {
    if (z0 >= stop_at_) throw Error(Errc::io, "stopped halfway");
    inner_->read_slab(z0, z1, out);
  }
  std::string describe_json() const override { return inner_->describe_json(); }

 private:
  std::unique_ptr<VolumeSource> inner_;
  int64_t stop_at_;
};

}  // namespace brickyard::testing
