#pragma once
/// @file background.h
/// @brief The value that fills a volume's border (CT air, MRI outside the head, land in an
/// ocean model's padding), for `import --background auto`: bricks within the constant
/// tolerance of it are stored empty.

namespace brickyard {

class VolumeSource;

/// @brief The median of the finite values on the volume's six faces: the first and last
/// z-slices and the border rows and columns of up to `max_slices` slices evenly spaced between
/// them (every slice for a source that cannot skip). A face holding more than about a million
/// voxels is subsampled evenly. Rewinds the source when done.
double estimate_background(VolumeSource& source, int max_slices = 64);

}  // namespace brickyard
