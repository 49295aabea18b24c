#pragma once
/// @file peer_results.h
/// @brief Other programs' renderers in `brickyard bench`: the results a peers script
/// (bench/peers/dvr.sh: VTK's ray casters) measured on the same scene, read from its
/// peers.json, and turned into bench rows whose error is computed here, against the same
/// reference as every back end's.
///
/// peers.json: {"peers": [{"name", "quality", "quality_value", "threads", "first_frame_s",
/// "steady_s": [...], "image", "read_s", "peak_rss_bytes", "description"}, ...]}; "image" is
/// a PNG of the frame (linear RGB bytes, as brickyard writes them) relative to the file's
/// folder. Every key is checked: an unknown one, a missing one or a value out of range is an
/// error naming the file and the key path ("peers[1].steady_s").

#include <cstdint>
#include <string>
#include <vector>

#include "renderers/common/frame.h"
#include "report/bench_report.h"

namespace brickyard {

struct PeerResult {
  std::string name;            ///< "vtk-fixed-point": the row's back-end column
  std::string quality;         ///< its setting, "sample=0.5" ("" for none)
  double quality_value = 0;    ///< orders a peer's rows in the plot
  int threads = 1;
  double first_frame_s = 0;    ///< its first frame, from the data in memory to the image
  std::vector<double> steady_s;  ///< the frames after it, nothing moved
  std::string image;           ///< the PNG, as a path (resolved against the file's folder)
  double read_s = 0;           ///< reading the volume before the first frame (0: not measured)
  uint64_t peak_rss_bytes = 0; ///< 0: not measured
  std::string description;     ///< what it is: program, version, settings
};

/// @brief Reads peers.json. Names are unique, not "reference", and match [A-Za-z0-9_.+-]+.
/// @throws Error(io) when the file cannot be read, Error(format) naming the key otherwise.
std::vector<PeerResult> read_peer_results(const std::string& path);

/// @brief The bench row of a peer: its times as its script measured them (its first frame is
/// its cold frame and its converged image, as a peer has nothing to refine), and its image's
/// error against `truth` (colour only: a PNG has neither depth nor normals).
/// @throws Error(format) naming the image when it cannot be read or its size is not the
/// truth's.
BenchRow peer_row(const PeerResult& peer, const FrameBuffers& truth, double voxel_size);

}  // namespace brickyard
