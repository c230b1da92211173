// The CSV files of the measured tables (accuracy_table, discretization_table): read line by line,
// '#' comment lines and blank lines skipped, a data line split on ',' into the number of fields
// its header promises, every number checked. Each error names the file and the line
// ("<file>:<line>: 5 fields, expected 6"; a field's name after the line: "<file>:<line>
// max_strain: 'nan' is not a finite number >= 0").
#pragma once

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

namespace neurosim::service {

class CsvFields {
 public:
  // Opens `file`; throws std::runtime_error "<file>: cannot open the <what>".
  CsvFields(const std::filesystem::path& file, const std::string& what);

  // Reads the header: the first line that is neither blank nor a comment must be one of
  // `accepted` (the first is the current one, named in the error). Returns its number of fields.
  // Throws "<file>: no header line (empty table)" or "<file>:<line>: expected the header '...',
  // got '...'".
  std::size_t header(std::initializer_list<std::string_view> accepted);

  // Moves to the next line that is neither blank nor a '#' comment (a trailing '\r' dropped);
  // false at the end of the file.
  bool next();
  // The current line, as read.
  const std::string& line() const { return line_; }
  // "<file>:<line>" of the current line.
  std::string where() const;
  // Throws std::runtime_error "<file>:<line>: <message>".
  [[noreturn]] void fail(const std::string& message) const;

  // Splits the current line on ',' (a trailing ',' is an empty last field); fails
  // "N fields, expected M" unless it has `expected` fields.
  void split(std::size_t expected);
  // Field i of the split line, as text.
  const std::string& text(std::size_t i) const { return fields_.at(i); }
  // Field i as a finite number >= 0 (the whole field: "0.1x" is refused); fails
  // "<file>:<line> <name>: '<text>' is not a finite number >= 0".
  double number(std::size_t i, const std::string& name) const;
  // Field i as a whole number from 1 to 2^53; fails "... is not a count (...)".
  std::size_t count(std::size_t i, const std::string& name) const;

  const std::filesystem::path& file() const { return file_; }

 private:
  std::filesystem::path file_;
  std::ifstream in_;
  std::string line_;
  int line_number_{0};  // 1-based, of line_
  std::vector<std::string> fields_;
};

}  // namespace neurosim::service
