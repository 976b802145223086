// Text files in and out, for every reader and writer of the library and the command-line tool:
// lines read with a length cap, files written whole or not at all, and tokens quoted safely into
// messages. Internal (src/), implemented in positions_io.cpp. Errors are Error(io) naming the path.
#pragma once

#include <cstddef>
#include <fstream>
#include <string>
#include <string_view>

namespace raycut::io {

// `text` made safe for a one-line message: control characters and NUL escaped (\n, \t, \xNN),
// and cut to at most `limit` bytes (at a UTF-8 character boundary) with "... (N bytes)".
std::string printable(std::string_view text, std::size_t limit = 64);

// Lines of a text file, numbered from 1, without their terminator ("\n" or "\r\n"). A UTF-8 byte
// order mark at the start is skipped. A line longer than max_line bytes or a NUL byte (a binary
// file, /dev/zero) is an error naming the file and line, so nothing grows without bound.
class LineReader {
 public:
  static constexpr std::size_t max_line = std::size_t{1} << 20;  // 1 MiB

  // Throws Error(io) when the path cannot be opened or is a directory.
  explicit LineReader(const std::string& path);
  // The next line into `line`; false at the end of the file.
  bool next(std::string& line);
  std::size_t number() const { return number_; }
  const std::string& path() const { return path_; }

 private:
  bool fill();
  std::string path_;
  std::ifstream in_;
  std::string buffer_;
  std::size_t at_ = 0;
  std::size_t number_ = 0;
  bool eof_ = false;
};

// An output file that appears whole or not at all. The constructor creates a temporary file next
// to `path` (so an unwritable target fails before any work is done); write() buffers, every write
// and the close are checked, and commit() renames the temporary file over `path`. Destroyed
// without commit() (an error, an exception), it removes the temporary file and leaves `path` as
// it was. A target that exists and is not a regular file (/dev/null, /dev/full, a pipe) cannot be
// replaced by a rename: it is written directly, with the same checks. A symbolic link to a
// regular file is followed (its target is replaced). Append mode copies the existing file into
// the temporary file first. Errors: Error(io), one line naming `path`.
class OutputFile {
 public:
  enum class Mode { replace, append };
  explicit OutputFile(std::string path, Mode mode = Mode::replace);
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::string_view text);
  // Pushes buffered text into the (temporary) file, e.g. after each row of a long run.
  void flush();
  // Flushes, syncs, closes and renames into place. Call once, at the end.
  void commit();
  const std::string& path() const { return path_; }
  // Whether the file was empty (or absent) when opened: append mode writes a header then.
  bool was_empty() const { return was_empty_; }

 private:
  [[noreturn]] void fail(const std::string& what);
  void write_all(const char* data, std::size_t size);
  std::string path_;    // as given, for messages
  std::string target_;  // where the data lands (symbolic links resolved)
  std::string temp_;    // empty when writing directly
  int fd_ = -1;
  bool was_empty_ = true;
  bool committed_ = false;
  std::string buffer_;
};

}  // namespace raycut::io
