#include "common/cli.hpp"

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>

#ifndef NEUROSIM_VERSION
#error "NEUROSIM_VERSION must be defined (common/CMakeLists.txt passes project(VERSION))"
#endif

namespace neurosim::cli {

const char* version() { return NEUROSIM_VERSION; }

int report_usage_error(const std::string& program, const std::string& message, std::ostream& err) {
  err << program << ": " << message << "\nRun with --help for more information.\n";
  return kUsageError;
}

int report_usage_error(const std::string& program, const std::string& message) {
  return report_usage_error(program, message, std::cerr);
}

namespace {

// CLI11 says "--opt: 1 required FLOAT missing" for an option given without its value.
std::string missing_value(const std::string& what) {
  const auto colon = what.find(": ");
  const std::string tail = " missing";
  if (colon != std::string::npos && what.size() > tail.size() &&
      what.compare(what.size() - tail.size(), tail.size(), tail) == 0)
    return what.substr(0, colon) + " needs a value";
  return what;
}

}  // namespace

Parser::Parser(std::string program, std::string description)
    : program_(std::move(program)), app_(std::move(description), program_) {
  app_.set_version_flag("--version", program_ + " " + version(), "Print the version and exit");
  app_.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
}

bool Parser::parse_or_throw(int argc, const char* const* argv, std::ostream& out) {
  try {
    app_.parse(argc, argv);
    for (const auto& rule : checks_) rule();
  } catch (const CLI::CallForHelp&) {
    out << app_.help();
    return false;
  } catch (const CLI::CallForAllHelp&) {
    out << app_.help("", CLI::AppFormatMode::All);
    return false;
  } catch (const CLI::CallForVersion& e) {
    out << e.what() << "\n";
    return false;
  } catch (const CLI::ArgumentMismatch& e) {
    throw UsageError(missing_value(e.what()));
  } catch (const CLI::ParseError& e) {
    throw UsageError(e.what());
  } catch (const UsageError&) {
    throw;
  } catch (const std::invalid_argument& e) {
    throw UsageError(e.what());
  }
  return true;
}

bool Parser::parse_or_throw(int argc, const char* const* argv) {
  return parse_or_throw(argc, argv, std::cout);
}

std::optional<int> Parser::parse(int argc, const char* const* argv, std::ostream& out,
                                 std::ostream& err) {
  try {
    if (!parse_or_throw(argc, argv, out)) return 0;
  } catch (const UsageError& e) {
    return report_usage_error(program_, e.what(), err);
  }
  return std::nullopt;
}

std::optional<int> Parser::parse(int argc, const char* const* argv) {
  return parse(argc, argv, std::cout, std::cerr);
}

int Parser::usage_error(const std::string& message) const {
  return report_usage_error(program_, message);
}

namespace {

// Parses text as a whole finite number; returns false otherwise.
bool to_finite(const std::string& text, double& v) {
  if (text.empty()) return false;
  const char* begin = text.c_str();
  char* end = nullptr;
  v = std::strtod(begin, &end);
  return end == begin + text.size() && std::isfinite(v);
}

std::string str(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

CLI::Validator number_check(std::string description, std::function<std::string(double)> rule) {
  return CLI::Validator(
      [rule = std::move(rule)](std::string& text) -> std::string {
        double v = 0;
        if (!to_finite(text, v)) return "'" + text + "' is not a finite number";
        return rule(v);
      },
      std::move(description));
}

}  // namespace

CLI::Validator finite() {
  return number_check("FINITE", [](double) { return std::string(); });
}

CLI::Validator positive() {
  return number_check("POSITIVE", [](double v) {
    return v > 0 ? std::string() : "must be > 0, not " + str(v);
  });
}

CLI::Validator non_negative() {
  return number_check("NON-NEGATIVE", [](double v) {
    return v >= 0 ? std::string() : "must be >= 0, not " + str(v);
  });
}

CLI::Validator in_range(double lo, double hi) {
  const std::string range = "[" + str(lo) + ", " + str(hi) + "]";
  return number_check("in " + range, [lo, hi, range](double v) {
    return v >= lo && v <= hi ? std::string() : str(v) + " is not in " + range;
  });
}

std::array<double, 3> parse_triple(const std::string& option, const std::string& text) {
  std::array<double, 3> v{};
  std::size_t start = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const std::size_t comma = i < 2 ? text.find(',', start) : text.size();
    if (comma == std::string::npos || !to_finite(text.substr(start, comma - start), v[i]))
      throw UsageError(option + ": expected X,Y,Z (finite numbers), got '" + text + "'");
    start = comma + 1;
  }
  return v;
}

CLI::Option* add_triple(CLI::App& app, const std::string& name, std::array<double, 3>& out,
                        const std::string& description) {
  return app
      .add_option_function<std::string>(
          name,
          [name, &out](const std::string& text) {
            try {
              out = parse_triple(name, text);
            } catch (const UsageError& e) {
              throw CLI::ValidationError(e.what());
            }
          },
          description)
      ->type_name("X,Y,Z");
}

}  // namespace neurosim::cli
