// Positions in files users already have: CSV (x,y,z per line, optional header) and extended XYZ
// (OVITO). Errors are Error(io) naming the file and line.
#pragma once

#include <string>

#include "raycut/tools/generators.hpp"

namespace raycut {

// Reads by extension (case-insensitive): .csv, .xyz / .extxyz. The cutoff field of the result
// is 0 (unknown), its name the path. "nan" and "inf" read as such (the engine refuses them).
//   CSV: one particle per line, exactly 3 comma-separated numbers; an optional first line of 3
//        fields none of which is a number ("x,y,z") is a header (a first line of 3 numbers is
//        data); blank lines and lines starting with '#' are skipped.
//   XYZ: line 1 the count N, line 2 a comment, then N lines "species x y z ...". A
//        Properties=name:type:count:... key on line 2 locates pos:R:3; without one, x y z follow
//        the species. Only the first frame is read; after it, blank lines aside, the file must
//        end or go on with the count line of a next frame (more atoms than the count is an
//        error). The periodic box comes from the comment line as ASE and OVITO write it:
//        Lattice="ax ay az bx by bz cx cy cz" (the rows a, b, c) and pbc="T T F" (T/F/True/
//        False/1/0, any case; one value stands for all three), key=value pairs quoted or not
//        (ASE's tokenizer: "", '', {} or [] delimit a value, spaces around '=' allowed; the last
//        of a repeated key counts). As in ASE's reader, Lattice without pbc means pbc="T T T";
//        pbc with a periodic axis but no Lattice is an error (ASE would give a zero cell, which
//        has no images); neither gives an open box. A malformed Lattice or pbc, or a box that
//        validate() (box.hpp) refuses, is an Error(io) naming file:line.
// Both: a UTF-8 byte order mark is skipped; a line over 1 MiB or a NUL byte is an error (a binary
// file, /dev/zero); tokens quoted in messages are escaped and cut short.
PointCloud read_positions(const std::string& path);
// Both write each float in its shortest form that reads back to the same bits, so a round trip
// through read_positions is exact. CSV starts with the header "x,y,z"; XYZ writes species "X"
// and the comment line Properties=species:S:1:pos:R:3, preceded by Lattice="..." and followed
// by pbc="T T F" when cloud.box is not open (ASE's layout; each cell entry in the shortest form
// that reads back to the same double). CSV has no place for a box: write_csv refuses a periodic
// one (Error(invalid_argument)), as write_xyz refuses one that validate() refuses.
// The file appears whole or not at all
// (written to a temporary file next to it, renamed at the end; a device such as /dev/null is
// written directly); every write is checked: Error(io) naming the path.
void write_csv(const std::string& path, const PointCloud& cloud);
void write_xyz(const std::string& path, const PointCloud& cloud);
// write_csv or write_xyz by the extension, as read_positions (case-insensitive); Error(io) for
// another extension.
void write_positions(const std::string& path, const PointCloud& cloud);
// Throws what write_positions would for the extension of `path`, before any work is done.
void check_positions_extension(const std::string& path);

}  // namespace raycut
