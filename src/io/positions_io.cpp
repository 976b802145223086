// CSV and extended-XYZ positions. Numbers are written in the shortest form that reads back to
// the same float (std::to_chars), and read with std::from_chars, so a write/read round trip is
// bit-exact. Every error names the file, and the line where there is one.
#include "raycut/io.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <system_error>
#include <vector>

#include "raycut/error.hpp"

namespace raycut {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw Error(ErrorCode::io, path + ": " + what);
}
[[noreturn]] void fail(const std::string& path, std::size_t line, const std::string& what) {
  throw Error(ErrorCode::io, path + ":" + std::to_string(line) + ": " + what);
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
      fail(path, line, "'" + std::string(token) + "' (" + column + ") is out of float range");
    case Parse::not_a_number:
      break;
  }
  fail(path, line, "cannot parse '" + std::string(token) + "' (" + column + ") as a number");
}

constexpr const char* axis_names[3] = {"x", "y", "z"};

// Lines of a file, numbered from 1, without their line terminator.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    if (!in_) fail(path, std::string("cannot open for reading: ") + std::strerror(errno));
    // Linux opens a directory for reading; only the first read fails.
    std::error_code ignored;
    if (std::filesystem::is_directory(path, ignored)) fail(path, "is a directory, not a file");
  }
  bool next(std::string& line) {
    if (!std::getline(in_, line)) {
      if (in_.bad()) fail(path_, number_ + 1, "read error");
      return false;
    }
    ++number_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }
  std::size_t number() const { return number_; }

 private:
  std::string path_;
  std::ifstream in_;
  std::size_t number_ = 0;
};

PointCloud read_csv(const std::string& path) {
  PointCloud cloud;
  cloud.name = path;
  LineReader reader(path);
  std::string line;
  bool first_content_line = true;
  std::vector<std::string_view> fields;
  while (reader.next(line)) {
    const std::string_view text = trim(line);
    if (text.empty() || text.front() == '#') continue;
    fields.clear();
    for (std::size_t begin = 0;;) {
      const std::size_t comma = text.find(',', begin);
      fields.push_back(trim(text.substr(begin, comma - begin)));
      if (comma == std::string_view::npos) break;
      begin = comma + 1;
    }
    if (first_content_line) {
      first_content_line = false;
      float ignored = 0;
      const bool any_number = std::any_of(fields.begin(), fields.end(), [&](std::string_view f) {
        return parse_float(f, ignored) == Parse::ok;
      });
      if (!any_number) continue;  // a header such as "x,y,z"
    }
    if (fields.size() != 3) {
      fail(path, reader.number(),
           "expected 3 comma-separated numbers (x,y,z), found " + std::to_string(fields.size()) +
               " fields");
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
    fail(path, line,
         "malformed Properties '" + std::string(value) + "' (expected name:type:count)");
  }
  std::size_t column = 0;
  for (std::size_t i = 0; i < parts.size(); i += 3) {
    std::size_t count = 0;
    const auto [ptr, ec] =
        std::from_chars(parts[i + 2].data(), parts[i + 2].data() + parts[i + 2].size(), count);
    if (ec != std::errc() || ptr != parts[i + 2].data() + parts[i + 2].size()) {
      fail(path, line, "malformed Properties count '" + std::string(parts[i + 2]) + "'");
    }
    if (lowercase(parts[i]) == "pos") {
      if (lowercase(parts[i + 1]) != "r" || count != 3) {
        fail(path, line, "Properties pos must be pos:R:3");
      }
      return column;
    }
    column += count;
  }
  fail(path, line, "Properties has no pos:R:3 field");
}

// The first frame of an (extended) XYZ file; later frames are ignored.
PointCloud read_xyz(const std::string& path) {
  PointCloud cloud;
  cloud.name = path;
  LineReader reader(path);
  std::string line;
  if (!reader.next(line)) fail(path, 1, "empty file, expected the particle count");
  const std::string_view count_text = trim(line);
  std::size_t count = 0;
  const auto [ptr, ec] =
      std::from_chars(count_text.data(), count_text.data() + count_text.size(), count);
  if (count_text.empty() || ec != std::errc() || ptr != count_text.data() + count_text.size()) {
    fail(path, 1, "expected the particle count, found '" + std::string(count_text) + "'");
  }
  if (!reader.next(line)) {
    if (count == 0) return cloud;
    fail(path, 2, "missing comment line");
  }
  const std::size_t pos_column = xyz_position_column(line, path, reader.number());
  cloud.xyz.reserve(3 * std::min<std::size_t>(count, std::size_t{1} << 24));
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
  return cloud;
}

std::string extension_of(const std::string& path) {
  const std::size_t slash = path.find_last_of("/\\");
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return lowercase(std::string_view(path).substr(dot));
}

// Buffered text output that reports failures with the path.
class Writer {
 public:
  explicit Writer(const std::string& path) : path_(path), out_(path, std::ios::binary) {
    if (!out_) fail(path, std::string("cannot open for writing: ") + std::strerror(errno));
    buffer_.reserve(buffer_limit + 256);
  }
  void text(std::string_view s) {
    buffer_.append(s);
    if (buffer_.size() >= buffer_limit) flush();
  }
  // Shortest representation that reads back to the same float.
  void number(float value) {
    char digits[64];
    const auto result = std::to_chars(digits, digits + sizeof digits, value);
    text(std::string_view(digits, static_cast<std::size_t>(result.ptr - digits)));
  }
  void close() {
    flush();
    out_.close();
    if (!out_) fail(path_, "write failed");
  }

 private:
  static constexpr std::size_t buffer_limit = std::size_t{1} << 20;
  void flush() {
    out_.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    if (!out_) fail(path_, std::string("write failed: ") + std::strerror(errno));
    buffer_.clear();
  }
  std::string path_;
  std::ofstream out_;
  std::string buffer_;
};

void require_whole_points(const std::string& path, const PointCloud& cloud) {
  if (cloud.xyz.size() % 3 != 0) {
    throw Error(ErrorCode::invalid_argument, path + ": positions hold " +
                                                 std::to_string(cloud.xyz.size()) +
                                                 " floats, not a multiple of 3");
  }
}

}  // namespace

PointCloud read_positions(const std::string& path) {
  const std::string extension = extension_of(path);
  if (extension == ".csv") return read_csv(path);
  if (extension == ".xyz" || extension == ".extxyz") return read_xyz(path);
  fail(path, "unknown extension '" + extension + "' (known: .csv, .xyz, .extxyz)");
}

void write_csv(const std::string& path, const PointCloud& cloud) {
  require_whole_points(path, cloud);
  Writer out(path);
  out.text("x,y,z\n");
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    out.number(cloud.xyz[3 * i]);
    out.text(",");
    out.number(cloud.xyz[3 * i + 1]);
    out.text(",");
    out.number(cloud.xyz[3 * i + 2]);
    out.text("\n");
  }
  out.close();
}

void write_xyz(const std::string& path, const PointCloud& cloud) {
  require_whole_points(path, cloud);
  Writer out(path);
  out.text(std::to_string(cloud.size()) + "\nProperties=species:S:1:pos:R:3\n");
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    out.text("X ");
    out.number(cloud.xyz[3 * i]);
    out.text(" ");
    out.number(cloud.xyz[3 * i + 1]);
    out.text(" ");
    out.number(cloud.xyz[3 * i + 2]);
    out.text("\n");
  }
  out.close();
}

}  // namespace raycut
