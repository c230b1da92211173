#include "viewer_client/viewer/state.hpp"

#include "common/force_colour.hpp"
#include "common/tool_pose.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace neurosim::viewer {

namespace {
enum WarnKind { kTopology = 0, kDeformation = 1, kTool = 2, kContact = 3, kStatus = 4 };

// The IDL's Tier in the scene's spelling; nullptr for a value this viewer does not know (a newer
// server's tier, or garbage).
const char* tier_text(neurosim_Tier t) {
  switch (t) {
    case neurosim_TIER_LINEAR: return "LINEAR";
    case neurosim_TIER_COROTATIONAL: return "COROTATIONAL";
    case neurosim_TIER_NONLINEAR: return "NONLINEAR";
  }
  return nullptr;
}

bool finite3(const double* v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}
}  // namespace

std::array<double, 3> force_colour(double force_n, double force_unit_n) {
  return common::force_colour(force_n, force_unit_n);
}

Eigen::Vector3d shaft_axis(double w, double x, double y, double z) {
  const double q[4] = {w, x, y, z};
  const std::array<double, 3> a = common::shaft_axis(q);
  return Eigen::Vector3d(a[0], a[1], a[2]);
}

MeshState mesh_from_topology(const neurosim_MeshTopology& t) {
  MeshState m;
  m.id = t.mesh_id;
  const std::string what = "MeshTopology '" + m.id + "'";
  if (m.id.empty()) throw std::invalid_argument("MeshTopology with an empty mesh_id");
  m.revision = t.revision;
  const auto v = wire::view(t.rest_vertices_m);
  if (v.size == 0 || v.size % 3 != 0)
    throw std::invalid_argument(what + ": rest_vertices_m has " + std::to_string(v.size) +
                                " components (a positive multiple of 3 expected)");
  const std::size_t nv = v.size / 3;
  if (nv > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument(what + ": too many vertices");
  m.rest_m.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    if (!finite3(&v[3 * i]))
      throw std::invalid_argument(what + ": vertex " + std::to_string(i) + " is not finite");
    m.rest_m[i] = Eigen::Vector3d(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
  }
  const auto te = wire::view(t.tetrahedra);
  if (te.size % 4 != 0)
    throw std::invalid_argument(what + ": tetrahedra has " + std::to_string(te.size) +
                                " ids (a multiple of 4 expected)");
  m.tets.resize(te.size / 4);
  for (std::size_t e = 0; e < m.tets.size(); ++e)
    for (int k = 0; k < 4; ++k) {
      const std::int32_t id = te[4 * e + static_cast<std::size_t>(k)];
      if (id < 0 || static_cast<std::size_t>(id) >= nv)
        throw std::invalid_argument(what + ": tetrahedron " + std::to_string(e) + " has vertex " +
                                    std::to_string(id) + " outside 0.." + std::to_string(nv - 1));
      m.tets[e][static_cast<std::size_t>(k)] = id;
    }
  const auto tr = wire::view(t.surface_triangles);
  if (tr.size % 3 != 0)
    throw std::invalid_argument(what + ": surface_triangles has " + std::to_string(tr.size) +
                                " ids (a multiple of 3 expected)");
  m.surface.resize(tr.size / 3);
  for (std::size_t e = 0; e < m.surface.size(); ++e)
    for (int k = 0; k < 3; ++k) {
      const std::int32_t id = tr[3 * e + static_cast<std::size_t>(k)];
      if (id < 0 || static_cast<std::size_t>(id) >= nv)
        throw std::invalid_argument(what + ": surface triangle " + std::to_string(e) +
                                    " has vertex " + std::to_string(id) + " outside 0.." +
                                    std::to_string(nv - 1));
      m.surface[e][static_cast<std::size_t>(k)] = id;
    }
  m.priority = t.priority;
  m.rigid = t.rigid;
  if (m.rigid && (!m.tets.empty() || m.surface.empty()))
    throw std::invalid_argument(what + ": a rigid mesh must have surface triangles and no "
                                       "tetrahedra (has " + std::to_string(m.tets.size()) +
                                " tetrahedra, " + std::to_string(m.surface.size()) +
                                " triangles)");
  const auto names = wire::view(t.region_names);
  for (const auto& n : names) m.region_names.emplace_back(n);
  const auto region = wire::view(t.tet_region);
  if (region.size != 0 && region.size != m.tets.size())
    throw std::invalid_argument(what + ": tet_region has " + std::to_string(region.size) +
                                " entries for " + std::to_string(m.tets.size()) + " tetrahedra");
  for (std::size_t e = 0; e < region.size; ++e) {
    if (region[e] >= m.region_names.size())
      throw std::invalid_argument(what + ": tetrahedron " + std::to_string(e) + " has region " +
                                  std::to_string(region[e]) + ", only " +
                                  std::to_string(m.region_names.size()) + " region names");
    m.tet_region.push_back(region[e]);
  }
  m.image_file = std::string(wire::get_string(t.volume_image_file));
  m.image_unit_m = t.volume_image_unit_m;
  if (!m.image_file.empty() && !(std::isfinite(m.image_unit_m) && m.image_unit_m > 0))
    throw std::invalid_argument(what + ": volume_image_unit_m " + std::to_string(m.image_unit_m) +
                                " is not a positive number");
  m.u_m.assign(3 * nv, 0.0F);
  return m;
}

std::vector<int> surface_regions(const MeshState& m) {
  std::vector<int> out(m.surface.size(), -1);
  if (m.tet_region.size() != m.tets.size() || m.tets.empty()) return out;
  // Faces of every tetrahedron, keyed by their sorted vertex ids.
  std::map<std::array<int, 3>, int> face_region;
  for (std::size_t e = 0; e < m.tets.size(); ++e) {
    const auto& t = m.tets[e];
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f{};
      int k = 0;
      for (int i = 0; i < 4; ++i)
        if (i != skip) f[static_cast<std::size_t>(k++)] = t[static_cast<std::size_t>(i)];
      std::sort(f.begin(), f.end());
      face_region.emplace(f, m.tet_region[e]);
    }
  }
  for (std::size_t i = 0; i < m.surface.size(); ++i) {
    std::array<int, 3> f = m.surface[i];
    std::sort(f.begin(), f.end());
    const auto it = face_region.find(f);
    if (it != face_region.end()) out[i] = it->second;
  }
  return out;
}

ViewerState::ViewerState(Warn warn, int max_warnings_per_kind)
    : warn_(std::move(warn)), max_warnings_(max_warnings_per_kind) {}

void ViewerState::warn(int kind, const std::string& message) {
  auto& n = warned_[static_cast<std::size_t>(kind)];
  if (!warn_ || n > max_warnings_) return;
  ++n;
  warn_(n > max_warnings_ ? message + " (further warnings of this kind suppressed)" : message);
}

MeshState* ViewerState::find(const std::string& id) {
  for (auto& m : meshes_)
    if (m.id == id) return &m;
  return nullptr;
}

const MeshState* ViewerState::mesh(const std::string& id) const {
  for (const auto& m : meshes_)
    if (m.id == id) return &m;
  return nullptr;
}

void ViewerState::set_mesh(MeshState mesh) {
  if (mesh.id.empty()) throw std::invalid_argument("viewer: mesh with an empty id");
  if (mesh.u_m.size() != 3 * mesh.rest_m.size()) mesh.u_m.assign(3 * mesh.rest_m.size(), 0.0F);
  if (MeshState* old = find(mesh.id)) {
    *old = std::move(mesh);
  } else {
    meshes_.push_back(std::move(mesh));
    // Stable order (by id) so renders do not depend on arrival order.
    std::sort(meshes_.begin(), meshes_.end(),
              [](const MeshState& a, const MeshState& b) { return a.id < b.id; });
  }
  ++topology_generation_;
}

bool ViewerState::ingest_topology(const neurosim_MeshTopology& t) {
  try {
    set_mesh(mesh_from_topology(t));
    ++counters_.topologies;
    return true;
  } catch (const std::invalid_argument& e) {
    ++counters_.malformed_topology;
    warn(kTopology, std::string("ignored a malformed sample: ") + e.what());
    return false;
  }
}

void ViewerState::set_displacements(const std::string& mesh_id, std::vector<float> u_m) {
  MeshState* m = find(mesh_id);
  if (m == nullptr) throw std::invalid_argument("viewer: no mesh '" + mesh_id + "'");
  if (m->rigid)
    throw std::invalid_argument("viewer: mesh '" + mesh_id + "' is rigid: no displacements");
  if (u_m.size() != m->u_m.size())
    throw std::invalid_argument("viewer: mesh '" + mesh_id + "' has " +
                                std::to_string(m->rest_m.size()) + " vertices, got " +
                                std::to_string(u_m.size()) + " displacement components");
  float mx = 0;
  for (std::size_t i = 0; i < u_m.size(); i += 3) {
    if (!std::isfinite(u_m[i]) || !std::isfinite(u_m[i + 1]) || !std::isfinite(u_m[i + 2]))
      throw std::invalid_argument("viewer: mesh '" + mesh_id + "' vertex " + std::to_string(i / 3) +
                                  ": non-finite displacement");
    mx = std::max(mx,
                  std::sqrt(u_m[i] * u_m[i] + u_m[i + 1] * u_m[i + 1] + u_m[i + 2] * u_m[i + 2]));
  }
  m->u_m = std::move(u_m);
  m->max_displacement_m = mx;
  m->has_deformation = true;
  ++m->u_version;
}

bool ViewerState::ingest_deformation(const neurosim_Deformation& d) {
  MeshState* m = find(d.mesh_id);
  if (m == nullptr) {
    ++counters_.deformations_waiting;  // topology not here yet (or another scene's mesh)
    return false;
  }
  try {
    if (m->rigid)
      throw std::invalid_argument("Deformation '" + m->id + "' frame " + std::to_string(d.frame) +
                                  ": the mesh is rigid (never deformed)");
    if (d.vertex_count != m->rest_m.size())
      throw std::invalid_argument("Deformation '" + m->id + "' frame " + std::to_string(d.frame) +
                                  ": vertex_count " + std::to_string(d.vertex_count) +
                                  ", the topology has " + std::to_string(m->rest_m.size()));
    if (!m->decoder.decode(d, scratch_)) {
      ++counters_.deformations_waiting;
      return false;
    }
    const std::uint64_t frame = d.frame;
    set_displacements(m->id, scratch_);  // checks finiteness; copies
    m->frame = frame;
    m->server_step = d.server_step;
    ++counters_.deformations;
    return true;
  } catch (const std::invalid_argument& e) {
    ++counters_.malformed_deformation;
    warn(kDeformation, std::string("ignored a malformed sample: ") + e.what());
    return false;
  }
}

void ViewerState::set_tool(const ToolView& tool) {
  if (!tool.tip_m.allFinite() || !tool.axis.allFinite() || !tool.force_n.allFinite())
    throw std::invalid_argument("viewer: station '" + tool.station + "': non-finite tool state");
  tools_[tool.station] = tool;
}

bool ViewerState::ingest_tool(const neurosim_ToolState& s) {
  const std::string station(s.station_id);
  if (station.empty() || !finite3(s.position_m) ||
      !(std::isfinite(s.orientation[0]) && finite3(s.orientation + 1))) {
    ++counters_.malformed_tool;
    warn(kTool, "ignored a malformed ToolState from station '" + station +
                    "': empty station id or non-finite pose");
    return false;
  }
  ToolView& t = tools_[station];
  t.station = station;
  t.tip_m = Eigen::Vector3d(s.position_m[0], s.position_m[1], s.position_m[2]);
  t.axis = shaft_axis(s.orientation[0], s.orientation[1], s.orientation[2], s.orientation[3]);
  t.has_pose = true;
  ++counters_.tool_states;
  return true;
}

bool ViewerState::ingest_contact(const neurosim_ContactModel& c) {
  const std::string station(c.station_id);
  if (station.empty() || !finite3(c.f0_n)) {
    ++counters_.malformed_contact;
    warn(kContact, "ignored a malformed ContactModel for station '" + station +
                       "': empty station id or non-finite force");
    return false;
  }
  ToolView& t = tools_[station];
  t.station = station;
  t.force_n =
      c.in_contact ? Eigen::Vector3d(c.f0_n[0], c.f0_n[1], c.f0_n[2]) : Eigen::Vector3d::Zero();
  t.in_contact = c.in_contact;
  // The model's reference pose stands in for the pose until a ToolState is read.
  if (!t.has_pose && finite3(c.x0_position_m)) {
    t.tip_m = Eigen::Vector3d(c.x0_position_m[0], c.x0_position_m[1], c.x0_position_m[2]);
    t.axis = shaft_axis(c.x0_orientation[0], c.x0_orientation[1], c.x0_orientation[2],
                        c.x0_orientation[3]);
    t.has_pose = true;
  }
  ++counters_.contact_models;
  return true;
}

bool ViewerState::ingest_status(const neurosim_SimStatus& st) {
  const char* tier = tier_text(st.tier);
  const bool rates_ok = std::isfinite(st.tier_update_rate_hz) && st.tier_update_rate_hz >= 0 &&
                        std::isfinite(st.step_rate_measured_hz) && st.step_rate_measured_hz >= 0 &&
                        std::isfinite(st.max_strain) && std::isfinite(st.expected_force_error) &&
                        std::isfinite(st.discretization_error_estimate) &&
                        std::isfinite(st.total_error_estimate);
  if (tier == nullptr || !rates_ok) {
    ++counters_.malformed_status;
    warn(kStatus, "ignored a malformed SimStatus from server '" + std::string(st.server_id) +
                      "': tier " + std::to_string(static_cast<long long>(st.tier)) +
                      (tier == nullptr ? " (unknown)" : "") + ", tier_update_rate_hz " +
                      std::to_string(st.tier_update_rate_hz) + ", step_rate_measured_hz " +
                      std::to_string(st.step_rate_measured_hz) + ", max_strain " +
                      std::to_string(st.max_strain) + ", expected_force_error " +
                      std::to_string(st.expected_force_error) + ", discretization_error_estimate " +
                      std::to_string(st.discretization_error_estimate) + ", total_error_estimate " +
                      std::to_string(st.total_error_estimate));
    return false;
  }
  ServerStatusView& v = server_status_;
  const std::string scene_name = st.scene_name != nullptr ? st.scene_name : "";
  const bool changed = !v.received || v.tier != tier ||
                       v.tier_update_rate_hz != st.tier_update_rate_hz ||
                       v.step_rate_measured_hz != st.step_rate_measured_hz ||
                       v.max_strain != st.max_strain ||
                       v.expected_force_error != st.expected_force_error ||
                       v.discretization_error_estimate != st.discretization_error_estimate ||
                       v.total_error_estimate != st.total_error_estimate ||
                       v.server_id != st.server_id || v.scene_name != scene_name;
  v.received = true;
  v.server_id = st.server_id;
  v.scene_name = scene_name;
  v.tier = tier;
  v.tier_update_rate_hz = st.tier_update_rate_hz;
  v.step_rate_measured_hz = st.step_rate_measured_hz;
  // Negative: not measured / unknown (the server sends -1).
  v.max_strain = st.max_strain >= 0 ? st.max_strain : -1.0;
  v.expected_force_error = st.expected_force_error >= 0 ? st.expected_force_error : -1.0;
  v.discretization_error_estimate =
      st.discretization_error_estimate >= 0 ? st.discretization_error_estimate : -1.0;
  v.total_error_estimate = st.total_error_estimate >= 0 ? st.total_error_estimate : -1.0;
  ++counters_.statuses;
  return changed;
}

namespace {
std::string percent(double fraction) {
  std::ostringstream os;
  os.setf(std::ios::fixed);
  os.precision(fraction < 0.01 ? 1 : 0);
  os << "~" << 100.0 * fraction << " %";
  return os.str();
}
}  // namespace

std::string error_text(const ServerStatusView& st) {
  if (!st.received) return {};
  std::ostringstream os;
  os << "error vs converged answer "
     << (st.total_error_estimate >= 0 ? percent(st.total_error_estimate) : std::string("unknown"))
     << " (mesh + element "
     << (st.discretization_error_estimate >= 0 ? percent(st.discretization_error_estimate)
                                               : std::string("unknown"))
     << ", tier "
     << (st.expected_force_error >= 0 ? percent(st.expected_force_error)
                                      : std::string(st.max_strain >= 0 ? "unknown"
                                                                       : "not measured"))
     << ")";
  return os.str();
}

void ViewerState::remove_station(const std::string& station) { tools_.erase(station); }

void ViewerState::set_server_alive(bool alive) {
  if (alive && !server_alive_) ++counters_.server_seen;
  if (!alive && server_alive_) ++counters_.server_lost;
  server_alive_ = alive;
  if (alive) server_ever_seen_ = true;
}

const ToolView* ViewerState::primary_tool() const {
  for (const auto& [id, t] : tools_)
    if (t.has_pose) return &t;
  return nullptr;
}

double ViewerState::max_displacement_m() const {
  double mx = 0;
  for (const auto& m : meshes_) mx = std::max(mx, static_cast<double>(m.max_displacement_m));
  return mx;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> ViewerState::bounds_m() const {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (const auto& m : meshes_)
    for (const auto& x : m.rest_m) {
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
  if (!lo.allFinite()) return {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  return {lo, hi};
}

std::string ViewerState::image_file() const {
  for (const auto& m : meshes_)
    if (!m.image_file.empty()) return m.image_file;
  return {};
}

double ViewerState::image_unit_m() const {
  for (const auto& m : meshes_)
    if (!m.image_file.empty()) return m.image_unit_m;
  return 1.0;
}

}  // namespace neurosim::viewer
