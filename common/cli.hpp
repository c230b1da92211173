// Command lines: thin helpers over CLI11 so that every neurosim program answers --help and
// --version ("<program> <project version>") and reports usage errors the same way:
//
//   <program>: <message>                      (on stderr)
//   Run with --help for more information.
//
// and exit status 2. Typical main:
//
//   neurosim::cli::Parser cli("neurosim-thing", "What it does.");
//   cli->add_option("--duration", duration_s, "stop after S seconds")->check(cli::positive());
//   if (auto rc = cli.parse(argc, argv)) return *rc;
#pragma once

#include <CLI/CLI.hpp>

#include <array>
#include <functional>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

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

class Parser {
 public:
  // --help/-h and --version are there; an option given twice keeps its last value.
  explicit Parser(std::string program, std::string description = "");

  CLI::App& app() { return app_; }
  CLI::App* operator->() { return &app_; }
  const std::string& program() const { return program_; }

  // A rule checked after a successful parse (across options); it reports a usage error by
  // throwing UsageError (or any std::invalid_argument, or CLI::ValidationError).
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

  // A usage error found after parse: reported like the others; returns kUsageError.
  int usage_error(const std::string& message) const;

 private:
  std::string program_;
  CLI::App app_;
  std::vector<std::function<void()>> checks_;
};

// Number checks for options (the value must parse as a number in full, and be finite).
CLI::Validator finite();                        // any finite number
CLI::Validator positive();                      // > 0
CLI::Validator non_negative();                  // >= 0
CLI::Validator in_range(double lo, double hi);  // in [lo, hi]

// An option taking "X,Y,Z" (three finite numbers) into out.
CLI::Option* add_triple(CLI::App& app, const std::string& name, std::array<double, 3>& out,
                        const std::string& description);
// Parses "X,Y,Z"; throws UsageError naming option on anything else.
std::array<double, 3> parse_triple(const std::string& option, const std::string& text);

}  // namespace neurosim::cli
