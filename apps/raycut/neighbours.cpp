// raycut neighbours: the neighbour list of a positions file written to .npz or .csv, with ASE's
// letters (i, j, d, D, S), in the input's box (an extended XYZ's Lattice and pbc, or --cell /
// --pbc), full or half. The output appears whole or not at all (io::OutputFile).
#include <array>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/files.hpp"
#include "raycut/tools/io.hpp"

namespace raycut::cli {
namespace {

struct NeighboursOptions {
  std::string input, output, quantities = "ijdDS", method = "auto";
  float cutoff = 0;
  bool half = false, quiet = false;
  BoxOptions box;
};

// ---- .npy / .npz -------------------------------------------------------------------------------

// CRC-32 (ISO-HDLC, the zip checksum), table-driven.
std::uint32_t crc32(std::string_view data) {
  static const std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t n = 0; n < 256; ++n) {
      std::uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xFFFFFFFFu;
  for (unsigned char byte : data) c = table[(c ^ byte) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

template <class T>
void put(std::string& out, T value) {  // little-endian, as zip and .npy want (x86/ARM hosts)
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

// An .npy file (format 1.0): the magic, a header dict padded to a multiple of 64 bytes, the data.
std::string npy(const char* descr, std::size_t rows, int columns, const void* data,
                std::size_t bytes) {
  std::string header = std::string("{'descr': '") + descr +
                       "', 'fortran_order': False, 'shape': (" + std::to_string(rows) +
                       (columns > 1 ? ", " + std::to_string(columns) + ")" : ",)") + ", }";
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header += '\n';
  std::string out = "\x93NUMPY";
  out += '\x01';
  out += '\x00';
  put(out, static_cast<std::uint16_t>(header.size()));
  out += header;
  out.append(static_cast<const char*>(data), bytes);
  return out;
}

// A zip archive of stored (uncompressed) members, as numpy.savez writes without compression;
// Zip64 records where a size or offset does not fit in 32 bits.
class ZipWriter {
 public:
  explicit ZipWriter(io::OutputFile& file) : file_(file) {}

  void add(const std::string& name, const std::string& data) {
    const std::uint32_t crc = crc32(data);
    const std::uint64_t size = data.size();
    const bool zip64 = size >= 0xFFFFFFFFu || offset_ >= 0xFFFFFFFFu;
    std::string local;
    put(local, std::uint32_t{0x04034b50});
    put(local, static_cast<std::uint16_t>(zip64 ? 45u : 20u));  // version needed
    put(local, std::uint16_t{0});                               // flags
    put(local, std::uint16_t{0});                               // stored
    put(local, std::uint16_t{0});                               // time
    put(local, std::uint16_t{0x21});                            // date: 1980-01-01
    put(local, crc);
    put(local, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(size));
    put(local, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(size));
    put(local, static_cast<std::uint16_t>(name.size()));
    put(local, static_cast<std::uint16_t>(zip64 ? 20u : 0u));
    local += name;
    if (zip64) {
      put(local, std::uint16_t{1});
      put(local, std::uint16_t{16});
      put(local, size);
      put(local, size);
    }
    entries_.push_back({name, crc, size, offset_});
    file_.write(local);
    file_.write(data);
    offset_ += local.size() + size;
  }

  void finish() {
    std::string central;
    for (const Entry& e : entries_) {
      const bool zip64 = e.size >= 0xFFFFFFFFu || e.offset >= 0xFFFFFFFFu;
      put(central, std::uint32_t{0x02014b50});
      put(central, static_cast<std::uint16_t>(zip64 ? 45u : 20u));  // made by
      put(central, static_cast<std::uint16_t>(zip64 ? 45u : 20u));  // needed
      put(central, std::uint16_t{0});
      put(central, std::uint16_t{0});
      put(central, std::uint16_t{0});
      put(central, std::uint16_t{0x21});
      put(central, e.crc);
      put(central, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(e.size));
      put(central, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(e.size));
      put(central, static_cast<std::uint16_t>(e.name.size()));
      put(central, static_cast<std::uint16_t>(zip64 ? 28u : 0u));  // extra
      put(central, std::uint16_t{0});                              // comment
      put(central, std::uint16_t{0});                              // disk
      put(central, std::uint16_t{0});                              // internal attributes
      put(central, std::uint32_t{0});                              // external attributes
      put(central, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(e.offset));
      central += e.name;
      if (zip64) {
        put(central, std::uint16_t{1});
        put(central, std::uint16_t{24});
        put(central, e.size);
        put(central, e.size);
        put(central, e.offset);
      }
    }
    const std::uint64_t start = offset_, count = entries_.size(), size = central.size();
    const bool zip64 = start + size >= 0xFFFFFFFFu || count >= 0xFFFF;
    if (zip64) {  // Zip64 end of central directory record and its locator
      put(central, std::uint32_t{0x06064b50});
      put(central, std::uint64_t{44});
      put(central, std::uint16_t{45});
      put(central, std::uint16_t{45});
      put(central, std::uint32_t{0});
      put(central, std::uint32_t{0});
      put(central, count);
      put(central, count);
      put(central, size);
      put(central, start);
      put(central, std::uint32_t{0x07064b50});
      put(central, std::uint32_t{0});
      put(central, start + size);
      put(central, std::uint32_t{1});
    }
    put(central, std::uint32_t{0x06054b50});
    put(central, std::uint16_t{0});
    put(central, std::uint16_t{0});
    put(central, static_cast<std::uint16_t>(zip64 ? 0xFFFF : count));
    put(central, static_cast<std::uint16_t>(zip64 ? 0xFFFF : count));
    put(central, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(size));
    put(central, zip64 ? 0xFFFFFFFFu : static_cast<std::uint32_t>(start));
    put(central, std::uint16_t{0});
    file_.write(central);
  }

 private:
  struct Entry {
    std::string name;
    std::uint32_t crc;
    std::uint64_t size, offset;
  };
  io::OutputFile& file_;
  std::vector<Entry> entries_;
  std::uint64_t offset_ = 0;
};

// The progress line counts percent of the run, by stage: the file read (30), the build (45), the
// list (60), then the output, in proportion to what is written.
constexpr std::uint64_t percent_read = 30, percent_built = 45, percent_listed = 60;

// ---- the list ----------------------------------------------------------------------------------

// The pairs of a CSR list as ASE's arrays: i and j (int64), d and D (float32), S (int32).
struct Pairs {
  std::vector<std::int64_t> i, j;
  const NeighbourList* list = nullptr;
  std::size_t size() const { return j.size(); }
};

Pairs pairs_of(const NeighbourList& list) {
  Pairs p;
  p.list = &list;
  const std::size_t n = list.offsets.empty() ? 0 : list.offsets.size() - 1;
  p.i.reserve(list.indices.size());
  p.j.assign(list.indices.begin(), list.indices.end());
  for (std::size_t r = 0; r < n; ++r)
    p.i.insert(p.i.end(), list.offsets[r + 1] - list.offsets[r], static_cast<std::int64_t>(r));
  return p;
}

void write_npz(const std::string& path, const Pairs& p, const std::string& letters,
               Progress& progress) {
  io::OutputFile file(path);
  ZipWriter zip(file);
  const std::size_t n = p.size();
  std::size_t done = 0;
  for (char letter : letters) {
    std::string data;
    switch (letter) {
      case 'i':
        data = npy("<i8", n, 1, p.i.data(), n * 8);
        break;
      case 'j':
        data = npy("<i8", n, 1, p.j.data(), n * 8);
        break;
      case 'd':
        data = npy("<f4", n, 1, p.list->distances.data(), n * 4);
        break;
      case 'D':
        data = npy("<f4", n, 3, p.list->vectors.data(), n * 12);
        break;
      case 'S':
        data = npy("<i4", n, 3, p.list->shifts.data(), n * 12);
        break;
    }
    zip.add(std::string(1, letter) + ".npy", data);
    progress.update(percent_listed + (100 - percent_listed) * ++done / letters.size());
  }
  zip.finish();
  file.commit();
}

// %.9g: a float32 reads back to the same value.
void write_csv_pairs(const std::string& path, const Pairs& p, const std::string& letters,
                     Progress& progress) {
  io::OutputFile file(path);
  std::string header;
  for (char letter : letters) {
    if (!header.empty()) header += ',';
    if (letter == 'D')
      header += "Dx,Dy,Dz";
    else if (letter == 'S')
      header += "Sx,Sy,Sz";
    else
      header += letter;
  }
  file.write(header + "\n");
  const NeighbourList& l = *p.list;
  std::string row;
  char number[64];
  for (std::size_t k = 0; k < p.size(); ++k) {
    row.clear();
    for (char letter : letters) {
      if (!row.empty()) row += ',';
      switch (letter) {
        case 'i':
          row += std::to_string(p.i[k]);
          break;
        case 'j':
          row += std::to_string(p.j[k]);
          break;
        case 'd':
          std::snprintf(number, sizeof number, "%.9g", l.distances[k]);
          row += number;
          break;
        case 'D':
          std::snprintf(number, sizeof number, "%.9g,%.9g,%.9g", l.vectors[3 * k],
                        l.vectors[3 * k + 1], l.vectors[3 * k + 2]);
          row += number;
          break;
        case 'S':
          std::snprintf(number, sizeof number, "%d,%d,%d", l.shifts[3 * k], l.shifts[3 * k + 1],
                        l.shifts[3 * k + 2]);
          row += number;
          break;
      }
    }
    row += '\n';
    file.write(row);
    if ((k & 0xFFFF) == 0) progress.update(percent_listed + (100 - percent_listed) * k / p.size());
  }
  file.commit();
}

bool has_extension(const std::string& path, std::string_view ext) {
  if (path.size() < ext.size()) return false;
  std::string tail = path.substr(path.size() - ext.size());
  for (char& c : tail) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return tail == ext;
}

int run_neighbours(const NeighboursOptions& o) {
  const bool npz = has_extension(o.output, ".npz");
  if (!npz && !has_extension(o.output, ".csv"))
    throw Error(ErrorCode::invalid_argument,
                "neighbours: --output '" + io::printable(o.output) +
                    "' must end in .npz or .csv (the format is chosen by the extension)");
  if (o.quantities.empty())
    throw Error(ErrorCode::invalid_argument,
                "neighbours: --quantities is empty (letters of ijdDS: i, j, d, D, S)");
  for (char letter : o.quantities)
    if (std::string_view("ijdDS").find(letter) == std::string_view::npos ||
        o.quantities.find(letter) != o.quantities.rfind(letter))
      throw Error(ErrorCode::invalid_argument,
                  "neighbours: --quantities '" + io::printable(o.quantities) +
                      "': each of the letters i, j, d, D, S at most once (ASE's letters)");
  Progress progress("neighbours", 100, o.quiet);
  PointCloud cloud = read_positions(o.input);
  progress.update(percent_read);
  cloud.box = resolve_box(o.box, cloud.box);
  Engine engine(o.method);
  engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, o.cutoff, cloud.box);
  progress.update(percent_built);
  ListOptions options;
  options.half = o.half;
  options.distances = o.quantities.find('d') != std::string::npos;
  options.vectors = o.quantities.find('D') != std::string::npos;
  options.shifts = o.quantities.find('S') != std::string::npos;
  const NeighbourList list = engine.neighbours(options);
  const Pairs pairs = pairs_of(list);
  progress.update(percent_listed);
  if (npz)
    write_npz(o.output, pairs, o.quantities, progress);
  else
    write_csv_pairs(o.output, pairs, o.quantities, progress);
  progress.done();
  std::printf("%s: %zu particles, %s, cutoff %g, %s list: %zu pairs (%s) -> %s\n",
              cloud.name.c_str(), cloud.size(), describe_box(cloud.box).c_str(), o.cutoff,
              o.half ? "half" : "full", pairs.size(), o.quantities.c_str(), o.output.c_str());
  return 0;
}

}  // namespace

Command add_neighbours(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "neighbours", "Write the neighbour list of a positions file to .npz or .csv (ASE's letters)");
  auto o = std::make_shared<NeighboursOptions>();
  cmd->add_option("-i,--input", o->input,
                  "Positions file (.csv, .xyz); an extended XYZ's Lattice and pbc are its "
                  "periodic box (--cell/--pbc override them)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("-c,--cutoff", o->cutoff, "Cutoff radius")->required()->check(positive_finite());
  cmd->add_option("-o,--output", o->output,
                  "Output: .npz (one array per letter, as numpy.savez: i.npy, j.npy, ...) or .csv "
                  "(a header row, then a row per pair)")
      ->required();
  cmd->add_option("--quantities", o->quantities,
                  "Letters of ijdDS, in the order wanted (ASE's: i, j int64; d distance and D "
                  "vector x_j - x_i + S.cell, float32; S image shift, int32)");
  cmd->add_flag("--half", o->half,
                "Each pair once: of (i, j, S) and (j, i, -S), the one with i < j (or i == j and S "
                "lexicographically positive)");
  cmd->add_option("-m,--method", o->method, "Method (a name from `raycut methods`, or auto)");
  cmd->add_flag("-q,--quiet", o->quiet, "No progress line on stderr");
  add_box_options(*cmd, o->box);
  return [o] { return run_neighbours(*o); };
}

}  // namespace raycut::cli
