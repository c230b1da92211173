// Command lines: every neurosim program answers --help and --version ("<program> <project
// version>") and reports usage errors the same way:
//
//   <program>: <message>                      (on stderr)
//   Run with --help for more information.
//
// and exit status 2. Typical main:
//
//   neurosim::cli::Parser cli("neurosim-thing", "What it does.");
//   cli.add_option("--duration", duration, "stop after S seconds")->check(cli::positive());
//   cli.add_flag("--csv", csv, "print CSV");
//   if (auto rc = cli.parse(argc, argv)) return *rc;
//
// CLI11 does the parsing, behind this header: only common/cli.cpp includes it (a file that
// includes CLI11 costs seconds of compile, this one does not). The API is CLI11's names, cut
// to what the programs use:
//
//   Parser::add_option(name, target, description)   an option ("--x", "-x,--x") or, without
//       a leading '-', a positional argument; target: std::string, double, int, unsigned, or
//       a std::vector of std::string, double or int (an option that may be repeated, or takes
//       several values)
//   Parser::add_option_function<T>(name, f, description)   f(value) for each value given;
//       f reports a bad value by throwing UsageError (T: std::string, double or int)
//   Parser::add_flag(name, bool&, description), add_flag_function(name, f, description)
//   Parser::add_triple(name, std::array<double, 3>&, description)   "X,Y,Z", finite numbers
//   Parser::footer(text)   text after the option list in --help
//   Parser::check(rule)    a rule across options, run after a successful parse
//   Parser::count(name)    how often an option was given (after parse)
//   Option: ->required(), ->check(Check), ->capture_default_str() (--help shows the default),
//       ->excludes(other), ->needs(other), ->expected(n) (n values per use), ->take_all()
//       (a repeated option collects every value), ->type_name(text), ->count()
//   Check: finite(), positive(), non_negative(), in_range(lo, hi) (the value must be a finite
//       number); range(lo, hi) (CLI11's Range: integer bounds check an integer, --help shows
//       "INT in [lo - hi]" or "FLOAT in [lo - hi]"), positive_number(), non_negative_number()
//       (CLI11's PositiveNumber, NonNegativeNumber), one_of({...}) and
//       one_of_ignore_case({...}) (CLI11's IsMember), or Check(rule, description) of one's own.
//
// An option given twice keeps its last value (unless ->take_all()).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace CLI {
class App;
class Option;
class Validator;
}  // namespace CLI

namespace neurosim::cli {

// Exit status of a usage error (bad, missing or unknown option).
inline constexpr int kUsageError = 2;

// The project version, e.g. "0.1.0" (CMake's project(VERSION)).
const char* version();

// A usage error found by a program's own checks.
struct UsageError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// Prints "<program>: <message>" and the --help hint on err; returns kUsageError.
int report_usage_error(const std::string& program, const std::string& message, std::ostream& err);
int report_usage_error(const std::string& program, const std::string& message);

// A check of an option's value (text as given).
class Check {
 public:
  // rule returns "" when the value is good, otherwise the message; description is shown in
  // --help (CLI11's Validator).
  Check(std::function<std::string(std::string&)> rule, const std::string& description);
  explicit Check(std::shared_ptr<const CLI::Validator> validator);

  const CLI::Validator& validator() const { return *validator_; }

 private:
  std::shared_ptr<const CLI::Validator> validator_;
};

Check finite();                        // any finite number
Check positive();                      // > 0
Check non_negative();                  // >= 0
Check in_range(double lo, double hi);  // in [lo, hi]
Check range(int lo, int hi);           // CLI11's Range
Check range(double lo, double hi);
Check positive_number();                                           // CLI11's PositiveNumber
Check non_negative_number();                                       // CLI11's NonNegativeNumber
Check one_of(const std::vector<std::string>& values);              // CLI11's IsMember
Check one_of_ignore_case(const std::vector<std::string>& values);  // IsMember, ignore_case

// One option of a Parser (owned by it).
class Option {
 public:
  explicit Option(CLI::Option* option) : option_(option) {}

  Option* required();
  Option* check(const Check& check);
  Option* capture_default_str();
  Option* excludes(Option* other);
  Option* needs(Option* other);
  Option* expected(int values);
  Option* take_all();
  Option* type_name(const std::string& name);
  std::size_t count() const;

 private:
  CLI::Option* option_;
};

class Parser {
 public:
  // --help/-h and --version are there; an option given twice keeps its last value.
  explicit Parser(std::string program, std::string description = "");
  ~Parser();
  Parser(const Parser&) = delete;
  Parser& operator=(const Parser&) = delete;

  const std::string& program() const { return program_; }

  Option* add_option(const std::string& name, std::string& target,
                     const std::string& description = "");
  Option* add_option(const std::string& name, double& target, const std::string& description = "");
  Option* add_option(const std::string& name, int& target, const std::string& description = "");
  Option* add_option(const std::string& name, unsigned& target,
                     const std::string& description = "");
  Option* add_option(const std::string& name, std::vector<std::string>& target,
                     const std::string& description = "");
  Option* add_option(const std::string& name, std::vector<double>& target,
                     const std::string& description = "");
  Option* add_option(const std::string& name, std::vector<int>& target,
                     const std::string& description = "");
  template <typename T>  // std::string, double or int
  Option* add_option_function(const std::string& name, std::function<void(const T&)> f,
                              const std::string& description = "");
  Option* add_flag(const std::string& name, bool& target, const std::string& description = "");
  Option* add_flag_function(const std::string& name, std::function<void(std::int64_t)> f,
                            const std::string& description = "");
  // An option taking "X,Y,Z" (three finite numbers) into out.
  Option* add_triple(const std::string& name, std::array<double, 3>& out,
                     const std::string& description);
  void footer(const std::string& text);

  // A rule checked after a successful parse (across options); it reports a usage error by
  // throwing UsageError (or any std::invalid_argument).
  void check(std::function<void()> rule) { checks_.push_back(std::move(rule)); }

  // Parses argv. Returns std::nullopt when the program should run; otherwise the program's exit
  // status: 0 after --help or --version (printed on out), kUsageError after a usage error
  // (reported on err).
  std::optional<int> parse(int argc, const char* const* argv);
  std::optional<int> parse(int argc, const char* const* argv, std::ostream& out, std::ostream& err);

  // As parse, but a usage error is thrown as UsageError(message). Returns false when --help or
  // --version was answered (printed on out): the program should exit 0.
  bool parse_or_throw(int argc, const char* const* argv);
  bool parse_or_throw(int argc, const char* const* argv, std::ostream& out);

  // How often the option (one of its names) was given; after parse.
  std::size_t count(const std::string& name) const;

  // A usage error found after parse: reported like the others; returns kUsageError.
  int usage_error(const std::string& message) const;

 private:
  Option* wrap(CLI::Option* option);

  std::string program_;
  std::unique_ptr<CLI::App> app_;
  std::vector<std::unique_ptr<Option>> options_;
  std::vector<std::function<void()>> checks_;
};

// Parses "X,Y,Z"; throws UsageError naming option on anything else.
std::array<double, 3> parse_triple(const std::string& option, const std::string& text);

}  // namespace neurosim::cli
