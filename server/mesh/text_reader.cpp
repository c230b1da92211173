#include "server/mesh/text_reader.hpp"

#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace neurosim::mesh {

TextReader::TextReader(std::string path, char comment) : path_(std::move(path)), comment_(comment) {
  std::ifstream in(path_, std::ios::binary);
  if (!in) throw std::runtime_error(path_ + ": cannot open file");
  std::ostringstream buf;
  buf << in.rdbuf();
  if (in.bad()) throw std::runtime_error(path_ + ": read error");
  text_ = buf.str();
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
