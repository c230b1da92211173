// The access token: accepted characters and lengths, files, constant-time comparison, Bearer
// headers.
#include "web/access_token.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <fstream>

namespace web = neurosim::web;
namespace nt = neurosim::testing;

TEST(AccessToken, ComparesWholeTokens) {
  const auto t = web::AccessToken::from_text("abcdefghijklmnop-1234", "--token");
  EXPECT_TRUE(t.matches("abcdefghijklmnop-1234"));
  EXPECT_FALSE(t.matches("abcdefghijklmnop-1235"));   // last character
  EXPECT_FALSE(t.matches("bbcdefghijklmnop-1234"));   // first character
  EXPECT_FALSE(t.matches("abcdefghijklmnop-123"));    // a prefix
  EXPECT_FALSE(t.matches("abcdefghijklmnop-12345"));  // longer
  EXPECT_FALSE(t.matches(""));
}

TEST(AccessToken, ConstantTimeEqualIsEquality) {
  EXPECT_TRUE(web::constant_time_equal("", ""));
  EXPECT_TRUE(web::constant_time_equal("x", "x"));
  EXPECT_FALSE(web::constant_time_equal("x", ""));
  EXPECT_FALSE(web::constant_time_equal("", "x"));
  EXPECT_FALSE(web::constant_time_equal("ab", "a\0"));
  // A presented string that equals expected followed by NULs is still different.
  EXPECT_FALSE(web::constant_time_equal("abc", std::string_view("abc\0\0", 5)));
}

TEST(AccessToken, RefusesShortLongAndUnsafeTokens) {
  EXPECT_NE(nt::message_of([] {
              web::AccessToken::from_text("short", "--token");
            }).find("--token: the access token has 5 characters, at least 16"),
            std::string::npos);
  EXPECT_NE(nt::message_of([] {
              web::AccessToken::from_text(std::string(300, 'a'), "--token");
            }).find("longer than 256"),
            std::string::npos);
  EXPECT_NE(nt::message_of([] {
              web::AccessToken::from_text("abcdefghijklmnop&x", "--token");
            }).find("character 17 of the access token"),
            std::string::npos);
  EXPECT_EQ(nt::message_of([] { web::AccessToken::from_text("A-Za-z0-9._~aaaaa", "--token"); }),
            "");
}

TEST(AccessToken, ReadsTheFirstLineOfAFile) {
  const auto dir = nt::temp_dir("web_token");
  std::ofstream(dir / "t") << "  0123456789abcdefXYZ \nsecond line\n";
  EXPECT_TRUE(web::AccessToken::from_file((dir / "t").string()).matches("0123456789abcdefXYZ"));
  const std::string missing = (dir / "missing").string();
  EXPECT_NE(nt::message_of([&] {
              web::AccessToken::from_file(missing);
            }).find("--token-file " + missing + ": cannot be read"),
            std::string::npos);
  std::ofstream(dir / "empty") << "\n";
  EXPECT_NE(nt::message_of([&] {
              web::AccessToken::from_file((dir / "empty").string());
            }).find("empty: the access token has 0 characters"),
            std::string::npos);
}

TEST(AccessToken, BearerHeader) {
  EXPECT_EQ(web::AccessToken::bearer("Bearer abc"), "abc");
  EXPECT_EQ(web::AccessToken::bearer("bearer  abc "), "abc");
  EXPECT_EQ(web::AccessToken::bearer("Basic abc"), "");
  EXPECT_EQ(web::AccessToken::bearer("Bearer "), "");
  EXPECT_EQ(web::AccessToken::bearer(""), "");
}
