// Whitespace-token reader for mesh text formats that knows the line of every token, so a
// broken file is reported as "path:line: what was expected".
//
// Hostile input: the file is read whole but never more than max_bytes (a FIFO or a device that
// never ends stops there), and every count a header states is checked against the bytes left in
// the file (check_count) before anything is allocated for it, so what a reader allocates stays a
// small multiple of the file's size.
#pragma once

#include <cstddef>
#include <new>
#include <stdexcept>
#include <string>
#include <string_view>

namespace neurosim::mesh {

// Largest mesh text file read, unit bytes (256 MiB: about 7 million tetrahedra in Medit; the
// patient model's files are a few MB).
inline constexpr std::size_t kMaxMeshFileBytes = std::size_t{256} << 20;

// Runs read() and reports std::bad_alloc as std::runtime_error("path: out of memory while
// reading"): a file too large for this machine is bad input to report, not a crash.
template <class Read>
auto guard_out_of_memory(const std::string& path, Read&& read) -> decltype(read()) {
  try {
    return read();
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(path + ": out of memory while reading");
  }
}

class TextReader {
 public:
  // Reads the whole file; comment (0 for none) starts a comment that runs to the end of line.
  // Throws std::runtime_error naming the file when it cannot be read or is larger than
  // max_bytes.
  explicit TextReader(std::string path, char comment = '#',
                      std::size_t max_bytes = kMaxMeshFileBytes);

  // Next token, across line ends; false at the end of the file.
  bool next(std::string_view& token);
  // Next token on the current line only; false at the end of the line (not consumed).
  bool next_on_line(std::string_view& token);
  // Skips the rest of the current line, including its end.
  void end_line();

  // Next token, or an error "unexpected end of file, expected <what>".
  std::string_view token(const std::string& what);
  double real(const std::string& what);      // a finite number
  long long integer(const std::string& what);
  // Next token must equal keyword (case-sensitive).
  void expect(std::string_view keyword);

  // Bytes of the file after the last token read.
  std::size_t bytes_left() const { return text_.size() - pos_; }
  // Checks a count read from the file before anything is allocated for it: n entries of at
  // least tokens_each numbers (one byte each at least) must fit in the bytes left, so what is
  // allocated for them stays within a few times the file's size. Fails
  // "path:line: <n> <what> cannot fit in the <b> bytes left in the file (...)".
  void check_count(long long n, int tokens_each, const std::string& what) const;

  // Line (1-based) of the last token read, or of the end of the file.
  int line() const { return token_line_; }
  const std::string& path() const { return path_; }
  // Throws std::runtime_error("path:line: message").
  [[noreturn]] void fail(const std::string& message) const;
  [[noreturn]] void fail_at(int line, const std::string& message) const;

  static bool parse_real(std::string_view s, double& value);
  static bool parse_integer(std::string_view s, long long& value);

 private:
  void skip_blanks(bool cross_lines);

  std::string path_;
  std::string text_;
  std::size_t pos_{0};
  int line_{1};        // line at pos_
  int token_line_{1};  // line of the last token
  char comment_;
};

}  // namespace neurosim::mesh
