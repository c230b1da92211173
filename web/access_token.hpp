// The bridge's access token: given on the command line or in a file, presented by a client as
// the URL parameter `?token=` or an `Authorization: Bearer` header, compared in constant time
// (the time does not depend on where a guess first differs).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace neurosim::web {

inline constexpr std::size_t kMinTokenLength = 16;   // characters
inline constexpr std::size_t kMaxTokenLength = 256;  // characters

class AccessToken {
 public:
  // Throws std::invalid_argument naming `source` (e.g. "--token") when the token is shorter
  // than kMinTokenLength or longer than kMaxTokenLength, or holds a character outside
  // A-Z a-z 0-9 - . _ ~ (those need no escaping in a URL).
  static AccessToken from_text(std::string token, const std::string& source);
  // The first line of `path`, surrounding white space removed. Throws std::invalid_argument
  // naming the file when it cannot be read or the token is not acceptable.
  static AccessToken from_file(const std::string& path);

  // Constant-time comparison with a presented token.
  bool matches(std::string_view presented) const;
  // The token of an Authorization header value "Bearer <token>" ("" when it is not one).
  static std::string_view bearer(std::string_view authorization_header);

  const std::string& text() const { return token_; }

 private:
  explicit AccessToken(std::string token) : token_(std::move(token)) {}
  std::string token_;
};

// Constant-time equality of two strings: every byte of `expected` is looked at whatever
// `presented` holds; only the length of `expected` (not secret) shows in the time.
bool constant_time_equal(std::string_view expected, std::string_view presented);

}  // namespace neurosim::web
