#include "common/cli.hpp"

#include <CLI/CLI.hpp>

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
    : program_(std::move(program)),
      app_(std::make_unique<CLI::App>(std::move(description), program_)) {
  app_->set_version_flag("--version", program_ + " " + version(), "Print the version and exit");
  app_->option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
}

Parser::~Parser() = default;

Option* Parser::wrap(CLI::Option* option) {
  options_.push_back(std::make_unique<Option>(option));
  return options_.back().get();
}

namespace {

// A value callback of a program: its UsageError becomes CLI11's ValidationError (same message).
template <typename F>
auto rethrow_as_validation_error(F f) {
  return [f = std::move(f)](const auto& value) {
    try {
      f(value);
    } catch (const UsageError& e) {
      throw CLI::ValidationError(e.what());
    }
  };
}

}  // namespace

// The value types the programs use (CLI11 instantiated here only).
Option* Parser::add_option(const std::string& name, std::string& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, double& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, int& target, const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, unsigned& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, std::vector<std::string>& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, std::vector<double>& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}
Option* Parser::add_option(const std::string& name, std::vector<int>& target,
                           const std::string& description) {
  return wrap(app_->add_option(name, target, description));
}

template <typename T>
Option* Parser::add_option_function(const std::string& name, std::function<void(const T&)> f,
                                    const std::string& description) {
  return wrap(
      app_->add_option_function<T>(name, rethrow_as_validation_error(std::move(f)), description));
}
template Option* Parser::add_option_function<std::string>(const std::string&,
                                                          std::function<void(const std::string&)>,
                                                          const std::string&);
template Option* Parser::add_option_function<double>(const std::string&,
                                                     std::function<void(const double&)>,
                                                     const std::string&);
template Option* Parser::add_option_function<int>(const std::string&,
                                                  std::function<void(const int&)>,
                                                  const std::string&);

Option* Parser::add_flag(const std::string& name, bool& target, const std::string& description) {
  return wrap(app_->add_flag(name, target, description));
}

Option* Parser::add_flag_function(const std::string& name, std::function<void(std::int64_t)> f,
                                  const std::string& description) {
  return wrap(app_->add_flag_function(name, std::move(f), description));
}

void Parser::footer(const std::string& text) { app_->footer(text); }

std::size_t Parser::count(const std::string& name) const { return app_->count(name); }

Option* Option::required() {
  option_->required();
  return this;
}

Option* Option::check(const Check& check) {
  option_->check(check.validator());
  return this;
}

Option* Option::capture_default_str() {
  option_->capture_default_str();
  return this;
}

Option* Option::excludes(Option* other) {
  option_->excludes(other->option_);
  return this;
}

Option* Option::needs(Option* other) {
  option_->needs(other->option_);
  return this;
}

Option* Option::expected(int values) {
  option_->expected(values);
  return this;
}

Option* Option::take_all() {
  option_->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  return this;
}

Option* Option::type_name(const std::string& name) {
  option_->type_name(name);
  return this;
}

std::size_t Option::count() const { return option_->count(); }

bool Parser::parse_or_throw(int argc, const char* const* argv, std::ostream& out) {
  try {
    app_->parse(argc, argv);
    for (const auto& rule : checks_) rule();
  } catch (const CLI::CallForHelp&) {
    out << app_->help();
    return false;
  } catch (const CLI::CallForAllHelp&) {
    out << app_->help("", CLI::AppFormatMode::All);
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

Check number_check(const std::string& description, std::function<std::string(double)> rule) {
  return Check(
      [rule = std::move(rule)](std::string& text) -> std::string {
        double v = 0;
        if (!to_finite(text, v)) return "'" + text + "' is not a finite number";
        return rule(v);
      },
      description);
}

Check check_of(CLI::Validator validator) {
  return Check(std::make_shared<const CLI::Validator>(std::move(validator)));
}

}  // namespace

Check finite() {
  return number_check("FINITE", [](double) { return std::string(); });
}

Check positive() {
  return number_check(
      "POSITIVE", [](double v) { return v > 0 ? std::string() : "must be > 0, not " + str(v); });
}

Check non_negative() {
  return number_check("NON-NEGATIVE", [](double v) {
    return v >= 0 ? std::string() : "must be >= 0, not " + str(v);
  });
}

Check in_range(double lo, double hi) {
  const std::string range = "[" + str(lo) + ", " + str(hi) + "]";
  return number_check("in " + range, [lo, hi, range](double v) {
    return v >= lo && v <= hi ? std::string() : str(v) + " is not in " + range;
  });
}

Check range(int lo, int hi) { return check_of(CLI::Range(lo, hi)); }
Check range(double lo, double hi) { return check_of(CLI::Range(lo, hi)); }
Check positive_number() { return check_of(CLI::PositiveNumber); }
Check non_negative_number() { return check_of(CLI::NonNegativeNumber); }
Check one_of(const std::vector<std::string>& values) { return check_of(CLI::IsMember(values)); }
Check one_of_ignore_case(const std::vector<std::string>& values) {
  return check_of(CLI::IsMember(values, CLI::ignore_case));
}

Check::Check(std::function<std::string(std::string&)> rule, const std::string& description)
    : validator_(std::make_shared<const CLI::Validator>(std::move(rule), description)) {}

Check::Check(std::shared_ptr<const CLI::Validator> validator) : validator_(std::move(validator)) {}

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

Option* Parser::add_triple(const std::string& name, std::array<double, 3>& out,
                           const std::string& description) {
  return add_option_function<std::string>(
             name, [name, &out](const std::string& text) { out = parse_triple(name, text); },
             description)
      ->type_name("X,Y,Z");
}

}  // namespace neurosim::cli
