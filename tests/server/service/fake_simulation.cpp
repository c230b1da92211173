#include "tests/server/service/fake_simulation.hpp"

#include <cstdio>
#include <stdexcept>
#include <type_traits>

namespace neurosim::service::testing {

namespace {

// n^3 cells, 6 tetrahedra each (Kuhn split along the cell diagonal), all positively oriented.
mesh::TetMesh box_mesh(const mesh::Vec3& lo, const mesh::Vec3& hi, int n) {
  std::vector<mesh::Vec3> v;
  auto id = [n](int i, int j, int k) { return (k * (n + 1) + j) * (n + 1) + i; };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i)
        v.push_back(lo + (hi - lo).cwiseProduct(mesh::Vec3(i, j, k) / n));
  std::vector<mesh::Tet> tets;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const auto& p : perms) {
          int c[3] = {i, j, k};
          mesh::Tet t;
          t[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[static_cast<std::size_t>(s + 1)] = id(c[0], c[1], c[2]);
          }
          if (mesh::signed_volume(v[static_cast<std::size_t>(t[0])], v[static_cast<std::size_t>(t[1])],
                                  v[static_cast<std::size_t>(t[2])], v[static_cast<std::size_t>(t[3])]) < 0)
            std::swap(t[2], t[3]);
          tets.push_back(t);
        }
  mesh::BuildOptions o;
  o.source = "fake box";
  return mesh::TetMesh::build(std::move(v), std::move(tets), o);
}

}  // namespace

FakeSimulation::FakeSimulation(const scene::Model& model, std::optional<scene::Tier> runs)
    : tier_(runs.value_or(model.effects.tier)) {
  for (const auto& m : model.meshes) {
    mesh::Vec3 lo, hi;
    m.mesh.bounds(lo, hi);
    ids_.push_back(m.id);
    meshes_.push_back(box_mesh(lo, hi, 3));
  }
  if (meshes_.empty()) throw std::runtime_error("FakeSimulation: the scene has no mesh");
  mesh::Vec3 lo, hi;
  meshes_[0].bounds(lo, hi);
  x_min_ = lo.x();
  x_max_ = hi.x();
  y_lo_ = lo.y();
  y_hi_ = hi.y();
  z_lo_ = lo.z();
  z_hi_ = hi.z();
  if (!model.tools.empty() && model.tools[0].tip_radius_m > 0)
    tip_radius_m_ = model.tools[0].tip_radius_m;
  depth_.reserve(64);
}

FakeSimulation::~FakeSimulation() {
  // Read by the effects test from the fake server's log.
  std::fprintf(stderr, "fake simulation: %ld displacements calls\n", displacement_calls_.load());
}

void FakeSimulation::step(const std::vector<interaction::ToolPose>& poses,
                          std::vector<interaction::ToolContact>& contacts,
                          interaction::StepStats& stats) {
  if (contacts.size() != poses.size()) throw std::invalid_argument("FakeSimulation: sizes differ");
  depth_.resize(poses.size());
  double sum = 0, deepest = 0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const auto& t = poses[k].tip_m;
    const bool over = t.y() >= y_lo_ && t.y() <= y_hi_ && t.z() >= z_lo_ && t.z() <= z_hi_;
    const double d = (x_max_ + tip_radius_m_) - t.x();
    depth_[k] = over && d > 0 ? d : 0.0;
    sum += depth_[k];
    deepest = std::max(deepest, depth_[k]);
  }
  for (std::size_t k = 0; k < poses.size(); ++k) {
    auto& c = contacts[k];
    c.in_contact = depth_[k] > 0;
    const double scale = 1.0 + kCross * (sum - depth_[k]) / tip_radius_m_;
    c.force_n = interaction::Vec3(kStiffness * depth_[k] * scale, 0, 0);
    c.stiffness_n_per_m.setZero();
    if (c.in_contact) c.stiffness_n_per_m(0, 0) = -kStiffness * scale;
    c.normal = c.in_contact ? interaction::Vec3(interaction::Vec3::UnitX()) : interaction::Vec3(interaction::Vec3::Zero());
    c.reference_tip_m = poses[k].tip_m;
    c.validity_radius_m = tip_radius_m_;
    c.mesh = c.in_contact ? 0 : -1;
    c.converged = true;
    c.iterations = 1;
  }
  last_max_depth_m_ = deepest;
  stepped_.store(true, std::memory_order_release);
  stats.solve_us = 0;
  stats.contact_rows = 0;
  stats.converged = true;
}

void FakeSimulation::displacements(int m, Eigen::VectorXd& u_m) const {
  ++displacement_calls_;
  const auto& me = mesh(m);
  u_m.setZero(3 * static_cast<Eigen::Index>(me.num_vertices()));
  if (m != 0) return;
  for (std::size_t v = 0; v < me.num_vertices(); ++v)
    u_m[3 * static_cast<Eigen::Index>(v)] =
        -last_max_depth_m_ * (me.vertices()[v].x() - x_min_) / (x_max_ - x_min_);
}

std::unique_ptr<interaction::Simulation> make_fake(const scene::Model& model) {
  return std::make_unique<FakeSimulation>(model);
}

}  // namespace neurosim::service::testing
