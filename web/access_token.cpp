#include "web/access_token.hpp"

#include <fstream>
#include <stdexcept>

namespace neurosim::web {

namespace {

bool url_safe(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' ||
         c == '.' || c == '_' || c == '~';
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return {};
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

}  // namespace

bool constant_time_equal(std::string_view expected, std::string_view presented) {
  unsigned diff = expected.size() == presented.size() ? 0U : 1U;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const unsigned char p = i < presented.size() ? static_cast<unsigned char>(presented[i]) : 0U;
    diff |= static_cast<unsigned>(static_cast<unsigned char>(expected[i]) ^ p);
  }
  return diff == 0;
}

AccessToken AccessToken::from_text(std::string token, const std::string& source) {
  if (token.size() < kMinTokenLength)
    throw std::invalid_argument(source + ": the access token has " + std::to_string(token.size()) +
                                " characters, at least " + std::to_string(kMinTokenLength) +
                                " are needed");
  if (token.size() > kMaxTokenLength)
    throw std::invalid_argument(source + ": the access token is longer than " +
                                std::to_string(kMaxTokenLength) + " characters");
  for (std::size_t i = 0; i < token.size(); ++i)
    if (!url_safe(token[i]))
      throw std::invalid_argument(source + ": character " + std::to_string(i + 1) +
                                  " of the access token is not one of A-Z a-z 0-9 - . _ ~");
  return AccessToken(std::move(token));
}

AccessToken AccessToken::from_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("--token-file " + path + ": cannot be read");
  std::string line;
  std::getline(in, line);
  return from_text(trim(line), "--token-file " + path);
}

bool AccessToken::matches(std::string_view presented) const {
  return constant_time_equal(token_, presented);
}

std::string_view AccessToken::bearer(std::string_view h) {
  constexpr std::string_view kScheme = "Bearer ";
  if (h.size() <= kScheme.size()) return {};
  for (std::size_t i = 0; i < kScheme.size(); ++i) {
    const char a = h[i], b = kScheme[i];
    const char la = (a >= 'A' && a <= 'Z') ? static_cast<char>(a - 'A' + 'a') : a;
    const char lb = (b >= 'A' && b <= 'Z') ? static_cast<char>(b - 'A' + 'a') : b;
    if (la != lb) return {};  // the scheme is case-insensitive (RFC 7235)
  }
  std::string_view t = h.substr(kScheme.size());
  while (!t.empty() && (t.front() == ' ' || t.front() == '\t')) t.remove_prefix(1);
  while (!t.empty() && (t.back() == ' ' || t.back() == '\t')) t.remove_suffix(1);
  return t;
}

}  // namespace neurosim::web
