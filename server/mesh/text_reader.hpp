// Whitespace-token reader for mesh text formats that knows the line of every token, so a
// broken file is reported as "path:line: what was expected".
#pragma once

#include <string>
#include <string_view>

namespace neurosim::mesh {

class TextReader {
 public:
  // Reads the whole file; comment (0 for none) starts a comment that runs to the end of line.
  // Throws std::runtime_error when the file cannot be read.
  explicit TextReader(std::string path, char comment = '#');

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
