#include "server/service/csv_fields.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace neurosim::service {

CsvFields::CsvFields(const std::filesystem::path& file, const std::string& what)
    : file_(file), in_(file) {
  if (!in_) throw std::runtime_error(file.string() + ": cannot open the " + what);
}

std::size_t CsvFields::header(std::initializer_list<std::string_view> accepted) {
  if (!next()) throw std::runtime_error(file_.string() + ": no header line (empty table)");
  for (const std::string_view h : accepted)
    if (line_ == h) return static_cast<std::size_t>(std::count(h.begin(), h.end(), ',')) + 1;
  fail("expected the header '" + std::string(accepted.size() ? *accepted.begin() : "") +
       "', got '" + line_ + "'");
}

bool CsvFields::next() {
  fields_.clear();
  while (std::getline(in_, line_)) {
    ++line_number_;
    if (!line_.empty() && line_.back() == '\r') line_.pop_back();
    if (!line_.empty() && line_[0] != '#') return true;
  }
  line_.clear();
  return false;
}

std::string CsvFields::where() const { return file_.string() + ":" + std::to_string(line_number_); }

void CsvFields::fail(const std::string& message) const {
  throw std::runtime_error(where() + ": " + message);
}

void CsvFields::split(std::size_t expected) {
  fields_.clear();
  std::stringstream ss(line_);
  std::string item;
  while (std::getline(ss, item, ',')) fields_.push_back(item);
  if (!line_.empty() && line_.back() == ',') fields_.emplace_back();
  if (fields_.size() != expected)
    fail(std::to_string(fields_.size()) + " fields, expected " + std::to_string(expected));
}

double CsvFields::number(std::size_t i, const std::string& name) const {
  const std::string& t = text(i);
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(t, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != t.size() || !std::isfinite(v) || v < 0.0)
    throw std::runtime_error(where() + " " + name + ": '" + t + "' is not a finite number >= 0");
  return v;
}

std::size_t CsvFields::count(std::size_t i, const std::string& name) const {
  const double v = number(i, name);
  // Above 2^53 a double no longer holds every whole number (and the cast could overflow).
  if (v != std::floor(v) || v < 1.0 || v > 9007199254740992.0)
    throw std::runtime_error(where() + " " + name + ": '" + text(i) +
                             "' is not a count (a whole number from 1 to 2^53)");
  return static_cast<std::size_t>(v);
}

}  // namespace neurosim::service
