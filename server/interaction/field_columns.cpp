#include "server/interaction/field_columns.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

FieldColumns::FieldColumns(const CoupledBody& body, std::size_t capacity_slots)
    : body_(&body), capacity_(capacity_slots) {
  if (capacity_ == 0) throw std::invalid_argument("FieldColumns: capacity must be at least one node");
  const std::size_t n = body.contact_nodes().size();
  full_.resize(n);
  last_use_.assign(n, 0);
}

std::size_t FieldColumns::bytes_per_slot(const CoupledBody& body) {
  return sizeof(double) * 9 * body.host().num_vertices();
}

bool FieldColumns::field(const std::vector<int>& slots, const std::vector<Vec3>& forces_n,
                         Eigen::VectorXd& u_host_m, fem::SolveWorkspace& ws) {
  if (slots.size() != forces_n.size()) {
    throw std::invalid_argument("FieldColumns::field: " + std::to_string(slots.size()) +
                                " slots, " + std::to_string(forces_n.size()) + " forces");
  }
  const int n_slots = static_cast<int>(full_.size());
  missing_.clear();
  for (int s : slots) {
    if (s < 0 || s >= n_slots) {
      throw std::invalid_argument("FieldColumns::field: contact slot " + std::to_string(s) +
                                  " out of range");
    }
    if (full_[s].size() == 0) missing_.push_back(s);
  }
  std::sort(missing_.begin(), missing_.end());
  missing_.erase(std::unique(missing_.begin(), missing_.end()), missing_.end());
  if (slots.size() > capacity_) {  // more distinct slots than room: the caller solves
    std::vector<int> all(slots);
    std::sort(all.begin(), all.end());
    if (static_cast<std::size_t>(std::unique(all.begin(), all.end()) - all.begin()) > capacity_)
      return false;
  }
  ++fields_;
  for (int s : slots) last_use_[s] = fields_;
  if (!missing_.empty()) {
    // Room first: evict the least recently used slots not in this field.
    if (kept_ + missing_.size() > capacity_) {
      std::sort(kept_slots_.begin(), kept_slots_.end(),
                [&](int a, int b) { return last_use_[a] != last_use_[b] ? last_use_[a] < last_use_[b] : a < b; });
      std::size_t k = 0;
      while (kept_ + missing_.size() > capacity_ && k < kept_slots_.size()) {
        const int s = kept_slots_[k++];
        if (last_use_[s] == fields_) continue;  // this field's
        full_[s] = Columns();
        --kept_;
        ++evicted_;
      }
      kept_slots_.erase(std::remove_if(kept_slots_.begin(), kept_slots_.end(),
                                       [&](int s) { return full_[s].size() == 0; }),
                        kept_slots_.end());
    }
    const auto& solver = body_->host_solver();
    const int nf = solver.num_free_dofs();
    const int n3 = 3 * static_cast<int>(body_->host().num_vertices());
    const std::size_t chunk = static_cast<std::size_t>(CoupledBody::kBlockColumns / 3);
    for (std::size_t first = 0; first < missing_.size(); first += chunk) {
      const std::size_t n = std::min(chunk, missing_.size() - first);
      const std::vector<int> part(missing_.begin() + static_cast<std::ptrdiff_t>(first),
                                  missing_.begin() + static_cast<std::ptrdiff_t>(first + n));
      body_->solve_contact_columns(part, x_, &ws);
      for (std::size_t j = 0; j < n; ++j) {
        const int c = 3 * static_cast<int>(j);
        Columns full = Columns::Zero(n3, 3);
        for (int r = 0; r < nf; ++r) full.row(solver.free_dofs()[r]) = x_.block<1, 3>(r, c);
        full_[part[j]] = std::move(full);
        kept_slots_.push_back(part[j]);
        ++kept_;
        ++solved_;
      }
    }
  }
  u_host_m.setZero(3 * static_cast<Eigen::Index>(body_->host().num_vertices()));
  for (std::size_t k = 0; k < slots.size(); ++k) u_host_m.noalias() += full_[slots[k]] * forces_n[k];
  return true;
}

}  // namespace neurosim::interaction
