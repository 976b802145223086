// CSV and XYZ: bit-exact round trips, the formats users already have, and errors that name the
// file and line.
#include <gtest/gtest.h>

#include <unistd.h>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "error_helpers.hpp"
#include "raycut/box.hpp"
#include "raycut/error.hpp"
#include "raycut/tools/files.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/io.hpp"

namespace raycut {
namespace {

namespace fs = std::filesystem;

class PositionsIo : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("raycut-io-" + std::to_string(::getpid()) + "-" + test->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::string write_file(const std::string& name, const std::string& contents) const {
    const std::string file = path(name);
    std::ofstream(file, std::ios::binary) << contents;
    return file;
  }

 private:
  fs::path dir_;
};

// Floats whose text form is easy to get wrong.
PointCloud awkward_cloud() {
  PointCloud cloud = make_family("uniform", 200, 0.37f, 11);
  const float extra[] = {0.0f,
                         -0.0f,
                         1.0f / 3.0f,
                         0.1f,
                         1e-7f,
                         std::nextafter(1.0f, 2.0f),
                         std::numeric_limits<float>::denorm_min(),
                         1e-40f,
                         std::numeric_limits<float>::min(),
                         std::numeric_limits<float>::max(),
                         std::numeric_limits<float>::lowest(),
                         16777217.0f,
                         123456.789f,
                         -2.5e-12f,
                         1e5f + 0.0078125f};
  cloud.xyz.insert(cloud.xyz.end(), std::begin(extra), std::end(extra));
  return cloud;
}

void expect_same_bits(const std::vector<float>& read, const std::vector<float>& written) {
  ASSERT_EQ(read.size(), written.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    std::uint32_t a, b;
    std::memcpy(&a, &read[i], 4);
    std::memcpy(&b, &written[i], 4);
    ASSERT_EQ(a, b) << "value " << i << ": read " << read[i] << ", wrote " << written[i];
  }
}

std::string io_error(const std::function<void()>& action) {
  return raycut_test::error_message(ErrorCode::io, action);
}

using raycut_test::contains;

TEST_F(PositionsIo, CsvRoundTripIsBitExact) {
  const PointCloud cloud = awkward_cloud();
  write_csv(path("points.csv"), cloud);
  const PointCloud read = read_positions(path("points.csv"));
  expect_same_bits(read.xyz, cloud.xyz);
  EXPECT_EQ(read.cutoff, 0.0f);
}

TEST_F(PositionsIo, XyzRoundTripIsBitExact) {
  const PointCloud cloud = awkward_cloud();
  write_xyz(path("points.xyz"), cloud);
  expect_same_bits(read_positions(path("points.xyz")).xyz, cloud.xyz);
  std::ifstream in(path("points.xyz"));
  std::string count, comment;
  std::getline(in, count);
  std::getline(in, comment);
  EXPECT_EQ(count, std::to_string(cloud.size()));
  EXPECT_EQ(comment, "Properties=species:S:1:pos:R:3");
}

TEST_F(PositionsIo, EmptyCloudRoundTrips) {
  const PointCloud empty;
  write_csv(path("empty.csv"), empty);
  write_xyz(path("empty.xyz"), empty);
  EXPECT_EQ(read_positions(path("empty.csv")).size(), 0u);
  EXPECT_EQ(read_positions(path("empty.xyz")).size(), 0u);
}

TEST_F(PositionsIo, NanAndInfReadAsSuch) {
  PointCloud cloud;
  cloud.xyz = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
               -std::numeric_limits<float>::infinity()};
  write_csv(path("special.csv"), cloud);
  for (const PointCloud& read :
       {read_positions(path("special.csv")),
        read_positions(write_file("typed.xyz", "1\nhand written\nX NaN inf -Infinity\n"))}) {
    ASSERT_EQ(read.size(), 1u);
    EXPECT_TRUE(std::isnan(read.xyz[0]));
    EXPECT_EQ(read.xyz[1], std::numeric_limits<float>::infinity());
    EXPECT_EQ(read.xyz[2], -std::numeric_limits<float>::infinity());
  }
}

TEST_F(PositionsIo, CsvSkipsHeaderCommentsAndBlankLines) {
  const std::string file = write_file("hand.csv",
                                      "# exported by hand\r\n"
                                      "X, Y, Z\r\n"
                                      "\r\n"
                                      "1, 2.5, -3\r\n"
                                      "   \n"
                                      "# a comment in the middle\n"
                                      "+4,5e-1,6E2\n"
                                      "1e-50,0,.5");  // no final newline; underflow reads as 0
  const PointCloud cloud = read_positions(file);
  const std::vector<float> expected = {1, 2.5f, -3, 4, 0.5f, 600, 0, 0, 0.5f};
  EXPECT_EQ(cloud.xyz, expected);
}

TEST_F(PositionsIo, CsvWithoutHeader) {
  const PointCloud cloud = read_positions(write_file("plain.CSV", "1,2,3\n4,5,6\n"));
  EXPECT_EQ(cloud.size(), 2u);
}

TEST_F(PositionsIo, XyzFindsPosThroughProperties) {
  const std::string file = write_file(
      "ovito.extxyz",
      "2\n"
      "Lattice=\"10 0 0 0 10 0 0 0 10\" Properties=species:S:1:id:I:1:pos:R:3:velo:R:3 pbc=\"T T "
      "T\"\n"
      "H 7 1.5 2 3 9 9 9\n"
      "O\t8\t-1\t-2\t-3\t9\t9\t9\n"
      "3\n"
      "second frame is ignored\n");
  const std::vector<float> expected = {1.5f, 2, 3, -1, -2, -3};
  EXPECT_EQ(read_positions(file).xyz, expected);
}

TEST_F(PositionsIo, XyzWithoutPropertiesHasSpeciesFirst) {
  const std::string file = write_file("plain.xyz", " 2 \nwater\nO 0 0 0 extra\nH 0.96 0 0\n");
  const std::vector<float> expected = {0, 0, 0, 0.96f, 0, 0};
  EXPECT_EQ(read_positions(file).xyz, expected);
}

TEST_F(PositionsIo, MissingFileNamesThePath) {
  const std::string file = path("absent.csv");
  EXPECT_TRUE(contains(io_error([&] { read_positions(file); }), file));
}

TEST_F(PositionsIo, DirectoryNamesThePath) {
  const std::string directory = path("folder.csv");
  fs::create_directories(directory);
  EXPECT_TRUE(
      contains(io_error([&] { read_positions(directory); }), directory + ": is a directory"));
}

TEST_F(PositionsIo, UnknownExtensionNamesThePath) {
  const std::string file = write_file("points.txt", "1,2,3\n");
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file)) << message;
  EXPECT_TRUE(contains(message, ".txt")) << message;
  EXPECT_TRUE(contains(io_error([&] { read_positions(path("no_extension")); }), "extension"));
}

TEST_F(PositionsIo, CsvWrongColumnCountNamesFileAndLine) {
  const std::string file = write_file("bad.csv", "x,y,z\n1,2,3\n4,5\n");
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file + ":3:")) << message;
  EXPECT_TRUE(contains(message, "found 2")) << message;
  EXPECT_TRUE(contains(io_error([&] { read_positions(write_file("four.csv", "1,2,3,4\n")); }),
                       "four.csv:1:"));
}

TEST_F(PositionsIo, CsvBadNumberNamesFileLineAndToken) {
  const std::string file = write_file("bad.csv", "1,2,3\n\n# note\n4,5,six\n");
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file + ":4:")) << message;
  EXPECT_TRUE(contains(message, "'six'")) << message;
  EXPECT_TRUE(contains(io_error([&] { read_positions(write_file("big.csv", "1,2,1e39\n")); }),
                       "big.csv:1:"));
  EXPECT_TRUE(contains(io_error([&] { read_positions(write_file("junk.csv", "1,2,3x\n")); }),
                       "junk.csv:1:"));
}

TEST_F(PositionsIo, XyzErrorsNameFileAndLine) {
  const std::string short_file = write_file("short.xyz", "3\ncomment\nH 1 2 3\nH 4 5 6\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(short_file); }), short_file + ":5:"));
  const std::string bad_count = write_file("count.xyz", "three\ncomment\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(bad_count); }), bad_count + ":1:"));
  const std::string few_columns = write_file("cols.xyz", "2\nc\nH 1 2 3\nH 1 2\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(few_columns); }), few_columns + ":4:"));
  const std::string bad_number = write_file("num.xyz", "1\nc\nH 1 y 3\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(bad_number); }), bad_number + ":3:"));
  const std::string no_pos = write_file("nopos.xyz", "1\nProperties=species:S:1\nH\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(no_pos); }), no_pos + ":2:"));
}

TEST_F(PositionsIo, UnwritablePathNamesThePath) {
  const std::string file = path("no/such/dir/out.csv");
  EXPECT_TRUE(contains(io_error([&] { write_csv(file, PointCloud{}); }), file));
}

// Hostile inputs give clear errors, never a crash, a hang or a silent misreading.

TEST_F(PositionsIo, XyzHugePropertiesCountIsAnError) {
  const std::string file = write_file(
      "huge.xyz", "1\nProperties=species:S:1:mass:R:18446744073709551614:pos:R:3\nH 1 2 3 4\n");
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file + ":2:")) << message;
  EXPECT_TRUE(contains(message, "too large")) << message;
  const std::string sum =
      write_file("sum.xyz", "1\nProperties=a:R:500000:b:R:500000:c:R:500000:pos:R:3\nH 1 2 3\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(sum); }), sum + ":2:"));
}

TEST_F(PositionsIo, LineWithoutEndIsCappedNotRead) {
  const std::string big = write_file("big.csv", std::string(3 << 20, '7'));
  const std::string message = io_error([&] { read_positions(big); });
  EXPECT_TRUE(contains(message, big + ":1: line longer than 1 MiB")) << message;
  const std::string zero = path("zero.xyz");
  fs::create_symlink("/dev/zero", zero);
  EXPECT_TRUE(contains(io_error([&] { read_positions(zero); }), zero + ":1: contains a NUL"));
  const std::string zero_csv = path("zero.csv");
  fs::create_symlink("/dev/zero", zero_csv);
  EXPECT_TRUE(contains(io_error([&] { read_positions(zero_csv); }), zero_csv + ":1:"));
}

TEST_F(PositionsIo, OneLineCsvWithoutHeaderIsData) {
  const std::vector<float> expected = {1, 2, 3};
  EXPECT_EQ(read_positions(write_file("one.csv", "1,2,3")).xyz, expected);
  EXPECT_EQ(read_positions(write_file("one_nl.csv", "1,2,3\n")).xyz, expected);
  // Not a header: a line without commas, or with a number in it, is data and must parse.
  const std::string spaces = write_file("spaces.csv", "1 2 3\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(spaces); }), spaces + ":1: expected 3"));
  const std::string half = write_file("half.csv", "x,2,z\n");
  EXPECT_TRUE(contains(io_error([&] { read_positions(half); }), half + ":1:"));
  EXPECT_EQ(read_positions(write_file("header.csv", "x,y,z\n")).size(), 0u);
}

TEST_F(PositionsIo, XyzMoreAtomsThanTheCountIsAnError) {
  const std::string file = write_file("two.xyz", "1\nc\nH 0 0 0\nH 1 1 1\n");
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file + ":4:")) << message;
  EXPECT_TRUE(contains(message, "line 1 says 1 particles")) << message;
  // Blank lines after the frame, and a next frame, are fine.
  EXPECT_EQ(read_positions(write_file("blank.xyz", "1\nc\nH 0 0 0\n\n  \n")).size(), 1u);
  EXPECT_EQ(
      read_positions(write_file("frames.xyz", "1\nc\nH 0 0 0\n\n2\nc\nH 1 1 1\nH 2 2 2\n")).size(),
      1u);
}

TEST_F(PositionsIo, ByteOrderMarkIsSkipped) {
  const std::vector<float> expected = {1, 2, 3};
  EXPECT_EQ(read_positions(write_file("bom.csv", "\xEF\xBB\xBFx,y,z\n1,2,3\n")).xyz, expected);
  EXPECT_EQ(read_positions(write_file("bom_data.csv",
                                      "\xEF\xBB\xBF"
                                      "1,2,3\n"))
                .xyz,
            expected);
  EXPECT_EQ(read_positions(write_file("bom.xyz",
                                      "\xEF\xBB\xBF"
                                      "1\nc\nH 1 2 3\n"))
                .xyz,
            expected);
}

TEST_F(PositionsIo, MessagesEscapeAndShortenTokens) {
  const std::string control = write_file("ctl.csv", std::string("1,2,\x01z\x1b[31m\n", 12));
  const std::string message = io_error([&] { read_positions(control); });
  EXPECT_TRUE(contains(message, "'\\x01z\\x1B[31m'")) << message;
  const std::string nul_token = write_file("nul.xyz", std::string("1\nc\nH 1 2 3\x00\n", 15));
  EXPECT_TRUE(contains(io_error([&] { read_positions(nul_token); }), nul_token + ":3: contains"));
  const std::string long_token = write_file("long.csv", "1,2," + std::string(900000, 'q') + "\n");
  const std::string long_message = io_error([&] { read_positions(long_token); });
  EXPECT_LT(long_message.size(), 400u) << long_message.substr(0, 400);
  EXPECT_TRUE(contains(long_message, "... (900000 bytes)")) << long_message.substr(0, 400);
  EXPECT_EQ(io::printable("a\nb\tc"), "a\\nb\\tc");
  EXPECT_EQ(io::printable("\xC3\xA9\xC3\xA9", 3), "\xC3\xA9... (4 bytes)");  // whole characters
}

TEST_F(PositionsIo, WritePositionsPicksTheFormatCaseInsensitively) {
  PointCloud cloud;
  cloud.xyz = {1, 2, 3};
  write_positions(path("upper.CSV"), cloud);
  std::ifstream in(path("upper.CSV"));
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "x,y,z");
  write_positions(path("upper.XYZ"), cloud);
  EXPECT_EQ(read_positions(path("upper.XYZ")).xyz, cloud.xyz);
  EXPECT_TRUE(contains(io_error([&] { write_positions(path("out.txt"), cloud); }), ".txt"));
  EXPECT_FALSE(fs::exists(path("out.txt")));
}

// No file in the folder but these: no temporary file is left behind.
std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

TEST_F(PositionsIo, WriteToAFullDeviceFails) {
  PointCloud cloud = make_family("uniform", 1000, 1.0f, 3);
  for (const auto& write : {write_csv, write_xyz}) {
    const std::string message = io_error([&] { write("/dev/full", cloud); });
    EXPECT_TRUE(contains(message, "/dev/full: write failed: No space left")) << message;
  }
  write_csv("/dev/null", cloud);  // a device is written in place
}

TEST_F(PositionsIo, WriteToAnUnwritableFolderFailsAndLeavesNothing) {
  const PointCloud cloud = make_family("uniform", 10, 1.0f, 3);
  for (const std::string& file : {path("missing/out.csv"), std::string("/proc/raycut-out.csv")}) {
    const std::string message = io_error([&] { write_csv(file, cloud); });
    EXPECT_TRUE(contains(message, file + ": cannot write in")) << message;
  }
  const std::string directory = path("folder.xyz");
  fs::create_directories(directory);
  EXPECT_TRUE(contains(io_error([&] { write_xyz(directory, cloud); }), "is a directory"));
}

TEST_F(PositionsIo, OutputFileAppearsWholeOrNotAtAll) {
  const std::string file = write_file("keep.csv", "old\n");
  {
    io::OutputFile out(file);
    out.write("new\n");
    out.flush();
    EXPECT_EQ(names_in(path("")).size(), 2u);  // the file and the temporary file
  }                                            // no commit: an error happened
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "old");
  EXPECT_EQ(names_in(path("")), std::vector<std::string>{"keep.csv"});
  {
    io::OutputFile out(file, io::OutputFile::Mode::append);
    EXPECT_FALSE(out.was_empty());
    out.write("more\n");
    out.commit();
  }
  std::ifstream again(file);
  std::string all((std::istreambuf_iterator<char>(again)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all, "old\nmore\n");
  // A symbolic link is followed: its target is replaced, the link stays.
  fs::create_symlink("keep.csv", path("link.csv"));
  write_csv(path("link.csv"), PointCloud{});
  EXPECT_TRUE(fs::is_symlink(path("link.csv")));
  EXPECT_EQ(read_positions(file).size(), 0u);
  EXPECT_EQ(names_in(path("")), (std::vector<std::string>{"keep.csv", "link.csv"}));
}

// ---------------------------------------------------------------------------------------------
// Periodic boxes in extended XYZ: Lattice and pbc on the comment line (ASE's and OVITO's format).

Box box_of(std::array<double, 9> rows, std::array<bool, 3> pbc) {
  Box box;
  for (int k = 0; k < 9; ++k) box.cell[k / 3][k % 3] = rows[k];
  for (int k = 0; k < 3; ++k) box.pbc[k] = pbc[k];
  return box;
}

std::string comment_line(const std::string& file) {
  std::ifstream in(file);
  std::string count, comment;
  std::getline(in, count);
  std::getline(in, comment);
  return comment;
}

TEST_F(PositionsIo, XyzBoxRoundTripsExactly) {
  const std::vector<Box> boxes = {
      Box::orthorhombic(5.44, 5.44, 5.44),
      box_of({3.1, 0.1, -1.0 / 3, 1.3, 2.7, 0.1, -0.9, 1.1, 2.3}, {true, true, true}),
      box_of({2, 0, 0, 0, 0, 3, 0, 4, 0}, {true, true, true}),  // left-handed
      box_of({1e-300, 0, 0, 0, 1e300, 0, 0, 0, 5e-324}, {true, true, true}),
      box_of({3, 0, 0, 1.5, 2.598, 0, 0, 0, 0}, {true, true, false}),  // slab, c zero
      box_of({0, 0, 0, 0, 0, 0, 0, 0, 7.25}, {false, false, true}),    // wire
      box_of({10, 0, 0, 0, 10, 0, 0, 0, 10}, {false, false, false}),   // a cell, no periodic axis
  };
  const PointCloud points = awkward_cloud();
  for (const Box& box : boxes) {
    PointCloud cloud = points;
    cloud.box = box;
    write_xyz(path("box.xyz"), cloud);
    const PointCloud read = read_positions(path("box.xyz"));
    EXPECT_EQ(read.box, box) << comment_line(path("box.xyz"));
    expect_same_bits(read.xyz, cloud.xyz);
  }
  PointCloud cloud = points;
  cloud.box = box_of({3, 0, 0, 1.5, 2.598, 0, 0, 0, 0}, {true, true, false});
  write_xyz(path("slab.xyz"), cloud);
  EXPECT_EQ(comment_line(path("slab.xyz")),
            "Lattice=\"3 0 0 1.5 2.598 0 0 0 0\" Properties=species:S:1:pos:R:3 pbc=\"T T F\"");
  // An open box keeps the comment line as it was.
  write_xyz(path("open.xyz"), points);
  EXPECT_EQ(comment_line(path("open.xyz")), "Properties=species:S:1:pos:R:3");
  EXPECT_TRUE(read_positions(path("open.xyz")).box.is_open());
  EXPECT_TRUE(read_positions(write_file("plain.xyz", "1\nplain\nX 1 2 3\n")).box.is_open());
}

// Byte for byte what ASE 3.29 writes (ase.io.write(..., format="extxyz")).
TEST_F(PositionsIo, XyzReadsWhatAseWrites) {
  const PointCloud si = read_positions(write_file(
      "si.xyz",
      "2\n"
      "Lattice=\"5.44 0.0 0.0 0.0 5.44 0.0 0.0 0.0 5.44\" Properties=species:S:1:pos:R:3 "
      "pbc=\"T T T\"\n"
      "Si       0.00000000       0.00000000       0.00000000\n"
      "Si       1.36000000       1.36000000       1.36000000\n"));
  EXPECT_EQ(si.box, Box::orthorhombic(5.44, 5.44, 5.44));
  EXPECT_EQ(si.xyz, (std::vector<float>{0, 0, 0, 1.36f, 1.36f, 1.36f}));
  const PointCloud slab = read_positions(
      write_file("slab.xyz",
                 "2\n"
                 "Lattice=\"3.0 0.0 0.0 1.5 2.598 0.0 0.0 0.0 0.0\" Properties=species:S:1:pos:R:3 "
                 "pbc=\"T T F\"\n"
                 "C        0.00000000       0.00000000       0.00000000\n"
                 "O        1.10000000       0.10000000      -0.20000000\n"));
  EXPECT_EQ(slab.box, box_of({3, 0, 0, 1.5, 2.598, 0, 0, 0, 0}, {true, true, false}));
  // An open molecule: ASE always writes pbc, and no Lattice for a zero cell.
  const PointCloud molecule =
      read_positions(write_file("mol.xyz",
                                "2\n"
                                "Properties=species:S:1:pos:R:3 pbc=\"F F F\"\n"
                                "H        0.00000000       0.00000000       0.00000000\n"
                                "H        0.74000000       0.00000000       0.00000000\n"));
  EXPECT_TRUE(molecule.box.is_open());
  EXPECT_EQ(molecule.size(), 2u);
  // With info and arrays of its own, and OVITO's Origin (irrelevant to pairs: ignored).
  const PointCloud rich = read_positions(write_file(
      "rich.xyz",
      "1\n"
      "Lattice=\"4.0 0.0 0.0 0.0 4.0 0.0 0.0 0.0 4.0\" "
      "Properties=species:S:1:pos:R:3:forces:R:3 energy=-1.5 config_type=bulk pbc=\"T T T\" "
      "Origin=\"-2 -2 -2\"\n"
      "Cu 1 2 3 0.1 0.2 0.3\n"));
  EXPECT_EQ(rich.box, Box::orthorhombic(4, 4, 4));
  EXPECT_EQ(rich.xyz, (std::vector<float>{1, 2, 3}));
}

TEST_F(PositionsIo, XyzBoxFollowsAseDefaults) {
  const std::string atom = "X 0 0 0\n";
  // Lattice without pbc: periodic on all three axes (ase/io/extxyz.py, _read_xyz_frame).
  EXPECT_EQ(read_positions(write_file("a.xyz", "1\nLattice=\"2 0 0 0 3 0 0 0 4\"\n" + atom)).box,
            Box::orthorhombic(2, 3, 4));
  // pbc=T stands for all three; True/False/1/0 in any case; separators spaces or commas.
  EXPECT_EQ(
      read_positions(write_file("b.xyz", "1\nLattice=\"2 0 0 0 3 0 0 0 4\" pbc=T\n" + atom)).box,
      Box::orthorhombic(2, 3, 4));
  EXPECT_EQ(read_positions(write_file("c.xyz",
                                      "1\nLattice='2,0,0,0,3,0,0,0,4' "
                                      "pbc=[True, false, TRUE]\n" +
                                          atom))
                .box,
            Box::orthorhombic(2, 3, 4, true, false, true));
  EXPECT_EQ(read_positions(write_file("d.xyz",
                                      "1\nlattice = \"2 0 0 0 3 0 0 0 4\"  PBC = "
                                      "\"1 1 0\"\n" +
                                          atom))
                .box,
            Box::orthorhombic(2, 3, 4, true, true, false));
  // The last of a repeated key counts, as in ASE's dict.
  EXPECT_EQ(read_positions(write_file("e.xyz",
                                      "1\nLattice=\"2 0 0 0 3 0 0 0 4\" pbc=\"T T T\" "
                                      "pbc=\"F F T\"\n" +
                                          atom))
                .box,
            Box::orthorhombic(2, 3, 4, false, false, true));
  // pbc all false without a Lattice: open. Bare words of a free comment are not keys.
  EXPECT_TRUE(read_positions(write_file("f.xyz", "1\npbc=\"F F F\"\n" + atom)).box.is_open());
  EXPECT_TRUE(
      read_positions(write_file("g.xyz", "1\nmade with pbc and a Lattice, it's fine\n" + atom))
          .box.is_open());
  // A periodic axis without a Lattice (ASE would make a zero cell): refused, naming file:line.
  const std::string file =
      write_file("h.xyz", "1\nProperties=species:S:1:pos:R:3 pbc=\"T T T\"\n" + atom);
  const std::string message = io_error([&] { read_positions(file); });
  EXPECT_TRUE(contains(message, file + ":2:")) << message;
  EXPECT_TRUE(contains(message, "no Lattice")) << message;
}

TEST_F(PositionsIo, XyzMalformedBoxNamesFileAndLine) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"Lattice=\"1 0 0 0 1 0 0 0\"", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1 0\"", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 nan 0 0 0 1\"", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 1 0 0 0 inf\"", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1e999\"", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 x 0 0 0 1\"", "malformed Lattice"},
      {"Lattice=", "malformed Lattice"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1\" pbc=\"T T\"", "malformed pbc"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1\" pbc=\"T X F\"", "malformed pbc"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1\" pbc=yes", "malformed pbc"},
      {"Lattice=\"1 0 0 0 1 0 0 0 1\" pbc=\"T T F T\"", "malformed pbc"},
      {"Lattice=\"1 0 0 2 0 0 0 0 1\"", "singular"},
      {"Lattice=\"1 0 0 0 0 0 0 0 1\" pbc=\"T T T\"", "b has zero length"},
      {"Lattice=\"1 0 0 0 1 0 0 0 0\"", "c has zero length"},
  };
  for (const auto& [comment, expected] : cases) {
    const std::string file = write_file("bad.xyz", "1\n" + comment + "\nX 0 0 0\n");
    const std::string message = io_error([&] { read_positions(file); });
    EXPECT_TRUE(contains(message, file + ":2: ")) << comment << " -> " << message;
    EXPECT_TRUE(contains(message, expected)) << comment << " -> " << message;
  }
  // A slab may leave its non-periodic row zero.
  EXPECT_EQ(read_positions(write_file("slab.xyz",
                                      "1\nLattice=\"1 0 0 0 1 0 0 0 0\" "
                                      "pbc=\"T T F\"\nX 0 0 0\n"))
                .box,
            Box::orthorhombic(1, 1, 0, true, true, false));
}

TEST_F(PositionsIo, WritersRefuseBoxesTheyCannotHold) {
  PointCloud cloud = make_family("uniform", 10, 1.0f, 1);
  cloud.box = Box::orthorhombic(2, 2, 2);
  auto refused = [](const std::function<void()>& action) -> std::string {
    try {
      action();
    } catch (const Error& error) {
      EXPECT_EQ(error.code(), ErrorCode::invalid_argument) << error.what();
      return error.what();
    }
    ADD_FAILURE() << "no raycut::Error thrown";
    return "";
  };
  EXPECT_TRUE(contains(refused([&] { write_csv(path("p.csv"), cloud); }), "periodic box"));
  EXPECT_FALSE(fs::exists(path("p.csv")));
  cloud.box = box_of({1, 0, 0, 2, 0, 0, 0, 0, 1}, {true, true, true});
  EXPECT_TRUE(contains(refused([&] { write_xyz(path("p.xyz"), cloud); }), "singular"));
  EXPECT_FALSE(fs::exists(path("p.xyz")));
  // A cell without periodic axes is no loss for pairs: CSV takes the positions.
  cloud.box = box_of({1, 0, 0, 0, 1, 0, 0, 0, 1}, {false, false, false});
  write_csv(path("q.csv"), cloud);
  EXPECT_EQ(read_positions(path("q.csv")).size(), 10u);
}

}  // namespace
}  // namespace raycut
