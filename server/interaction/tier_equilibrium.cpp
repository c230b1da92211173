#include "server/interaction/tier_equilibrium.hpp"

#include "server/fem/cholmod_threads.hpp"
#include "server/fem/polar_decomposition.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::interaction {

namespace {

std::string body_name(const CoupledBody& b) {
  return "body of host mesh " + std::to_string(b.host_index());
}

}  // namespace

fem::EquilibriumDefinition equilibrium_definition(const CoupledBody& body,
                                                  const fem::Material& host_material,
                                                  const std::vector<int>& host_fixed_nodes,
                                                  fem::Tier tier) {
  fem::EquilibriumDefinition d;
  d.mesh = &body.host();
  d.materials = fem::MaterialMap::uniform(host_material);
  d.tier = tier;
  d.fixed_nodes = host_fixed_nodes;
  for (const auto& tie : body.ties()) {
    d.tied.push_back({&tie.geometry(), fem::MaterialMap::uniform(tie.material()),
                      tie.fixed_nodes(), tie.tied_nodes(), tie.host_nodes(), tie.weights()});
  }
  return d;
}

TierEquilibrium::TierEquilibrium(const TierEquilibriumDefinition& def)
    : body_(def.body), tier_(def.tier), newton_(def.newton) {
  // Updates follow small force changes: the last factorized tangent is kept across updates
  // (fem::NewtonOptions::reuse_factorization, refactorized when it contracts too little), and
  // every update takes at least one step, so the equilibrium follows forces that moved by less
  // than the tolerance and the step/update fixed point is reached to round-off.
  newton_.reuse_factorization = true;
  newton_.min_iterations = 1;
  if (body_ == nullptr) throw std::invalid_argument("TierEquilibrium: no body");
  if (tier_ == fem::Tier::kLinear) {
    throw std::invalid_argument("TierEquilibrium: " + body_name(*body_) +
                                ": the LINEAR tier has no equilibrium to update");
  }
  if (body_->sliding().size() > 0) {
    throw std::invalid_argument("TierEquilibrium: " + body_name(*body_) +
                                ": SLIDING couplings are not implemented in tier " +
                                fem::tier_name(tier_));
  }
  solver_ = std::make_unique<fem::EquilibriumSolver>(
      equilibrium_definition(*body_, def.host_material, def.host_fixed_nodes, tier_));
  // Each contact slot's mesh, node and stacked dofs (a slot on an exposed tied mesh is that
  // mesh's node, CoupledBody::contact_point).
  const int num_contact = static_cast<int>(body_->contact_nodes().size());
  slot_mesh_.resize(num_contact);
  slot_vertex_.resize(num_contact);
  slot_dof_.resize(num_contact);
  for (int s = 0; s < num_contact; ++s) {
    const CoupledBody::ContactPoint cp = body_->contact_point(s);
    slot_mesh_[s] = cp.tie + 1;
    slot_vertex_[s] = cp.node;
    slot_dof_[s] = solver_->body_offset(cp.tie + 1) + 3 * cp.node;
  }
  // Relaxing meshes: their internal variables, the solver evaluating each update's step.
  std::vector<const fem::Viscoelastic*> kernels{&def.host_material.viscoelastic};
  for (const auto& tie : body_->ties()) kernels.push_back(&tie.material().viscoelastic);
  for (std::size_t b = 0; b < kernels.size(); ++b) {
    if (kernels[b]->empty()) continue;
    if (qlv_.empty()) qlv_.resize(kernels.size());
    const std::string what = body_name(*body_) + (b == 0 ? ": host" : ": tied mesh " + std::to_string(b - 1)) +
                             " material.viscoelastic";
    qlv_[b] = std::make_unique<fem::QuasiLinearViscoelastic>(solver_->body_forces(static_cast<int>(b)),
                                                             *kernels[b], what);
    solver_->set_viscous_step(static_cast<int>(b), &qlv_[b]->step());
  }
  u_.setZero(solver_->num_dofs());
  f_.setZero(solver_->num_dofs());
  trial_.setZero(solver_->num_dofs());
  u_body_.resize(body_->ties().size() + 1);
  for (std::size_t b = 0; b < u_body_.size(); ++b)
    u_body_[b].setZero(solver_->body_forces(static_cast<int>(b)).num_dofs());
  rotation_.assign(slot_dof_.size(), Eigen::Matrix3d::Identity());
  compliance_.assign(slot_dof_.size(), mesh::Vec3::Zero());
  // The linearization's compliance columns, as many slots as the budget holds.
  if (!slot_dof_.empty()) {
    columns_ = std::make_unique<ContactColumns>(*body_);
    column_capacity_ = def.column_budget_bytes / columns_->bytes_per_slot();
    if (column_capacity_ == 0) {
      columns_.reset();
    } else {
      last_load_.assign(slot_dof_.size(), 0);
      kept_.reserve(std::min(column_capacity_, slot_dof_.size()));
    }
  }
  // The first update starts at rest: its tangent is factorized now, on another thread, while
  // the simulation is set up (the first update waits for it only if it is not done; elastic
  // bodies: a relaxing one's tangent depends on its step).
  if (qlv_.empty()) solver_->start_factorization(u_);
}

TierEquilibrium::~TierEquilibrium() = default;


void TierEquilibrium::rest(TierLinearization& out) const {
  out.offset_m.assign(slot_dof_.size(), mesh::Vec3::Zero());
  out.warped_normal = body_->contact_normals();
  out.rotation.assign(slot_dof_.size(), Eigen::Matrix3d::Identity());
  out.displacement_m.assign(slot_dof_.size(), mesh::Vec3::Zero());
  out.u_m.setZero(solver_->num_dofs());
  out.load.slots.clear();
  out.load.forces_n.clear();
  out.iterations = 0;
  out.inverted_elements = 0;
  out.barrier_elements = 0;
  out.converged = true;
  out.residual_n = 0.0;
  out.count = 0;
}

void TierEquilibrium::rotations() {
  // The displacement of every mesh with a slot (the host always; an exposed tied mesh's).
  for (std::size_t b = 0; b < u_body_.size(); ++b) {
    if (b > 0 && std::find(slot_mesh_.begin(), slot_mesh_.end(), static_cast<int>(b)) == slot_mesh_.end())
      continue;
    const int nd = solver_->body_forces(static_cast<int>(b)).num_dofs();
    u_body_[b] = u_.segment(solver_->body_offset(static_cast<int>(b)), nd);
  }
  for (std::size_t s = 0; s < slot_dof_.size(); ++s) {
    const int b = slot_mesh_[s], v = slot_vertex_[s];
    const mesh::TetMesh& mesh = b == 0 ? body_->host() : body_->ties()[b - 1].geometry();
    const auto& offsets = mesh.vertex_tet_offsets();
    const auto& list = mesh.vertex_tet_list();
    const fem::ElasticForces& forces = solver_->body_forces(b);
    const Eigen::VectorXd& u_mesh = u_body_[static_cast<std::size_t>(b)];
    Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
    int n = 0;
    for (int k = offsets[v]; k < offsets[v + 1]; ++k, ++n)
      f += forces.displacement_gradient(static_cast<std::size_t>(list[k]), u_mesh);
    // Mean gradient of the tetrahedra around the node; its polar rotation (stable for flat and
    // inverted elements: sign-corrected SVD).
    rotation_[s] = n > 0 ? fem::polar_rotation(Eigen::Matrix3d::Identity() + f / n)
                         : Eigen::Matrix3d::Identity();
  }
}

void TierEquilibrium::count_elements(int& inverted, int& barrier) {
  inverted = 0;
  barrier = 0;
  for (int b = 0; b <= static_cast<int>(body_->ties().size()); ++b) {
    const fem::ElasticForces& forces = solver_->body_forces(b);
    Eigen::VectorXd& u_mesh = u_body_[static_cast<std::size_t>(b)];
    u_mesh = u_.segment(solver_->body_offset(b), forces.num_dofs());
    for (std::size_t t = 0; t < forces.num_tets(); ++t) {
      const Eigen::Matrix3d h = forces.displacement_gradient(t, u_mesh);
      if ((Eigen::Matrix3d::Identity() + h).determinant() <= 0.0) ++inverted;
      if (forces.barrier_holds(t, h)) ++barrier;
    }
  }
}

bool TierEquilibrium::relaxing_at(double time_s) const {
  if (qlv_.empty() || !timed_ || !(time_s > time_s_)) return false;
  for (const auto& q : qlv_)
    if (q && q->unrelaxed() > kRelaxedFraction) return true;
  return false;
}

const fem::QuasiLinearViscoelastic* TierEquilibrium::history(int body) const {
  if (body < 0 || body >= static_cast<int>(qlv_.size())) return nullptr;
  return qlv_[static_cast<std::size_t>(body)].get();
}

void TierEquilibrium::check_load(const TierLoad& load, const char* who) const {
  if (load.slots.size() != load.forces_n.size()) {
    throw std::invalid_argument(std::string(who) + ": " + body_name(*body_) + ": " +
                                std::to_string(load.slots.size()) + " slots, " +
                                std::to_string(load.forces_n.size()) + " forces");
  }
  for (std::size_t k = 0; k < load.slots.size(); ++k) {
    const int s = load.slots[k];
    if (s < 0 || s >= num_slots() || !load.forces_n[k].allFinite()) {
      throw std::invalid_argument(std::string(who) + ": " + body_name(*body_) +
                                  ": bad contact load at slot " + std::to_string(s));
    }
  }
}

void TierEquilibrium::update(const TierLoad& load, TierLinearization& out) {
  check_load(load, "TierEquilibrium");
  f_.setZero();
  for (std::size_t k = 0; k < load.slots.size(); ++k)
    f_.segment<3>(slot_dof_[load.slots[k]]) += load.forces_n[k];
  // Relaxing meshes: the step from the last update's time to the load's (0: replaces it).
  if (!qlv_.empty()) {
    if (!std::isfinite(load.time_s)) {
      throw std::invalid_argument("TierEquilibrium: " + body_name(*body_) + ": load time not finite");
    }
    const double dt = timed_ ? std::max(0.0, load.time_s - time_s_) : 0.0;
    for (std::size_t b = 0; b < qlv_.size(); ++b) {
      if (!qlv_[b]) continue;
      qlv_[b]->begin(dt);
      solver_->set_viscous_step(static_cast<int>(b), &qlv_[b]->step());
    }
  }
  // Newton from the previous equilibrium (one load step: the forces change little between
  // updates); a jump it cannot take goes the incremental load path from rest.
  Eigen::VectorXd& u = trial_;  // scratch for the trial (u_'s size: no allocation)
  u = u_;
  int iterations = 0;
  bool converged = true;
  double residual_n = 0.0;
  // The compliance columns of the load's slots that the linearization lacks (slots newly
  // loaded: one block solve with the host's linear factor, ~0.1-0.3 s at 5 mm) are solved on
  // another thread while Newton runs (they depend on the load's slots only); joined before the
  // linearization, also when Newton throws.
  std::thread aside;
  std::exception_ptr aside_error;
  if (!load.slots.empty() && plan_columns(load) && !missing_.empty()) {
    aside = std::thread([this, &aside_error] {
      fem::cholmod_threads_follow_omp_num_threads();  // as the worker's thread
      try {
        columns_solved_ += static_cast<std::uint64_t>(columns_->ensure(missing_, *ws_));
      } catch (...) {
        aside_error = std::current_exception();
      }
    });
  }
  auto finish_aside = [&] {
    if (!aside.joinable()) return;
    aside.join();
    if (aside_error) std::rethrow_exception(aside_error);
    kept_.insert(kept_.end(), missing_.begin(), missing_.end());
    missing_.clear();
  };
  try {
    equilibrium(u, iterations, converged, residual_n);
  } catch (...) {
    if (aside.joinable()) aside.join();
    if (!aside_error) {
      kept_.insert(kept_.end(), missing_.begin(), missing_.end());
      missing_.clear();
    }
    throw;
  }
  finish_aside();
  if (!u.allFinite()) {
    throw std::runtime_error("TierEquilibrium: " + body_name(*body_) + ": equilibrium not finite");
  }
  u_.swap(u);
  // The update's equilibrium enters the relaxing meshes' history (converged or cut short: the
  // fixed point moves in time; an update at the same time replaces it).
  for (std::size_t b = 0; b < qlv_.size(); ++b) {
    if (!qlv_[b]) continue;
    const fem::ElasticForces& forces = solver_->body_forces(static_cast<int>(b));
    u_body_[b] = u_.segment(solver_->body_offset(static_cast<int>(b)), forces.num_dofs());
    qlv_[b]->commit(u_body_[b]);
  }
  if (!qlv_.empty()) {
    time_s_ = timed_ ? std::max(time_s_, load.time_s) : load.time_s;
    timed_ = true;
  }

  linearize(load, out);
  out.u_m = u_;
  out.load = load;
  out.iterations = iterations;
  out.converged = converged;
  out.residual_n = residual_n;
  count_elements(out.inverted_elements, out.barrier_elements);
  out.count = ++count_;
}

void TierEquilibrium::equilibrium(Eigen::VectorXd& u, int& iterations, bool& converged,
                                  double& residual_n) {
  if (qlv_.empty() && f_.isZero(0.0)) {
    // No force on an elastic body (every tool has left it): its equilibrium is the rest state,
    // exactly (the body carries no other load and nothing is prescribed). Newton from the last
    // deformed equilibrium would walk back over several step-limited updates, during which the
    // step finds its rows on a surface that is no longer there (a tool released deep in the
    // tissue felt nothing until the tissue closed on its shaft).
    u.setZero();
  } else {
    try {
      const fem::NewtonIncrement inc = solver_->solve_from(f_, u, newton_);
      iterations = static_cast<int>(inc.residual_n.size()) - 1;
      converged = inc.converged;
      residual_n = inc.residual_n.empty() ? 0.0 : inc.residual_n.back();
    } catch (const std::runtime_error&) {
      try {
        const fem::EquilibriumResult r = solver_->solve(f_, newton_);
        u = r.displacement_m;
        for (const auto& inc : r.increments)
          iterations += static_cast<int>(inc.residual_n.size()) - 1;
        if (!r.increments.empty() && !r.increments.back().residual_n.empty())
          residual_n = r.increments.back().residual_n.back();
      } catch (const std::runtime_error& e) {
        throw std::runtime_error("TierEquilibrium: " + body_name(*body_) + " in tier " +
                                 fem::tier_name(tier_) + ": " + e.what());
      }
    }
  }
}

void TierEquilibrium::linearize(const TierLoad& load, TierLinearization& out) {
  check_load(load, "TierEquilibrium::linearize");
  // Rotations at the contact slots, then u0 = u* - R C R^T f* there (C: the linear coupled
  // compliance, ties included): C R^T f* from the loaded slots' columns, or one coupled solve.
  rotations();
  rotated_.resize(load.slots.size());
  for (std::size_t k = 0; k < load.slots.size(); ++k)
    rotated_[k] = rotation_[load.slots[k]].transpose() * load.forces_n[k];
  if (load.slots.empty()) {
    std::fill(compliance_.begin(), compliance_.end(), mesh::Vec3::Zero());
  } else if (!compliance_from_columns(load)) {
    body_->host_displacement(load.slots, rotated_, u_lin_, ws_.get());
    ++linearization_solves_;
    for (std::size_t s = 0; s < static_cast<std::size_t>(body_->num_host_contact()); ++s)
      compliance_[s] = u_lin_.segment<3>(3 * slot_vertex_[s]);
    // Slots on exposed tied meshes: the mesh's field for the host's and the forces on it.
    for (std::size_t s = body_->num_host_contact(); s < slot_dof_.size();) {
      const int b = slot_mesh_[s];
      const auto& tie = body_->ties()[static_cast<std::size_t>(b - 1)];
      if (!body_->tie_contact_forces(b - 1, load.slots, rotated_, f_tie_))
        f_tie_.setZero(3 * static_cast<Eigen::Index>(tie.geometry().num_vertices()));
      tie.displacement(u_lin_, f_tie_, u_tie_, ws_.get());
      for (; s < slot_dof_.size() && slot_mesh_[s] == b; ++s)
        compliance_[s] = u_tie_.segment<3>(3 * slot_vertex_[s]);
    }
  }
  const auto& normals = body_->contact_normals();
  out.offset_m.resize(slot_dof_.size());
  out.warped_normal.resize(slot_dof_.size());
  out.rotation = rotation_;
  out.displacement_m.resize(slot_dof_.size());
  for (std::size_t s = 0; s < slot_dof_.size(); ++s) {
    out.displacement_m[s] = u_.segment<3>(slot_dof_[s]);
    out.offset_m[s] = out.displacement_m[s] - rotation_[s] * compliance_[s];
    out.warped_normal[s] = rotation_[s].transpose() * normals[s];
  }
}

bool TierEquilibrium::compliance_from_columns(const TierLoad& load) {
  if (!plan_columns(load)) return false;
  if (!missing_.empty()) {
    columns_solved_ += static_cast<std::uint64_t>(columns_->ensure(missing_, *ws_));
    kept_.insert(kept_.end(), missing_.begin(), missing_.end());
    missing_.clear();
  }
  std::fill(compliance_.begin(), compliance_.end(), mesh::Vec3::Zero());
  const int n = num_slots();
  for (std::size_t k = 0; k < load.slots.size(); ++k) {
    const int j = load.slots[k];
    const mesh::Vec3 f = rotated_[k];
    for (int i = 0; i < n; ++i) compliance_[static_cast<std::size_t>(i)] += columns_->block(i, j) * f;
  }
  return true;
}

bool TierEquilibrium::plan_columns(const TierLoad& load) {
  if (!columns_) return false;
  const std::uint64_t now = ++linearizations_;
  std::size_t distinct = 0;
  missing_.clear();
  for (int s : load.slots) {
    if (last_load_[s] == now) continue;  // a slot twice in the load
    last_load_[s] = now;
    ++distinct;
    if (!columns_->has(s)) missing_.push_back(s);
  }
  if (distinct > column_capacity_) return false;
  if (kept_.size() + missing_.size() > column_capacity_) {
    // The least recently loaded kept slots make room (never one of this load: there are enough
    // others, the load's distinct slots being at most the capacity). One thread plays both
    // sides of the cache's eviction mailbox.
    const std::size_t need = kept_.size() + missing_.size() - column_capacity_;
    victims_.clear();
    for (int s : kept_)
      if (last_load_[s] != now) victims_.push_back(s);
    std::sort(victims_.begin(), victims_.end(), [this](int a, int b) {
      return last_load_[a] != last_load_[b] ? last_load_[a] < last_load_[b] : a < b;
    });
    victims_.resize(std::min(need, victims_.size()));
    for (std::size_t first = 0; first < victims_.size(); first += ContactColumns::kMaxVictims) {
      const std::size_t n = std::min<std::size_t>(ContactColumns::kMaxVictims, victims_.size() - first);
      const std::vector<int> part(victims_.begin() + static_cast<std::ptrdiff_t>(first),
                                  victims_.begin() + static_cast<std::ptrdiff_t>(first + n));
      columns_->propose_eviction(part);
      columns_->grant_eviction([this, now](int s) { return last_load_[s] == now; });
      columns_->reclaim();
    }
    kept_.erase(std::remove_if(kept_.begin(), kept_.end(), [this](int s) { return !columns_->has(s); }),
                kept_.end());
  }
  return true;
}

}  // namespace neurosim::interaction
