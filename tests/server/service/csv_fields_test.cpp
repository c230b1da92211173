// CsvFields: comment and blank lines skipped, '\r' dropped, fields split on ',' (a trailing ','
// an empty field), numbers and counts checked whole; every bad input an error naming the file
// and the line it is on.
#include "server/service/csv_fields.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <stdexcept>

namespace neurosim::service {
namespace {

using neurosim::testing::message_of;

std::filesystem::path write(const std::string& text) {
  return neurosim::testing::write_temp_file("csv_fields", "t.csv", text);
}

// The message of reading field 0 of the first line of `text` with `read`.
template <class Read>
std::string message_reading(const std::string& text, Read read) {
  CsvFields in(write(text), "table");
  EXPECT_TRUE(in.next());
  return message_of([&] {
    in.split(1);
    read(in);
  });
}

TEST(CsvFields, SkipsCommentsAndBlankLinesAndKnowsTheLine) {
  const auto file = write("# comment\n\nscene,x\r\n#,1\r\n\r\na,,2,\n");
  CsvFields in(file, "table");
  ASSERT_TRUE(in.next());
  EXPECT_EQ(in.line(), "scene,x");
  EXPECT_EQ(in.where(), file.string() + ":3");
  ASSERT_TRUE(in.next());
  EXPECT_EQ(in.where(), file.string() + ":6") << "lines 4 (a comment) and 5 (blank) skipped";
  in.split(4);
  EXPECT_EQ(in.text(0), "a");
  EXPECT_EQ(in.text(1), "");
  EXPECT_NE(message_of([&] { in.number(1, "n"); }).find("n: '' is not a finite number"),
            std::string::npos);
  EXPECT_EQ(in.number(2, "n"), 2.0);
  EXPECT_EQ(in.text(3), "") << "a trailing ',' is an empty last field";
  EXPECT_FALSE(in.next());
  EXPECT_FALSE(in.next());
}

TEST(CsvFields, AWrongFieldCountNamesFileAndLine) {
  const auto file = write("h\n#\na,b,c\n");
  CsvFields in(file, "table");
  ASSERT_TRUE(in.next());
  ASSERT_TRUE(in.next());
  EXPECT_EQ(message_of([&] { in.split(2); }), file.string() + ":3: 3 fields, expected 2");
  EXPECT_EQ(message_of([&] { in.fail("what"); }), file.string() + ":3: what");
}

TEST(CsvFields, NumbersAreWholeFiniteAndNotNegative) {
  const auto number = [](CsvFields& in) { in.number(0, "max_strain"); };
  for (const char* bad : {"nan", "inf", "-0.1", "0.1x", "x", "1e400"}) {
    const std::string m = message_reading(std::string(bad) + "\n", number);
    EXPECT_NE(m.find(".csv:1 max_strain: '" + std::string(bad) + "' is not a finite number >= 0"),
              std::string::npos)
        << bad << ": " << m;
  }
  CsvFields in(write("0.25,0,1e-3\n"), "table");
  ASSERT_TRUE(in.next());
  in.split(3);
  EXPECT_EQ(in.number(0, "a"), 0.25);
  EXPECT_EQ(in.number(1, "b"), 0.0);
  EXPECT_EQ(in.number(2, "c"), 1e-3);
}

TEST(CsvFields, CountsAreWholeFromOneTo2To53) {
  const auto count = [](CsvFields& in) { in.count(0, "host_vertices"); };
  for (const char* bad : {"5354.5", "0", "1e30"}) {
    const std::string m = message_reading(std::string(bad) + "\n", count);
    EXPECT_NE(m.find(".csv:1 host_vertices: '" + std::string(bad) + "' is not a count"),
              std::string::npos)
        << bad << ": " << m;
  }
  EXPECT_NE(message_reading("-3\n", count).find("is not a finite number >= 0"), std::string::npos);
  CsvFields in(write("5354,1e3\n"), "table");
  ASSERT_TRUE(in.next());
  in.split(2);
  EXPECT_EQ(in.count(0, "v"), 5354u);
  EXPECT_EQ(in.count(1, "t"), 1000u);
}

TEST(CsvFields, TheHeaderIsOneOfThoseAcceptedAndGivesTheFieldCount) {
  const auto header_of = [](const std::string& text) {
    CsvFields in(write(text), "table");
    return in.header({"a,b,c", "a,b"});
  };
  EXPECT_EQ(header_of("# comment\n\na,b,c\n1,2,3\n"), 3u);
  EXPECT_EQ(header_of("a,b\r\n"), 2u);
  const auto file = write("# comment\na,b,d\n");
  EXPECT_EQ(message_of([&] {
              CsvFields(file, "table").header({"a,b,c", "a,b"});
            }),
            file.string() + ":2: expected the header 'a,b,c', got 'a,b,d'");
  const auto empty = write("# only a comment\n\n");
  EXPECT_EQ(message_of([&] { CsvFields(empty, "table").header({"a,b,c"}); }),
            empty.string() + ": no header line (empty table)");
}

TEST(CsvFields, AMissingFileNamesItAndWhatItHolds) {
  EXPECT_EQ(message_of([] { CsvFields("/nonexistent/t.csv", "accuracy table"); }),
            "/nonexistent/t.csv: cannot open the accuracy table");
}

}  // namespace
}  // namespace neurosim::service
