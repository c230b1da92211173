#include "server/interaction/contact_columns.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

ContactColumns::ContactColumns(const CoupledBody& body, bool keep_full_columns)
    : body_(&body), keep_full_(keep_full_columns) {
  const std::size_t n = body.contact_nodes().size();
  columns_.resize(n);
  sliding_columns_.resize(n);
  if (keep_full_) full_columns_.resize(n);
  ready_ = std::make_unique<std::atomic<unsigned char>[]>(n);
  for (std::size_t s = 0; s < n; ++s) ready_[s].store(0, std::memory_order_relaxed);
  bytes_per_slot_ = sizeof(double) * 3 * (3 * n + static_cast<std::size_t>(body.sliding().size()));
  if (keep_full_) bytes_per_slot_ += sizeof(double) * 9 * body.host().num_vertices();
}

bool ContactColumns::propose_eviction(const std::vector<int>& victims) {
  if (mailbox_.load(std::memory_order_acquire) != kIdle) return false;
  int n = 0;
  for (int s : victims) {
    if (s < 0 || s >= num_slots()) {
      throw std::invalid_argument("ContactColumns::propose_eviction: contact slot " +
                                  std::to_string(s) + " out of range");
    }
    if (n == kMaxVictims) break;
    victims_[n++] = s;
  }
  if (n == 0) return true;
  num_victims_ = n;
  mailbox_.store(kProposed, std::memory_order_release);
  return true;
}

int ContactColumns::reclaim() {
  if (mailbox_.load(std::memory_order_acquire) != kGranted) return 0;
  int freed = 0;
  for (int k = 0; k < num_victims_; ++k) {
    const int s = victims_[k];
    // Published again by this writer after the grant (fresh storage, ready): keep it.
    if (!granted_[k] || has(s)) continue;
    columns_[s] = Blocks();
    sliding_columns_[s] = Columns();
    if (keep_full_) full_columns_[s] = Columns();
    ++freed;
  }
  evicted_.fetch_add(static_cast<std::uint64_t>(freed), std::memory_order_acq_rel);
  num_victims_ = 0;
  mailbox_.store(kIdle, std::memory_order_release);
  return freed;
}

int ContactColumns::ensure(const std::vector<int>& slots) { return ensure(slots, *ws_); }

int ContactColumns::ensure(const std::vector<int>& slots, fem::SolveWorkspace& ws) {
  std::vector<int> missing;
  for (int s : slots) {
    if (s < 0 || s >= num_slots()) {
      throw std::invalid_argument("ContactColumns::ensure: contact slot " + std::to_string(s) +
                                  " out of range");
    }
    if (!has(s)) missing.push_back(s);
  }
  std::sort(missing.begin(), missing.end());
  missing.erase(std::unique(missing.begin(), missing.end()), missing.end());
  if (missing.empty()) return 0;
  const auto& solver = body_->host_solver();
  const auto& contact = body_->contact_nodes();
  const int nf = solver.num_free_dofs();
  const int s3 = 3 * static_cast<int>(contact.size());
  const int n3 = 3 * static_cast<int>(body_->host().num_vertices());
  const SlidingOperator& sliding = body_->sliding();
  const std::size_t chunk = static_cast<std::size_t>(CoupledBody::kBlockColumns / 3);
  const bool slides = body_->has_exposed_slide() && sliding.size() > 0;
  Eigen::MatrixXd x, rows, slide_rows;
  for (std::size_t first = 0; first < missing.size(); first += chunk) {
    const std::size_t n = std::min(chunk, missing.size() - first);
    const std::vector<int> part(missing.begin() + static_cast<std::ptrdiff_t>(first),
                                missing.begin() + static_cast<std::ptrdiff_t>(first + n));
    body_->solve_contact_columns(part, x, &ws, &iterations_);
    // Rows at every contact slot (an exposed tie's from its mesh's displacement, an exposed
    // sliding mesh's from its own compliance, with its part of the sliding rows).
    body_->contact_rows(part, x, rows, &ws, slides ? &slide_rows : nullptr);
    for (std::size_t j = 0; j < n; ++j) {
      const int c = 3 * static_cast<int>(j);
      const int slot = part[j];
      Blocks col(s3, 3);
      col = rows.middleCols(c, 3);
      columns_[slot] = std::move(col);
      if (sliding.size() > 0) sliding_columns_[slot] = sliding.apply(x.middleCols(c, 3));
      // A slot on an exposed sliding mesh: J_A x is zero, its rows are J_B L_B[:, node].
      if (slides && body_->contact_point(slot).slide >= 0)
        sliding_columns_[slot] += slide_rows.middleCols(c, 3);
      if (keep_full_) {
        Columns full = Columns::Zero(n3, 3);
        for (int r = 0; r < nf; ++r) full.row(solver.free_dofs()[r]) = x.block<1, 3>(r, c);
        full_columns_[slot] = std::move(full);
      }
      // Publish: the storage above is complete before a reader can see the slot ready.
      ready_[slot].store(1, std::memory_order_release);
      count_.fetch_add(1, std::memory_order_acq_rel);
    }
  }
  return static_cast<int>(missing.size());
}

bool ContactColumns::full_field(const std::vector<int>& slots,
                                const std::vector<mesh::Vec3>& forces_n,
                                Eigen::VectorXd& u_host_m) const {
  if (!keep_full_) return false;
  for (int s : slots)
    if (s < 0 || s >= num_slots() || !has(s)) return false;
  u_host_m.setZero(3 * static_cast<int>(body_->host().num_vertices()));
  for (std::size_t k = 0; k < slots.size(); ++k)
    u_host_m.noalias() += full_columns_[slots[k]] * forces_n[k];
  return true;
}

}  // namespace neurosim::interaction
