// Peers in `brickyard bench`: reading peers.json strictly, and a peer's row from its image.

#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "core/error.h"
#include "core/image.h"
#include "report/peer_results.h"
#include "test_util.h"

namespace brickyard {
namespace {

std::string write_peers(const testing::TempDir& dir, const std::string& text) {
  const std::string path = dir.file("peers.json");
  std::ofstream(path) << text;
  return path;
}

const std::string kPeer =
    R"({"name": "vtk-fixed-point", "quality": "sample=1", "quality_value": 1, "threads": 2, "first_frame_s": 0.5,
        "steady_s": [0.15, 0.13, 0.14], "image": "vtk.png", "read_s": 0.9, "peak_rss_bytes": 1000,
        "description": "VTK 9.1"})";

TEST(PeerResults, ReadsEveryFieldAndResolvesTheImageAgainstTheFile) {
  testing::TempDir dir;
  const auto peers = read_peer_results(write_peers(dir, R"({"peers": [)" + kPeer + "]}"));
  ASSERT_EQ(peers.size(), 1u);
  const PeerResult& p = peers[0];
  EXPECT_EQ(p.name, "vtk-fixed-point");
  EXPECT_EQ(p.quality, "sample=1");
  EXPECT_EQ(p.quality_value, 1.0);
  EXPECT_EQ(p.threads, 2);
  EXPECT_EQ(p.first_frame_s, 0.5);
  EXPECT_EQ(p.steady_s, (std::vector<double>{0.15, 0.13, 0.14}));
  EXPECT_EQ(p.image, dir.file("vtk.png"));
  EXPECT_EQ(p.read_s, 0.9);
  EXPECT_EQ(p.peak_rss_bytes, 1000u);
  EXPECT_EQ(p.description, "VTK 9.1");
}

TEST(PeerResults, BadFilesAreErrorsNamingTheKey) {
  testing::TempDir dir;
  auto expect_error = [&](const std::string& text, const std::string& key) {
    const std::string path = write_peers(dir, text);
    try {
      read_peer_results(path);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << what;
      EXPECT_NE(what.find(key), std::string::npos) << key << ": " << what;
    }
  };
  auto with = [&](const std::string& from, const std::string& to) {
    std::string p = kPeer;
    p.replace(p.find(from), from.size(), to);
    return R"({"peers": [)" + p + "]}";
  };
  expect_error("[]", "peers");
  expect_error(R"({"peer": []})", "peers");
  expect_error(R"({"peers": {}})", "peers");
  expect_error(R"({"peers": [1]})", "peers[0]");
  expect_error(with(R"("steady_s": [0.15, 0.13, 0.14])", R"("steady_s": [])"), "peers[0].steady_s");
  expect_error(with(R"("steady_s": [0.15, 0.13, 0.14])", R"("steady_s": [0.1, -1])"), "peers[0].steady_s");
  expect_error(with(R"("first_frame_s": 0.5)", R"("first_frame_s": 0)"), "peers[0].first_frame_s");
  expect_error(with(R"("name": "vtk-fixed-point")", R"("name": "vtk fixed")"), "peers[0].name");
  expect_error(with(R"("name": "vtk-fixed-point")", R"("name": "reference")"), "peers[0].name");
  expect_error(with(R"("threads": 2)", R"("threads": 0)"), "peers[0].threads");
  expect_error(with(R"("read_s": 0.9)", R"("read_secs": 0.9)"), "read_secs");  // a misspelt key
  expect_error(with(R"("image": "vtk.png", )", ""), "peers[0].image");
  expect_error(R"({"peers": [)" + kPeer + "," + kPeer + "]}", "peers[1]");  // the same peer twice
}

TEST(PeerResults, RowTakesThePeersTimesAndMeasuresItsImageAgainstTheTruth) {
  testing::TempDir dir;
  PeerResult p = read_peer_results(write_peers(dir, R"({"peers": [)" + kPeer + "]}"))[0];
  FrameBuffers truth(4, 3, FrameOutputs{});
  ImageRGBA8 png(4, 3, Rgba8{51, 102, 204, 255});
  for (int i = 0; i < 12; ++i) truth.color.data()[i] = {0.2f, 0.4f, 0.8f, 1.0f};
  write_png(p.image, png);
  BenchRow row = peer_row(p, truth, 1.0);
  EXPECT_TRUE(row.is_peer);
  EXPECT_EQ(row.backend, "vtk-fixed-point");
  EXPECT_EQ(row.description, "VTK 9.1");
  EXPECT_EQ(row.warm_median_s, 0.14);
  EXPECT_EQ(row.warm_runs, 3);
  EXPECT_EQ(row.cold_median_s, 0.5);
  EXPECT_EQ(row.converged_median_s, 0.5);  // a peer's first frame is its finished image
  EXPECT_EQ(row.converged_frames, 1);
  EXPECT_NEAR(row.error.rmse, 0.0, 1e-7);  // bytes / 255, as brickyard writes linear colour
  EXPECT_EQ(row.first_rmse, row.error.rmse);
  EXPECT_EQ(row.peak_rss_bytes, 1000u);

  // One pixel off by a full channel: RMSE sqrt(1 / (12 * 3)).
  png(1, 1) = Rgba8{51, 102, 204 - 204, 255};
  write_png(p.image, png);
  row = peer_row(p, truth, 1.0);
  EXPECT_NEAR(row.error.rmse, 0.8 / std::sqrt(36.0), 1e-6);

  // An image of another size is named.
  write_png(p.image, ImageRGBA8(5, 3));
  try {
    peer_row(p, truth, 1.0);
    ADD_FAILURE() << "a 5x3 image against a 4x3 bench was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("vtk.png"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("5x3"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace brickyard
