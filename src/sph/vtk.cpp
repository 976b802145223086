// The appended-raw layout: each array is a UInt64 byte count followed by its bytes, and an array's
// offset attribute counts from the first byte after the '_' that opens <AppendedData>. Binary data
// are written in the host's byte order, declared as LittleEndian below.
#include "raycut/sph/vtk.hpp"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

#include "raycut/error.hpp"

namespace raycut::sph {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the .vtp writer declares byte_order=\"LittleEndian\"");

namespace fs = std::filesystem;

[[noreturn]] void io_error(const std::string& path, const std::string& what) {
  throw Error(ErrorCode::io, path + ": " + what);
}

void check_arrays(const float* xyz, const float* vel, const float* rho, const float* p,
                  std::size_t n) {
  if (n > 0 && (!xyz || !vel || !rho || !p)) {
    throw Error(ErrorCode::invalid_argument,
                "write_vtp: positions, velocities, densities and pressures must be non-null");
  }
  // Vertex cells index points with Int32.
  if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
    throw Error(ErrorCode::invalid_argument, "write_vtp: at most 2^31 - 1 points per frame");
  }
}

struct ArraySpec {
  const char* name;
  const char* type;
  int components;
  std::uint64_t bytes;
};

void append_ascii_floats(std::string& out, const float* values, std::size_t count) {
  char buffer[32];
  for (std::size_t i = 0; i < count; ++i) {
    // Shortest text that reads back to the same float.
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, values[i]);
    out.append(buffer, result.ptr);
    out.push_back((i + 1) % 9 == 0 ? '\n' : ' ');
  }
}

void append_ascii_ints(std::string& out, std::int64_t first, std::int64_t count) {
  for (std::int64_t i = 0; i < count; ++i) {
    out += std::to_string(first + i);
    out.push_back((i + 1) % 16 == 0 ? '\n' : ' ');
  }
}

// For file names in the .pvd's attributes.
std::string xml_escape(const std::string& raw) {
  std::string out;
  for (char c : raw) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out.push_back(c);
    }
  }
  return out;
}

void write_binary(std::ofstream& file, const void* data, std::uint64_t bytes) {
  file.write(reinterpret_cast<const char*>(&bytes), sizeof bytes);
  if (bytes > 0) file.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
}

}  // namespace

void write_vtp(const std::string& path, const float* xyz, const float* vel, const float* rho,
               const float* p, std::size_t n, VtkEncoding encoding) {
  check_arrays(xyz, vel, rho, p, n);
  const bool binary = encoding == VtkEncoding::binary;
  const std::uint64_t f32 = sizeof(float), i32 = sizeof(std::int32_t);
  // The order of the data blocks in the appended section.
  const ArraySpec arrays[] = {
      {"velocity", "Float32", 3, 3 * n * f32}, {"density", "Float32", 1, n * f32},
      {"pressure", "Float32", 1, n * f32},     {"Points", "Float32", 3, 3 * n * f32},
      {"connectivity", "Int32", 1, n * i32},   {"offsets", "Int32", 1, n * i32}};
  std::uint64_t offsets[6];
  std::uint64_t next = 0;
  for (int a = 0; a < 6; ++a) {
    offsets[a] = next;
    next += sizeof(std::uint64_t) + arrays[a].bytes;
  }

  std::string text;
  const auto data_array = [&](int a) {
    const ArraySpec& spec = arrays[a];
    text += "        <DataArray type=\"";
    text += spec.type;
    text += "\" Name=\"";
    text += spec.name;
    text += "\"";
    if (spec.components != 1)
      text += " NumberOfComponents=\"" + std::to_string(spec.components) + "\"";
    if (binary) {
      text += " format=\"appended\" offset=\"" + std::to_string(offsets[a]) + "\"/>\n";
      return;
    }
    text += " format=\"ascii\">\n";
    switch (a) {
      case 0:
        append_ascii_floats(text, vel, 3 * n);
        break;
      case 1:
        append_ascii_floats(text, rho, n);
        break;
      case 2:
        append_ascii_floats(text, p, n);
        break;
      case 3:
        append_ascii_floats(text, xyz, 3 * n);
        break;
      case 4:
        append_ascii_ints(text, 0, static_cast<std::int64_t>(n));
        break;
      case 5:
        append_ascii_ints(text, 1, static_cast<std::int64_t>(n));
        break;
    }
    text += "\n        </DataArray>\n";
  };
  const std::string count = std::to_string(n);
  text += "<?xml version=\"1.0\"?>\n";
  text +=
      "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\">\n";
  text += "  <PolyData>\n";
  text += "    <Piece NumberOfPoints=\"" + count + "\" NumberOfVerts=\"" + count +
          "\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n";
  text += "      <PointData Scalars=\"density\" Vectors=\"velocity\">\n";
  data_array(0);
  data_array(1);
  data_array(2);
  text += "      </PointData>\n      <Points>\n";
  data_array(3);
  text += "      </Points>\n      <Verts>\n";
  data_array(4);
  data_array(5);
  text += "      </Verts>\n    </Piece>\n  </PolyData>\n";
  if (binary) text += "  <AppendedData encoding=\"raw\">\n   _";

  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) io_error(path, "cannot open for writing");
  file.write(text.data(), static_cast<std::streamsize>(text.size()));
  if (binary) {
    write_binary(file, vel, arrays[0].bytes);
    write_binary(file, rho, arrays[1].bytes);
    write_binary(file, p, arrays[2].bytes);
    write_binary(file, xyz, arrays[3].bytes);
    // A vertex cell per point: cell i is point i, and cell i ends at offset i + 1.
    std::vector<std::int32_t> indices(n);
    for (std::size_t i = 0; i < n; ++i) indices[i] = static_cast<std::int32_t>(i);
    write_binary(file, indices.data(), arrays[4].bytes);
    for (std::size_t i = 0; i < n; ++i) indices[i] = static_cast<std::int32_t>(i + 1);
    write_binary(file, indices.data(), arrays[5].bytes);
    file << "\n  </AppendedData>\n";
  }
  file << "</VTKFile>\n";
  file.close();
  if (!file) io_error(path, "write failed (disk full?)");
}

VtkSeries::VtkSeries(std::string dir, std::string basename, VtkEncoding encoding)
    : dir_(std::move(dir)), basename_(std::move(basename)), encoding_(encoding) {
  if (basename_.empty()) {
    throw Error(ErrorCode::invalid_argument, "VtkSeries: basename must not be empty");
  }
  std::error_code error;
  fs::create_directories(dir_, error);
  if (error || !fs::is_directory(dir_))
    io_error(dir_, "cannot create directory: " + error.message());
}

std::string VtkSeries::pvd_path() const {
  return (fs::path(dir_) / (basename_ + ".pvd")).string();
}

void VtkSeries::write_frame(double time, const float* xyz, const float* vel, const float* rho,
                            const float* p, std::size_t n) {
  if (!std::isfinite(time)) {
    throw Error(ErrorCode::invalid_argument, "VtkSeries: frame time must be finite");
  }
  char name[32];
  std::snprintf(name, sizeof name, "_%06zu.vtp", frame_paths_.size());
  const std::string path = (fs::path(dir_) / (basename_ + name)).string();
  write_vtp(path, xyz, vel, rho, p, n, encoding_);
  frame_paths_.push_back(path);
  times_.push_back(time);
  write_pvd();
}

void VtkSeries::write_pvd() const {
  std::ostringstream text;
  text.precision(17);  // times read back exactly
  text << "<?xml version=\"1.0\"?>\n"
       << "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
       << "  <Collection>\n";
  for (std::size_t i = 0; i < frame_paths_.size(); ++i) {
    // Relative to the .pvd, so the folder can be moved.
    text << "    <DataSet timestep=\"" << times_[i] << "\" group=\"\" part=\"0\" file=\""
         << xml_escape(fs::path(frame_paths_[i]).filename().string()) << "\"/>\n";
  }
  text << "  </Collection>\n</VTKFile>\n";
  // Written aside and renamed, so a reader never sees half a collection.
  const std::string path = pvd_path();
  const std::string temporary = path + ".tmp";
  {
    std::ofstream file(temporary, std::ios::binary | std::ios::trunc);
    if (!file) io_error(temporary, "cannot open for writing");
    file << text.str();
    file.close();
    if (!file) io_error(temporary, "write failed (disk full?)");
  }
  std::error_code error;
  fs::rename(temporary, path, error);
  if (error) io_error(path, "cannot replace: " + error.message());
}

}  // namespace raycut::sph
