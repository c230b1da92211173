#include "server/mesh/text_reader.hpp"

#include "common/input_file.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace neurosim::mesh {

TextReader::TextReader(std::string path, char comment, std::size_t max_bytes)
    : path_(std::move(path)), comment_(comment) {
  // Regular files only, at most max_bytes (a named pipe would block the open, /dev/zero never
  // ends): refused before reading, naming the file.
  text_ = common::read_input_file(path_, max_bytes, "mesh file");
}

void TextReader::check_count(long long n, int tokens_each, const std::string& what) const {
  if (n < 0) fail("bad number of " + what + ": " + std::to_string(n));
  // Every number takes at least one byte (its separators are not even counted): a count above
  // this cannot be what the file holds. A count just above what the file holds is left to the
  // entries, whose own error names the line where the file ends.
  const unsigned long long per = static_cast<unsigned long long>(std::max(tokens_each, 1));
  if (static_cast<unsigned long long>(n) > bytes_left() / per)
    fail(std::to_string(n) + " " + what + " cannot fit in the " + std::to_string(bytes_left()) +
         " bytes left in the file (each takes at least " + std::to_string(per) + ")");
}

void TextReader::skip_blanks(bool cross_lines) {
  while (pos_ < text_.size()) {
    const char c = text_[pos_];
    if (c == '\n') {
      if (!cross_lines) return;
      ++line_;
      ++pos_;
    } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
      ++pos_;
    } else if (comment_ != 0 && c == comment_) {
      while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    } else {
      return;
    }
  }
}

bool TextReader::next(std::string_view& token) {
  skip_blanks(true);
  token_line_ = line_;
  if (pos_ >= text_.size()) {
    // At the end, point at the last line that has text rather than past the final newline.
    if (!text_.empty() && text_.back() == '\n' && token_line_ > 1) --token_line_;
    return false;
  }
  const std::size_t start = pos_;
  while (pos_ < text_.size()) {
    const char c = text_[pos_];
    if (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v' ||
        (comment_ != 0 && c == comment_))
      break;
    ++pos_;
  }
  token = std::string_view(text_).substr(start, pos_ - start);
  return true;
}

bool TextReader::next_on_line(std::string_view& token) {
  skip_blanks(false);
  if (pos_ >= text_.size() || text_[pos_] == '\n') return false;
  return next(token);
}

void TextReader::end_line() {
  while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  if (pos_ < text_.size()) {
    ++pos_;
    ++line_;
  }
}

std::string_view TextReader::token(const std::string& what) {
  std::string_view t;
  if (!next(t)) fail("unexpected end of file, expected " + what);
  return t;
}

double TextReader::real(const std::string& what) {
  const std::string_view t = token(what);
  double v;
  if (!parse_real(t, v)) fail("expected " + what + " (a finite number), got '" + std::string(t) + "'");
  return v;
}

long long TextReader::integer(const std::string& what) {
  const std::string_view t = token(what);
  long long v;
  if (!parse_integer(t, v)) fail("expected " + what + " (an integer), got '" + std::string(t) + "'");
  return v;
}

void TextReader::expect(std::string_view keyword) {
  const std::string_view t = token(std::string(keyword));
  if (t != keyword) fail("expected " + std::string(keyword) + ", got '" + std::string(t) + "'");
}

void TextReader::fail(const std::string& message) const { fail_at(token_line_, message); }

void TextReader::fail_at(int line, const std::string& message) const {
  throw std::runtime_error(path_ + ":" + std::to_string(line) + ": " + message);
}

bool TextReader::parse_real(std::string_view s, double& value) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return ec == std::errc() && end == s.data() + s.size() && !s.empty() && std::isfinite(value);
}

bool TextReader::parse_integer(std::string_view s, long long& value) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  return ec == std::errc() && end == s.data() + s.size() && !s.empty();
}

}  // namespace neurosim::mesh
