#include "server/fem/elastic_forces.hpp"

#include "server/fem/tet_element.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

namespace {

// Largest |principal Green-Lagrange strain|, E = (H + H^T + H^T H) / 2.
double green_strain_magnitude(const Eigen::Matrix3d& h) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(
      0.5 * (h + h.transpose() + h.transpose() * h), Eigen::EigenvaluesOnly);
  const Eigen::Vector3d e = eig.eigenvalues();
  return std::max(std::abs(e(0)), std::abs(e(2)));
}

void note(ElasticForcesReport* report, const Eigen::Matrix3d& h, const LawEvaluation& eval) {
  if (!report) return;
  if (eval.clamped) ++report->clamped_elements;
  if ((Eigen::Matrix3d::Identity() + h).determinant() <= 0.0) ++report->inverted_elements;
  report->max_strain = std::max(report->max_strain, green_strain_magnitude(h));
}

}  // namespace

ElasticForces::ElasticForces(const mesh::TetMesh& mesh, const MaterialMap& materials, Tier tier)
    : tier_(tier),
      element_(materials.element()),
      num_nodes_(static_cast<int>(mesh.num_vertices())),
      tets_(mesh.tets()),
      assembler_(mesh, materials.element()) {
  materials.validate(mesh.num_tets());
  if (element_ != Element::kLinearTet) nodal_ = std::make_unique<NodalPressure>(mesh, materials);
  if (element_ == Element::kSmoothedTet) {
    smoothed_ = std::make_unique<SmoothedStrain>(mesh, materials, assembler_.pattern());
  }
  for (const Material& m : materials.materials) {
    const LawConstants c = LawConstants::of(m);
    laws_.push_back(element_ == Element::kLinearTet ? c : c.deviatoric());
    if (smoothed_ && tier_ == Tier::kNonlinear) barriers_.push_back(ElementBarrier::of(c));
  }
  const auto& x = mesh.vertices();
  gradients_.resize(tets_.size());
  volume_m3_.resize(tets_.size());
  law_index_.resize(tets_.size());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const auto& t = tets_[e];
    const TetGeometry g =
        tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e));
    gradients_[e] = g.gradients;
    volume_m3_[e] = g.volume_m3;
    total_volume_m3_ += g.volume_m3;
    law_index_[e] = materials.tet_material.empty() ? 0 : materials.tet_material[e];
  }
}

void ElasticForces::check_size(const Eigen::VectorXd& u_m, const char* what) const {
  if (u_m.size() != num_dofs()) {
    throw std::invalid_argument(std::string("ElasticForces::") + what + ": displacement has " +
                                std::to_string(u_m.size()) + " entries, expected " +
                                std::to_string(num_dofs()));
  }
}

Eigen::Matrix3d ElasticForces::displacement_gradient(std::size_t tet,
                                                     const Eigen::VectorXd& u_m) const {
  Eigen::Matrix3d f = Eigen::Matrix3d::Zero();
  const auto& t = tets_[tet];
  for (int a = 0; a < 4; ++a) {
    f.noalias() += u_m.segment<3>(3 * t[a]) * gradients_[tet].row(a);
  }
  return f;
}

Eigen::Matrix3d ElasticForces::elastic_second_piola(std::size_t tet,
                                                    const Eigen::VectorXd& u_m) const {
  const Eigen::Matrix3d h = displacement_gradient(tet, u_m);
  const Eigen::Matrix3d p = first_piola(tier_, laws_[law_index_[tet]], h);
  const Eigen::Matrix3d s = (Eigen::Matrix3d::Identity() + h).inverse() * p;
  return 0.5 * (s + s.transpose());
}

void ElasticForces::nodal_state(const Eigen::VectorXd& u_m, Workspace& s) const {
  s.element.resize(tets_.size());
  s.theta.resize(tets_.size());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    s.element[e] = volumetric_strain(tier_, displacement_gradient(e, u_m));
    s.theta[e] = s.element[e].theta;
  }
  nodal_->nodal_strain(s.theta, s.nodal_theta);
  nodal_->element_pressure(s.nodal_theta, s.pressure_pa);
}

double ElasticForces::energy(const Eigen::VectorXd& u_m, ElasticForcesReport* report,
                             Workspace* workspace) const {
  check_size(u_m, "energy");
  Workspace local;
  Workspace& ws = workspace ? *workspace : local;
  if (nodal_) nodal_state(u_m, ws);
  double e_total = 0.0;
  LawEvaluation eval;
  if (smoothed_) {
    // smoothed-tet: the deviatoric energy over the smoothing cells, the elements only report.
    for (int c = 0; c < smoothed_->num_cells(); ++c) {
      eval = LawEvaluation{};
      e_total += smoothed_->volume_m3(c) *
                 energy_density(tier_, laws_[smoothed_->material(c)],
                                smoothed_->displacement_gradient(c, u_m), &eval);
      if (report && eval.clamped) ++report->clamped_elements;
    }
    // Per tetrahedron: the element barrier's energy (NONLINEAR) and the report.
    const bool per_tet = report || !barriers_.empty();
    for (std::size_t e = 0; per_tet && e < tets_.size(); ++e) {
      const Eigen::Matrix3d h = displacement_gradient(e, u_m);
      if (!barriers_.empty()) {
        const ElementBarrier& b = barriers_[law_index_[e]];
        if (b.active(h)) {
          e_total += volume_m3_[e] * b.energy_density(h);
          if (report) ++report->barrier_elements;
        }
      }
      note(report, h, {});
    }
  } else {
    const ViscousStep* v = workspace ? workspace->viscous : nullptr;
    for (std::size_t e = 0; e < tets_.size(); ++e) {
      const Eigen::Matrix3d f = displacement_gradient(e, u_m);
      eval = LawEvaluation{};
      // anp-tet: the element's law is the deviatoric part, the nodes hold the volumetric one.
      const double w = energy_density(tier_, laws_[law_index_[e]], f, &eval);
      // A relaxing step: gamma W + S_h : E with E = (H + H^T + H^T H) / 2.
      e_total += volume_m3_[e] *
                 (v ? v->gamma * w + 0.5 * v->history_stress_pa[e].cwiseProduct(
                                               f + f.transpose() + f.transpose() * f).sum()
                    : w);
      note(report, f, eval);
    }
  }
  if (nodal_) e_total += nodal_->energy(ws.nodal_theta);
  return e_total;
}

void ElasticForces::internal_force(const Eigen::VectorXd& u_m, Eigen::VectorXd& f_n,
                                   ElasticForcesReport* report, Workspace* workspace) const {
  check_size(u_m, "internal_force");
  Workspace local;
  Workspace& ws = workspace ? *workspace : local;
  if (nodal_) nodal_state(u_m, ws);
  f_n.setZero(num_dofs());
  if (smoothed_) {
    for (int c = 0; c < smoothed_->num_cells(); ++c) {
      LawEvaluation eval;
      const Eigen::Matrix3d p = first_piola(tier_, laws_[smoothed_->material(c)],
                                            smoothed_->displacement_gradient(c, u_m), &eval);
      if (report && eval.clamped) ++report->clamped_elements;
      smoothed_->add_force(c, p, f_n);
    }
  }
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    LawEvaluation eval;
    Eigen::Matrix3d p;
    if (smoothed_) {
      // smoothed-tet: the element carries only its average nodal pressure (its gradient only
      // for the report: nodal_state took what the pressure needs).
      p = ws.pressure_pa[e] * ws.element[e].gradient;
      if (report || !barriers_.empty()) {
        const Eigen::Matrix3d h = displacement_gradient(e, u_m);
        if (!barriers_.empty()) {
          const ElementBarrier& b = barriers_[law_index_[e]];
          if (b.active(h)) {
            p += b.stress(h);
            if (report) ++report->barrier_elements;
          }
        }
        note(report, h, eval);
      }
      const double v = volume_m3_[e];
      const auto& t = tets_[e];
      for (int a = 0; a < 4; ++a)
        f_n.segment<3>(3 * t[a]).noalias() += v * (p * gradients_[e].row(a).transpose());
      continue;
    }
    const Eigen::Matrix3d f = displacement_gradient(e, u_m);
    p = first_piola(tier_, laws_[law_index_[e]], f, &eval);
    // anp-tet: the deviatoric stress plus the element's average nodal pressure.
    if (nodal_) p += ws.pressure_pa[e] * ws.element[e].gradient;
    // A relaxing step (linear-tet): gamma P + F S_h.
    if (ws.viscous) {
      p = ws.viscous->gamma * p +
          (Eigen::Matrix3d::Identity() + f) * ws.viscous->history_stress_pa[e];
    }
    note(report, f, eval);
    const auto& t = tets_[e];
    for (int a = 0; a < 4; ++a) {
      f_n.segment<3>(3 * t[a]).noalias() += volume_m3_[e] * (p * gradients_[e].row(a).transpose());
    }
  }
}

void ElasticForces::tangent(const Eigen::VectorXd& u_m, bool project_psd, SparseMatrix& k,
                            ElasticForcesReport* report, Workspace* workspace) const {
  check_size(u_m, "tangent");
  const SparseMatrix& pattern = assembler_.pattern();
  if (k.rows() != pattern.rows() || k.nonZeros() != pattern.nonZeros() || !k.isCompressed()) {
    k = pattern;
  }
  double* values = k.valuePtr();
  std::fill_n(values, k.nonZeros(), 0.0);
  Workspace local;
  Workspace& ws = workspace ? *workspace : local;
  if (nodal_) {
    nodal_state(u_m, ws);
    ws.w.resize(tets_.size());  // d theta_e / d u_b = G_e grad N_b
  }
  StressTangent c, d2theta;
  if (smoothed_) {
    ws.cell.resize(static_cast<std::size_t>(smoothed_->max_cell_nodes()));
    for (int cell = 0; cell < smoothed_->num_cells(); ++cell) {
      LawEvaluation eval;
      stress_tangent(tier_, laws_[smoothed_->material(cell)],
                     smoothed_->displacement_gradient(cell, u_m), project_psd, c, &eval);
      if (report && eval.clamped) ++report->clamped_elements;
      smoothed_->add_tangent(cell, c, ws.cell, k);
    }
  }
  Eigen::Matrix<double, 9, 12> b;
  Eigen::Matrix<double, 12, 12> k_e;
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const Eigen::Matrix3d f = displacement_gradient(e, u_m);
    LawEvaluation eval;
    const LawConstants& law = laws_[law_index_[e]];
    if (!nodal_ && ws.viscous) {
      // A relaxing step: gamma dP/dF plus S_h's geometric term d(F S_h)_ij / dF_kl =
      // delta_ik S_h(l, j), projected as a whole.
      stress_tangent(tier_, law, f, false, c, &eval);
      c *= ws.viscous->gamma;
      const Eigen::Matrix3d& sh = ws.viscous->history_stress_pa[e];
      for (int j = 0; j < 3; ++j)
        for (int l = 0; l < 3; ++l)
          for (int i = 0; i < 3; ++i) c(i + 3 * j, i + 3 * l) += sh(l, j);
      if (project_psd) project_to_psd(c);
    } else if (!nodal_) {
      stress_tangent(tier_, law, f, project_psd, c, &eval);
    } else {
      const VolumetricStrain& v = ws.element[e];
      ws.w[e] = gradients_[e] * v.gradient.transpose();
      if (smoothed_) {
        // smoothed-tet: the element's pbar d2theta only (none in LINEAR); the nodal K q q^T
        // terms follow below.
        note(report, f, eval);
        if (tier_ == Tier::kLinear) continue;
        volumetric_hessian(tier_, f, d2theta);
        c = ws.pressure_pa[e] * d2theta;
        if (!barriers_.empty()) {
          const ElementBarrier& bar = barriers_[law_index_[e]];
          if (bar.active(f)) {
            bar.add_tangent(f, c);
            if (report) ++report->barrier_elements;
          }
        }
        if (project_psd) project_to_psd(c);
      } else {
        // anp-tet: deviatoric tangent plus the nodal pressure's pbar d2theta, projected as a
        // whole; the nodal K q q^T terms follow below.
        stress_tangent(tier_, law, f, false, c, &eval);
        if (tier_ != Tier::kLinear) {
          volumetric_hessian(tier_, f, d2theta);
          c += ws.pressure_pa[e] * d2theta;
        }
        if (project_psd) project_to_psd(c);
      }
    }
    if (!smoothed_) note(report, f, eval);
    // vec(dF) = B du: dF(i, l) = sum_b du_b,i g_b,l at vec index i + 3 l.
    b.setZero();
    for (int a = 0; a < 4; ++a) {
      for (int l = 0; l < 3; ++l) {
        for (int i = 0; i < 3; ++i) {
          b(i + 3 * l, 3 * a + i) = gradients_[e](a, l);
        }
      }
    }
    k_e.noalias() = volume_m3_[e] * (b.transpose() * c * b);
    assembler_.add_element(e, k_e, values);
  }
  if (nodal_) nodal_->add_nodal_stiffness(ws.w, k, ws.q);
}

}  // namespace neurosim::fem
