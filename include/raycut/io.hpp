// Positions in files users already have: CSV (x,y,z per line, optional header) and extended XYZ
// (OVITO). Errors are Error(io) naming the file and line.
#pragma once

#include <string>

#include "raycut/generators.hpp"

namespace raycut {

// Reads by extension (case-insensitive): .csv, .xyz / .extxyz. The cutoff field of the result
// is 0 (unknown), its name the path. "nan" and "inf" read as such (the engine refuses them).
//   CSV: one particle per line, exactly 3 comma-separated numbers; an optional first line with
//        no number is a header; blank lines and lines starting with '#' are skipped.
//   XYZ: line 1 the count N, line 2 a comment, then N lines "species x y z ...". A
//        Properties=name:type:count:... key on line 2 locates pos:R:3; without one, x y z follow
//        the species. Only the first frame is read.
PointCloud read_positions(const std::string& path);
// Both write each float in its shortest form that reads back to the same bits, so a round trip
// through read_positions is exact. CSV starts with the header "x,y,z"; XYZ writes species "X"
// and the comment line Properties=species:S:1:pos:R:3.
void write_csv(const std::string& path, const PointCloud& cloud);
void write_xyz(const std::string& path, const PointCloud& cloud);

}  // namespace raycut
