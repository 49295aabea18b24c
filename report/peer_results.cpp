#include "report/peer_results.h"

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.h"
#include "core/image.h"
#include "core/json_reader.h"
#include "renderers/common/metrics.h"

namespace brickyard {
namespace fs = std::filesystem;

namespace {

bool valid_name(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '+' || c == '-';
  });
}

PeerResult read_peer(JsonObjectReader r, const fs::path& folder) {
  PeerResult p;
  p.name = r.string("name");
  if (!valid_name(p.name) || p.name == "reference")
    throw r.error("name", fmt::format("'{}' is not a peer's name (letters, digits and _ . + -; not 'reference')", p.name));
  p.quality = r.string("quality", "");
  p.quality_value = r.number("quality_value", 0);
  p.threads = int(r.integer("threads", 1, 1, 4096));
  p.first_frame_s = r.required_number("first_frame_s", 1e-9, 1e9);
  const nlohmann::json& steady = r.require("steady_s");
  const auto times = json_exact<std::vector<double>>(steady);
  if (!times || times->empty() || std::any_of(times->begin(), times->end(), [](double t) { return !(t > 0); }))
    throw r.error("steady_s", "must be a non-empty array of positive seconds");
  p.steady_s = *times;
  const std::string image = r.string("image");
  if (image.empty()) throw r.error("image", "must name the peer's PNG");
  p.image = (folder / image).string();
  p.read_s = r.number("read_s", 0, 0, 1e9);
  p.peak_rss_bytes = uint64_t(r.integer("peak_rss_bytes", 0, 0, int64_t(1) << 62));
  p.description = r.string("description", "");
  r.finish();
  return p;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace

std::vector<PeerResult> read_peer_results(const std::string& path) {
  const nlohmann::json doc = read_json_file(path);
  if (!doc.is_object()) throw Error(Errc::format, "must be a JSON object with a 'peers' array").with_file(path);
  JsonObjectReader top(doc, path);
  const nlohmann::json& list = top.require("peers");
  if (!list.is_array()) throw top.error("peers", "must be an array");
  top.finish();
  const fs::path folder = fs::path(path).parent_path();
  std::vector<PeerResult> out;
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string where = fmt::format("peers[{}]", i);
    if (!list[i].is_object()) throw Error(Errc::format, "must be an object").with_file(path).with_field(where);
    PeerResult p = read_peer(JsonObjectReader(list[i], path, where), folder);
    for (const PeerResult& q : out)
      if (q.name == p.name && q.quality == p.quality)
        throw Error(Errc::format, fmt::format("'{}' at '{}' appears twice", p.name, p.quality)).with_file(path).with_field(where);
    out.push_back(std::move(p));
  }
  return out;
}

BenchRow peer_row(const PeerResult& peer, const FrameBuffers& truth, double voxel_size) {
  const ImageRGBA8 png = read_png(peer.image);
  if (png.width() != truth.width() || png.height() != truth.height())
    throw Error(Errc::format, fmt::format("is {}x{} pixels; the bench renders {}x{}", png.width(), png.height(),
                                          truth.width(), truth.height()))
        .with_file(peer.image);
  FrameBuffers frame;
  frame.color = Image<Rgbaf>(png.width(), png.height());
  for (size_t i = 0; i < png.size(); ++i) {
    const Rgba8 c = png.data()[i];
    frame.color.data()[i] = {c.r / 255.0f, c.g / 255.0f, c.b / 255.0f, 1.0f};
  }
  BenchRow row;
  row.backend = peer.name;
  row.quality = peer.quality;
  row.quality_value = peer.quality_value;
  row.is_peer = true;
  row.description = peer.description;
  row.peak_rss_bytes = peer.peak_rss_bytes;
  row.width = png.width();
  row.height = png.height();
  row.threads = peer.threads;
  row.cold_median_s = row.cold_p95_s = peer.first_frame_s;
  row.cold_runs = 1;
  row.converged_median_s = peer.first_frame_s;
  row.converged_frames = 1;
  row.still_median_s = peer.first_frame_s;
  row.still_frames = 1;
  row.warm_median_s = median(peer.steady_s);
  std::vector<double> steady = peer.steady_s;
  row.warm_p95_s = percentile(steady, 95);
  row.warm_runs = int(peer.steady_s.size());
  row.error = compare_frames(frame, truth, voxel_size);
  row.first_rmse = row.error.rmse;
  row.first_ssim = row.error.ssim;
  return row;
}

}  // namespace brickyard
