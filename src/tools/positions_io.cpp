// CSV and extended-XYZ positions. Numbers are written in the shortest form that reads back to
// the same float (std::to_chars), and read with std::from_chars, so a write/read round trip is
// bit-exact. Every error names the file, and the line where there is one. Also the file helpers
// of include/raycut/tools/files.hpp (capped line reader, whole-or-nothing output file) that every
// reader and writer of raycut uses.
#include "raycut/tools/io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string_view>
#include <system_error>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/error.hpp"
#include "raycut/tools/files.hpp"

namespace raycut {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw Error(ErrorCode::io, io::printable(path, 4096) + ": " + what);
}
[[noreturn]] void fail(const std::string& path, std::size_t line, const std::string& what) {
  throw Error(ErrorCode::io, io::printable(path, 4096) + ":" + std::to_string(line) + ": " + what);
}

// A token of the file, quoted for a message: escaped and cut short.
std::string quote_token(std::string_view token) {
  std::string quoted = "'";
  quoted += io::printable(token);
  quoted += '\'';
  return quoted;
}

std::string lowercase(std::string_view text) {
  std::string lower(text);
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return lower;
}

std::string_view trim(std::string_view text) {
  const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!text.empty() && is_space(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_space(text.back())) text.remove_suffix(1);
  return text;
}

std::vector<std::string_view> split_whitespace(std::string_view text) {
  std::vector<std::string_view> tokens;
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t' || text[i] == '\r')) ++i;
    const std::size_t begin = i;
    while (i < text.size() && text[i] != ' ' && text[i] != '\t' && text[i] != '\r') ++i;
    if (i > begin) tokens.push_back(text.substr(begin, i - begin));
  }
  return tokens;
}

enum class Parse { ok, not_a_number, out_of_range };

// The whole token must be one number; "nan" and "inf" are accepted (the engine's validation
// names the particle). Values too small for float become 0 or a subnormal, as strtof would give.
Parse parse_float(std::string_view token, float& value) {
  if (token.size() > 1 && token.front() == '+' && token[1] != '-') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec == std::errc() && ptr == end) return Parse::ok;
  if (ec != std::errc::result_out_of_range || ptr != end) return Parse::not_a_number;
  double wide = 0;
  const auto [wide_ptr, wide_ec] = std::from_chars(token.data(), end, wide);
  if (wide_ec == std::errc() && wide_ptr == end && std::abs(wide) < 1.0) {
    value = static_cast<float>(wide);
    return Parse::ok;
  }
  return Parse::out_of_range;
}

float parse_coordinate(std::string_view token, const std::string& path, std::size_t line,
                       const char* column) {
  float value = 0;
  switch (parse_float(token, value)) {
    case Parse::ok:
      return value;
    case Parse::out_of_range:
      fail(path, line, quote_token(token) + " (" + column + ") is out of float range");
    case Parse::not_a_number:
      break;
  }
  fail(path, line, "cannot parse " + quote_token(token) + " (" + column + ") as a number");
}

// A whole token as a non-negative integer (an XYZ count).
bool parse_count(std::string_view token, std::size_t& value) {
  const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  return !token.empty() && ec == std::errc() && ptr == token.data() + token.size();
}

constexpr const char* axis_names[3] = {"x", "y", "z"};

std::vector<std::string_view> split_commas(std::string_view text) {
  std::vector<std::string_view> fields;
  for (std::size_t begin = 0;;) {
    const std::size_t comma = text.find(',', begin);
    fields.push_back(trim(text.substr(begin, comma - begin)));
    if (comma == std::string_view::npos) break;
    begin = comma + 1;
  }
  return fields;
}

// A CSV header is a first content line of exactly 3 fields, none of them a number ("x,y,z").
// Anything else is data, so a headerless one-line file is one particle, and "1 2 3" (no commas)
// is an error, not a header.
bool is_csv_header(const std::vector<std::string_view>& fields) {
  if (fields.size() != 3) return false;
  float ignored = 0;
  return std::none_of(fields.begin(), fields.end(), [&](std::string_view f) {
    return f.empty() || parse_float(f, ignored) != Parse::not_a_number;
  });
}

PointCloud read_csv(const std::string& path) {
  PointCloud cloud;
  cloud.name = path;
  io::LineReader reader(path);
  std::string line;
  bool first_content_line = true;
  while (reader.next(line)) {
    const std::string_view text = trim(line);
    if (text.empty() || text.front() == '#') continue;
    const std::vector<std::string_view> fields = split_commas(text);
    if (first_content_line) {
      first_content_line = false;
      if (is_csv_header(fields)) continue;
    }
    if (fields.size() != 3) {
      fail(path, reader.number(),
           "expected 3 comma-separated numbers (x,y,z), found " + std::to_string(fields.size()) +
               (fields.size() == 1 ? " field " + quote_token(fields[0]) : " fields"));
    }
    for (int k = 0; k < 3; ++k) {
      cloud.xyz.push_back(parse_coordinate(fields[k], path, reader.number(), axis_names[k]));
    }
  }
  return cloud;
}

// The first column of pos in an extended-XYZ comment line (Properties=name:type:count:...),
// or 1 (species first, then x y z) when there is no Properties key.
std::size_t xyz_position_column(std::string_view comment, const std::string& path,
                                std::size_t line) {
  const std::string lower = lowercase(comment);
  std::size_t key = std::string::npos;
  for (std::size_t at = lower.find("properties="); at != std::string::npos;
       at = lower.find("properties=", at + 1)) {
    if (at == 0 || lower[at - 1] == ' ' || lower[at - 1] == '\t') {
      key = at;
      break;
    }
  }
  if (key == std::string::npos) return 1;
  std::string_view value = comment.substr(key + std::strlen("properties="));
  if (!value.empty() && (value.front() == '"' || value.front() == '\'')) {
    const char quote = value.front();
    value.remove_prefix(1);
    value = value.substr(0, value.find(quote));
  } else {
    value = value.substr(0, value.find_first_of(" \t"));
  }
  // Fields come in triples name:type:count; columns are counted over all of them.
  std::vector<std::string_view> parts;
  for (std::size_t begin = 0;;) {
    const std::size_t colon = value.find(':', begin);
    parts.push_back(value.substr(begin, colon - begin));
    if (colon == std::string_view::npos) break;
    begin = colon + 1;
  }
  if (parts.size() % 3 != 0) {
    fail(path, line, "malformed Properties " + quote_token(value) + " (expected name:type:count)");
  }
  // A line holds at most max_line bytes, so at most max_line / 2 columns: a larger count cannot
  // describe a line of this file (and would overflow the column index).
  constexpr std::size_t max_columns = io::LineReader::max_line / 2;
  std::size_t column = 0;
  for (std::size_t i = 0; i < parts.size(); i += 3) {
    std::size_t count = 0;
    if (!parse_count(parts[i + 2], count)) {
      fail(path, line, "malformed Properties count " + quote_token(parts[i + 2]));
    }
    if (count > max_columns) {
      fail(path, line,
           "Properties count " + quote_token(parts[i + 2]) + " of " + quote_token(parts[i]) +
               " is too large (a line has at most " + std::to_string(max_columns) + " columns)");
    }
    if (lowercase(parts[i]) == "pos") {
      if (lowercase(parts[i + 1]) != "r" || count != 3) {
        fail(path, line, "Properties pos must be pos:R:3");
      }
      return column;
    }
    column += count;
    if (column > max_columns) {
      fail(path, line,
           "Properties describe more than " + std::to_string(max_columns) +
               " columns before pos (a line has at most that many)");
    }
  }
  fail(path, line, "Properties has no pos:R:3 field");
}

// The key=value pairs of an extended-XYZ comment line, split as ASE's key_val_str_to_dict
// (ase/io/extxyz.py) splits them: "", '', {} or [] delimit a value, a backslash escapes the next
// character, whitespace separates pairs, spaces around '=' are allowed. A key without '=' has
// no value (ASE reads it as T).
struct KeyValue {
  std::string key, value;
  bool has_value = false;
};

std::vector<KeyValue> comment_key_values(std::string_view line) {
  line = trim(line);
  std::vector<std::vector<std::string>> pairs(1, std::vector<std::string>(1));
  char closing = 0;
  bool escaped = false;
  for (const char c : line) {
    if (escaped) {
      pairs.back().back() += c;
      escaped = false;
    } else if (c == '\\') {
      escaped = true;
    } else if (closing != 0) {
      if (c == closing) {
        closing = 0;
      } else {
        pairs.back().back() += c;
      }
    } else if (c == '"' || c == '\'' || c == '{' || c == '[') {
      closing = c == '{' ? '}' : c == '[' ? ']' : c;
    } else if (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f') {
      if (!pairs.back().back().empty()) pairs.emplace_back(1);
    } else if (c == '=') {
      // "key = value": the space opened an empty pair, which '=' folds back into the key's.
      if (pairs.size() > 1 && pairs.back().size() == 1 && pairs.back()[0].empty()) {
        pairs.pop_back();
      }
      pairs.back().emplace_back();
    } else {
      pairs.back().back() += c;
    }
  }
  std::vector<KeyValue> result;
  for (const auto& pair : pairs) {
    if (pair.size() == 1 && pair[0].empty()) continue;
    KeyValue kv;
    kv.key = pair[0];
    kv.has_value = pair.size() > 1;
    for (std::size_t k = 1; k < pair.size(); ++k) kv.value += (k > 1 ? "=" : "") + pair[k];
    result.push_back(std::move(kv));
  }
  return result;
}

// Tokens of a value separated by whitespace or commas (ASE: re.findall(r'[^\s,]+', value)).
std::vector<std::string_view> value_tokens(std::string_view value) {
  std::vector<std::string_view> tokens;
  const auto separator = [](char c) {
    return c == ' ' || c == '\t' || c == ',' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
  };
  std::size_t i = 0;
  while (i < value.size()) {
    while (i < value.size() && separator(value[i])) ++i;
    const std::size_t begin = i;
    while (i < value.size() && !separator(value[i])) ++i;
    if (i > begin) tokens.push_back(value.substr(begin, i - begin));
  }
  return tokens;
}

bool parse_double(std::string_view token, double& value) {
  if (token.size() > 1 && token.front() == '+' && token[1] != '-') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  return ec == std::errc() && ptr == end && std::isfinite(value);
}

// The periodic box of an extended-XYZ comment line (io.hpp: the rules, ASE's).
Box xyz_box(std::string_view comment, const std::string& path, std::size_t line) {
  const KeyValue* lattice = nullptr;
  const KeyValue* pbc = nullptr;
  const std::vector<KeyValue> pairs = comment_key_values(comment);
  for (const KeyValue& kv : pairs) {  // the last of a repeated key counts, as in ASE's dict
    if (!kv.has_value) continue;      // a bare word of a free-text comment
    const std::string key = lowercase(kv.key);
    if (key == "lattice") lattice = &kv;
    if (key == "pbc") pbc = &kv;
  }
  Box box;
  if (lattice == nullptr && pbc == nullptr) return box;
  if (lattice != nullptr) {
    const auto tokens = value_tokens(lattice->value);
    bool ok = tokens.size() == 9;
    for (std::size_t k = 0; ok && k < 9; ++k) ok = parse_double(tokens[k], box.cell[k / 3][k % 3]);
    if (!ok) {
      fail(path, line,
           "malformed Lattice " + quote_token(lattice->value) +
               " (expected 9 finite numbers, the cell rows: \"ax ay az bx by bz cx cy cz\")");
    }
  }
  if (pbc != nullptr) {
    const auto tokens = value_tokens(pbc->value);
    bool ok = tokens.size() == 1 || tokens.size() == 3;
    for (std::size_t k = 0; ok && k < tokens.size(); ++k) {
      const std::string word = lowercase(tokens[k]);
      ok = word == "t" || word == "true" || word == "1" || word == "f" || word == "false" ||
           word == "0";
      box.pbc[k] = word == "t" || word == "true" || word == "1";
    }
    if (!ok) {
      fail(path, line,
           "malformed pbc " + quote_token(pbc->value) +
               " (expected 3 of T/F/True/False, e.g. pbc=\"T T F\")");
    }
    if (tokens.size() == 1) box.pbc[1] = box.pbc[2] = box.pbc[0];  // ASE: pbc=T is all three
  } else {
    // ase/io/extxyz.py, _read_xyz_frame: "default pbc for extxyz file containing Lattice is
    // True in all directions".
    box.pbc[0] = box.pbc[1] = box.pbc[2] = true;
  }
  if (lattice == nullptr && box.periodic()) {
    fail(path, line,
         "pbc " + quote_token(pbc->value) +
             " has a periodic axis but there is no Lattice (the cell) on the comment line");
  }
  try {
    validate(box);
  } catch (const Error& error) {
    fail(path, line, error.what());
  }
  return box;
}

// The first frame of an (extended) XYZ file. What follows it, blank lines aside, must be the
// count line of a next frame (a trajectory; not read), or nothing: a count smaller than the
// atoms that follow is an error, not a silent truncation.
PointCloud read_xyz(const std::string& path) {
  PointCloud cloud;
  cloud.name = path;
  io::LineReader reader(path);
  std::string line;
  if (!reader.next(line)) fail(path, 1, "empty file, expected the particle count");
  std::size_t count = 0;
  if (!parse_count(trim(line), count)) {
    fail(path, 1, "expected the particle count, found " + quote_token(trim(line)));
  }
  if (!reader.next(line)) {
    if (count == 0) return cloud;
    fail(path, 2, "missing comment line");
  }
  const std::size_t pos_column = xyz_position_column(line, path, reader.number());
  cloud.box = xyz_box(line, path, reader.number());
  // The count is only a claim: reserve no more than the file can hold (a particle line has at
  // least 6 bytes, "0 0 0\n"), so that a 10-byte file saying 10^9 allocates nothing large.
  std::error_code size_error;
  const auto bytes = std::filesystem::file_size(path, size_error);
  const std::size_t fits = size_error ? 4096 : static_cast<std::size_t>(bytes / 6 + 1);
  cloud.xyz.reserve(3 * std::min(count, fits));
  for (std::size_t i = 0; i < count; ++i) {
    if (!reader.next(line)) {
      fail(path, reader.number() + 1,
           "file ends after " + std::to_string(i) + " of " + std::to_string(count) +
               " particles (the count on line 1)");
    }
    const auto tokens = split_whitespace(line);
    if (tokens.size() < pos_column + 3) {
      fail(path, reader.number(),
           "expected at least " + std::to_string(pos_column + 3) + " columns, found " +
               std::to_string(tokens.size()));
    }
    for (int k = 0; k < 3; ++k) {
      cloud.xyz.push_back(
          parse_coordinate(tokens[pos_column + k], path, reader.number(), axis_names[k]));
    }
  }
  while (reader.next(line)) {
    const std::string_view text = trim(line);
    if (text.empty()) continue;
    std::size_t next_count = 0;
    if (parse_count(text, next_count)) break;  // the next frame's count line
    fail(path, reader.number(),
         "expected the end of the file or the count line of a next frame, found " +
             quote_token(text) + " (line 1 says " + std::to_string(count) + " particles)");
  }
  return cloud;
}

std::string extension_of(const std::string& path) {
  const std::size_t slash = path.find_last_of("/\\");
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return lowercase(std::string_view(path).substr(dot));
}

enum class Format { csv, xyz };

Format format_of(const std::string& path) {
  const std::string extension = extension_of(path);
  if (extension == ".csv") return Format::csv;
  if (extension == ".xyz" || extension == ".extxyz") return Format::xyz;
  fail(path, "unknown extension " + quote_token(extension) + " (known: .csv, .xyz, .extxyz)");
}

void require_whole_points(const std::string& path, const PointCloud& cloud) {
  if (cloud.xyz.size() % 3 != 0) {
    throw Error(ErrorCode::invalid_argument, path + ": positions hold " +
                                                 std::to_string(cloud.xyz.size()) +
                                                 " floats, not a multiple of 3");
  }
}

// Shortest representation that reads back to the same float (double).
void write_number(io::OutputFile& out, float value) {
  char digits[64];
  const auto result = std::to_chars(digits, digits + sizeof digits, value);
  out.write(std::string_view(digits, static_cast<std::size_t>(result.ptr - digits)));
}

void write_number(io::OutputFile& out, double value) {
  char digits[64];
  const auto result = std::to_chars(digits, digits + sizeof digits, value);
  out.write(std::string_view(digits, static_cast<std::size_t>(result.ptr - digits)));
}

// One line per particle: prefix, then x, y, z with the separator between them.
void write_rows(io::OutputFile& out, const PointCloud& cloud, const char* prefix,
                const char* separator) {
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    out.write(prefix);
    for (int a = 0; a < 3; ++a) {
      if (a > 0) out.write(separator);
      write_number(out, cloud.xyz[3 * i + a]);
    }
    out.write("\n");
  }
}

}  // namespace

PointCloud read_positions(const std::string& path) {
  return format_of(path) == Format::csv ? read_csv(path) : read_xyz(path);
}

void write_csv(const std::string& path, const PointCloud& cloud) {
  require_whole_points(path, cloud);
  if (cloud.box.periodic()) {
    throw Error(ErrorCode::invalid_argument,
                path + ": CSV has no place for a periodic box (Lattice, pbc): write .xyz");
  }
  io::OutputFile out(path);
  out.write("x,y,z\n");
  write_rows(out, cloud, "", ",");
  out.commit();
}

void write_xyz(const std::string& path, const PointCloud& cloud) {
  require_whole_points(path, cloud);
  const bool has_box = !cloud.box.is_open();
  if (has_box) {
    try {
      validate(cloud.box);
    } catch (const Error& error) {
      throw Error(ErrorCode::invalid_argument, path + ": " + error.what());
    }
  }
  io::OutputFile out(path);
  out.write(std::to_string(cloud.size()) + "\n");
  if (has_box) {  // ASE's layout: Lattice="..." Properties=... pbc="T T F"
    out.write("Lattice=\"");
    for (int k = 0; k < 9; ++k) {
      if (k > 0) out.write(" ");
      write_number(out, cloud.box.cell[k / 3][k % 3]);
    }
    out.write("\" ");
  }
  out.write("Properties=species:S:1:pos:R:3");
  if (has_box) {
    out.write(std::string(" pbc=\"") + (cloud.box.pbc[0] ? "T" : "F") + " " +
              (cloud.box.pbc[1] ? "T" : "F") + " " + (cloud.box.pbc[2] ? "T" : "F") + "\"");
  }
  out.write("\n");
  write_rows(out, cloud, "X ", " ");
  out.commit();
}

void write_positions(const std::string& path, const PointCloud& cloud) {
  format_of(path) == Format::csv ? write_csv(path, cloud) : write_xyz(path, cloud);
}

void check_positions_extension(const std::string& path) {
  format_of(path);
}

// ---------------------------------------------------------------------------------------------
// Files in and out (include/raycut/tools/files.hpp).
namespace io {

std::string printable(std::string_view text, std::size_t limit) {
  std::size_t used = std::min(text.size(), limit);
  // Do not cut a UTF-8 character in half: back off over continuation bytes.
  if (used < text.size())
    while (used > 0 && (static_cast<unsigned char>(text[used]) & 0xC0) == 0x80) --used;
  std::string out;
  out.reserve(used + 24);
  for (std::size_t i = 0; i < used; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c < 0x20 || c == 0x7F) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned>(c));
      out += hex;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (used < text.size()) out += "... (" + std::to_string(text.size()) + " bytes)";
  return out;
}

LineReader::LineReader(const std::string& path) : path_(path) {
  std::error_code ignored;
  // Linux opens a directory for reading; only the first read fails.
  if (std::filesystem::is_directory(path, ignored)) fail(path, "is a directory, not a file");
  in_.open(path, std::ios::binary);
  if (!in_) fail(path, std::string("cannot open for reading: ") + std::strerror(errno));
}

// Appends the next chunk of the file to the unread text (moved to the front of buffer_);
// false at the end of the file.
bool LineReader::fill() {
  if (at_ > 0) {
    buffer_.erase(0, at_);
    at_ = 0;
  }
  if (eof_) return false;
  constexpr std::size_t chunk = std::size_t{1} << 16;
  const std::size_t old = buffer_.size();
  buffer_.resize(old + chunk);
  in_.read(buffer_.data() + old, static_cast<std::streamsize>(chunk));
  const auto got = static_cast<std::size_t>(in_.gcount());
  buffer_.resize(old + got);
  if (in_.bad()) fail(path_, number_ + 1, "read error");
  if (got < chunk) eof_ = true;
  return got > 0;
}

bool LineReader::next(std::string& line) {
  std::size_t scanned = at_;  // buffer_[at_, scanned) holds neither a newline nor a NUL
  std::size_t end = 0;
  for (;;) {
    const std::size_t newline = buffer_.find('\n', scanned);
    end = newline == std::string::npos ? buffer_.size() : newline;
    if (std::memchr(buffer_.data() + scanned, '\0', end - scanned) != nullptr) {
      fail(path_, number_ + 1, "contains a NUL byte: not a text file");
    }
    if (end - at_ > max_line) {
      fail(path_, number_ + 1,
           "line longer than " + std::to_string(max_line >> 20) + " MiB: not a text file");
    }
    if (newline != std::string::npos) break;
    const std::size_t unread = buffer_.size() - at_;
    if (!fill()) {  // the last line has no newline, or there is none left
      if (buffer_.empty()) return false;
      end = buffer_.size();
      break;
    }
    scanned = unread;
  }
  line.assign(buffer_, at_, end - at_);
  at_ = std::min(end + 1, buffer_.size());
  if (number_ == 0 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);  // UTF-8 BOM
  ++number_;
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return true;
}

namespace {

// The permissions a new file gets (0666 less the umask), read without changing the umask.
mode_t new_file_mode() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("Umask:", 0) == 0) {
      return 0666 & ~static_cast<mode_t>(std::strtoul(line.c_str() + 6, nullptr, 8));
    }
  }
  return 0644;
}

}  // namespace

OutputFile::OutputFile(std::string path, Mode mode) : path_(std::move(path)), target_(path_) {
  namespace fs = std::filesystem;
  if (path_.empty()) throw Error(ErrorCode::io, "empty output path");
  struct stat st {};
  const bool exists = ::stat(path_.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode)) raycut::fail(path_, "is a directory, not a file");
  if (exists && !S_ISREG(st.st_mode)) {
    // A device or a pipe: written in place, every write still checked.
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC | (mode == Mode::append ? O_APPEND : O_TRUNC));
    if (fd_ < 0)
      raycut::fail(path_, std::string("cannot open for writing: ") + std::strerror(errno));
    buffer_.reserve(std::size_t{1} << 20);
    return;
  }
  std::error_code ec;
  if (exists && fs::is_symlink(path_, ec)) {
    const fs::path real = fs::canonical(path_, ec);
    if (!ec) target_ = real.string();
  }
  was_empty_ = !exists || st.st_size == 0;
  const fs::path target(target_);
  const std::string dir = target.has_parent_path() ? target.parent_path().string() : ".";
  std::string name = dir;  // dir/.name.tmp-XXXXXX, hidden, on the same file system
  name += "/.";
  name += target.filename().string();
  name += ".tmp-XXXXXX";
  fd_ = ::mkstemp(name.data());
  if (fd_ < 0)
    raycut::fail(path_, std::string("cannot write in ") + io::printable(dir, 4096) + ": " +
                            std::strerror(errno));
  temp_ = name;
  ::fchmod(fd_, exists ? (st.st_mode & 07777) : new_file_mode());
  buffer_.reserve(std::size_t{1} << 20);
  if (mode == Mode::append && exists && st.st_size > 0) {
    std::ifstream old(target_, std::ios::binary);
    if (!old) fail(std::string("cannot open for reading: ") + std::strerror(errno));
    std::vector<char> chunk(std::size_t{1} << 16);
    while (old.read(chunk.data(), static_cast<std::streamsize>(chunk.size())) || old.gcount() > 0)
      write_all(chunk.data(), static_cast<std::size_t>(old.gcount()));
    if (old.bad()) fail("read error while copying the existing file");
  }
}

OutputFile::~OutputFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !temp_.empty()) ::unlink(temp_.c_str());
}

// Closes and removes the temporary file (the target is left as it was), then throws.
void OutputFile::fail(const std::string& what) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!temp_.empty()) ::unlink(temp_.c_str());
  temp_.clear();
  buffer_.clear();
  raycut::fail(path_, what);
}

void OutputFile::write_all(const char* data, std::size_t size) {
  if (fd_ < 0) fail("write after an error or after commit");
  while (size > 0) {
    const ssize_t n = ::write(fd_, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail(std::string("write failed: ") + std::strerror(n < 0 ? errno : EIO));
    data += n;
    size -= static_cast<std::size_t>(n);
  }
}

void OutputFile::write(std::string_view text) {
  buffer_.append(text);
  if (buffer_.size() >= (std::size_t{1} << 20)) flush();
}

void OutputFile::flush() {
  write_all(buffer_.data(), buffer_.size());
  buffer_.clear();
}

void OutputFile::commit() {
  flush();
  if (!temp_.empty() && ::fsync(fd_) != 0)
    fail(std::string("write failed: ") + std::strerror(errno));
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail(std::string("write failed (close): ") + std::strerror(errno));
  if (!temp_.empty() && ::rename(temp_.c_str(), target_.c_str()) != 0)
    fail(std::string("cannot rename the finished file into place: ") + std::strerror(errno));
  committed_ = true;
}

}  // namespace io
}  // namespace raycut
