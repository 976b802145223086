// CSV and XYZ: bit-exact round trips, the formats users already have, and errors that name the
// file and line.
#include <gtest/gtest.h>

#include <unistd.h>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "raycut/error.hpp"
#include "raycut/generators.hpp"
#include "raycut/io.hpp"

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
  try {
    action();
  } catch (const Error& error) {
    EXPECT_EQ(error.code(), ErrorCode::io) << error.what();
    return error.what();
  }
  ADD_FAILURE() << "no raycut::Error thrown";
  return "";
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

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

}  // namespace
}  // namespace raycut
