#pragma once
/// @file image.h
/// @brief 2D pixel buffers (RGBA8 colour, float depth/error maps) and PNG input/output.
///
/// libpng stays inside image.cpp. PNG files are written to a temporary name and renamed into
/// place, so a reader never sees a half-written image.

#include <cstdint>
#include <string>
#include <vector>

#include "core/error.h"

namespace brickyard {

struct Rgba8 {
  uint8_t r = 0, g = 0, b = 0, a = 0;
  friend constexpr bool operator==(const Rgba8&, const Rgba8&) = default;
};

/// @brief Row-major 2D buffer of T, row 0 at the top (PNG order).
template <typename T>
class Image {
 public:
  Image() = default;
  Image(int width, int height, T fill = T{}) : width_(width), height_(height) {
    if (width < 0 || height < 0) throw Error(Errc::invalid_argument, "image size must not be negative");
    pixels_.assign(size_t(width) * size_t(height), fill);
  }

  int width() const { return width_; }
  int height() const { return height_; }
  size_t size() const { return pixels_.size(); }
  bool empty() const { return pixels_.empty(); }

  T& operator()(int x, int y) { return pixels_[size_t(y) * size_t(width_) + size_t(x)]; }
  const T& operator()(int x, int y) const { return pixels_[size_t(y) * size_t(width_) + size_t(x)]; }
  T* data() { return pixels_.data(); }
  const T* data() const { return pixels_.data(); }
  T* row(int y) { return pixels_.data() + size_t(y) * size_t(width_); }
  const T* row(int y) const { return pixels_.data() + size_t(y) * size_t(width_); }

  void fill(const T& v) { std::fill(pixels_.begin(), pixels_.end(), v); }

  friend bool operator==(const Image&, const Image&) = default;

 private:
  int width_ = 0, height_ = 0;
  std::vector<T> pixels_;
};

using ImageRGBA8 = Image<Rgba8>;
/// @brief Float buffer for depth, error and other scalar maps.
using FloatImage = Image<float>;

/// @brief Writes an 8-bit RGBA PNG; throws Error(io) naming the path on failure.
void write_png(const std::string& path, const ImageRGBA8& image);
/// @brief Reads any PNG (grey, palette, 16-bit, with or without alpha) as 8-bit RGBA.
ImageRGBA8 read_png(const std::string& path);

}  // namespace brickyard
