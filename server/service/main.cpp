// neurosim-server: the simulation service over DDS (issue 5). See server.hpp for the design.
#include "server/service/server.hpp"

#include <stdexcept>

#if NEUROSIM_HAVE_INTERACTION
#include "server/interaction/coupled_body.hpp"

#include <vector>

namespace {

namespace ia = neurosim::interaction;

// Full-field solves for Deformation on the service's worker thread, from a copy of the last
// step's contact forces (Simulation::last_contact_forces) through the body's const solves
// (CoupledBody::host_displacement / embedded_displacement; the factor's solves are serialized
// by StaticSolver's mutex). One host solve per body and frame serves the host and its ties.
class CoupledFieldWorker : public neurosim::service::FieldWorker {
 public:
  explicit CoupledFieldWorker(const ia::Simulation& sim) {
    for (int m = 0; m < sim.num_meshes(); ++m) {
      const ia::CoupledBody* b = sim.body_of(m);
      int body = -1, tie = -1;
      if (b != nullptr) {
        for (std::size_t k = 0; k < bodies_.size(); ++k)
          if (bodies_[k].body == b) body = static_cast<int>(k);
        if (body < 0) {
          bodies_.push_back(Body{b, m, {}, {}, {}, 0});
          body = static_cast<int>(bodies_.size()) - 1;
        }
        if (b->host_index() != m) {
          for (std::size_t k = 0; k < b->ties().size(); ++k)
            if (b->ties()[k].mesh == m) tie = static_cast<int>(k);
          if (tie < 0)
            throw std::runtime_error("field worker: mesh '" + sim.mesh_id(m) +
                                     "' is neither host nor tie of its body");
        }
      }
      mesh_body_.push_back(body);
      mesh_tie_.push_back(tie);
    }
  }
  void snapshot(const ia::Simulation& sim) override {
    ++job_;
    for (auto& b : bodies_) sim.last_contact_forces(b.any_mesh, b.slots, b.forces_n);
  }
  void displacements(const ia::Simulation& sim, int m, Eigen::VectorXd& u_m) override {
    const int body = mesh_body_.at(static_cast<std::size_t>(m));
    if (body < 0) {  // inert mesh
      u_m.setZero(3 * static_cast<Eigen::Index>(sim.mesh(m).num_vertices()));
      return;
    }
    Body& b = bodies_[static_cast<std::size_t>(body)];
    if (b.host_job != job_) {
      b.body->host_displacement(b.slots, b.forces_n, b.u_host_m);
      b.host_job = job_;
    }
    const int tie = mesh_tie_[static_cast<std::size_t>(m)];
    if (tie < 0)
      u_m = b.u_host_m;
    else
      b.body->embedded_displacement(tie, b.u_host_m, u_m);
  }

 private:
  struct Body {
    const ia::CoupledBody* body;
    int any_mesh;
    std::vector<int> slots;
    std::vector<ia::Vec3> forces_n;  // unit N
    Eigen::VectorXd u_host_m;        // unit m
    std::uint64_t host_job;
  };
  std::vector<Body> bodies_;
  std::vector<int> mesh_body_, mesh_tie_;
  std::uint64_t job_{0};
};

}  // namespace
#endif

int main(int argc, char** argv) {
  return neurosim::service::run_main(
      argc, argv,
      [](const neurosim::scene::Scene& scene,
         const std::string& path) -> std::unique_ptr<neurosim::interaction::Simulation> {
#if NEUROSIM_HAVE_INTERACTION
        return neurosim::interaction::Simulation::build(scene, path);
#else
        (void)scene;
        throw std::runtime_error(path + ": this neurosim-server was built without "
                                        "neurosim::interaction (server/interaction): no physics to run");
#endif
      },
#if NEUROSIM_HAVE_INTERACTION
      [](const neurosim::interaction::Simulation& sim) -> std::unique_ptr<neurosim::service::FieldWorker> {
        return std::make_unique<CoupledFieldWorker>(sim);
      });
#else
      {});
#endif
}
