#include "web/observer_state.hpp"

#include "common/force_colour.hpp"
#include "common/json.hpp"
#include "common/tool_pose.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace neurosim::web {

namespace {

enum WarnKind { kTopology = 0, kFrame = 1, kContact = 2, kStatus = 3 };

// An enum field of a received sample as the integer it is on the wire: a value outside the C
// enum (a newer server's, or garbage) must not be loaded as the enum.
template <class E>
std::int32_t raw_enum(const E& field) {
  static_assert(sizeof(E) == sizeof(std::int32_t), "IDL enums are 32-bit");
  std::int32_t v = 0;
  std::memcpy(&v, &field, sizeof v);
  return v;
}

// The IDL's Tier in the scene's spelling; nullptr for a value this bridge does not know.
const char* tier_text(std::int32_t t) {
  switch (t) {
    case neurosim_TIER_LINEAR:
      return "LINEAR";
    case neurosim_TIER_COROTATIONAL:
      return "COROTATIONAL";
    case neurosim_TIER_NONLINEAR:
      return "NONLINEAR";
    default:
      return nullptr;
  }
}

bool finite3(const double* v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

common::Json array3(const std::array<double, 3>& v) {
  return common::Json::array({v[0], v[1], v[2]});
}

}  // namespace

std::array<double, 3> force_colour(double force_n, double force_unit_n) {
  return common::force_colour(force_n, force_unit_n);
}

ObserverState::ObserverState(Warn warn, int max_warnings_per_kind)
    : warn_(std::move(warn)), max_warnings_(max_warnings_per_kind) {}

void ObserverState::warn(int kind, const std::string& message) {
  auto& n = warned_[static_cast<std::size_t>(kind)];
  if (!warn_ || n > max_warnings_) return;
  ++n;
  warn_(n > max_warnings_ ? message + " (further warnings of this kind suppressed)" : message);
}

TopologyPtr ObserverState::ingest_topology(const neurosim_MeshTopology& t) {
  Mesh m;
  m.id = std::string(t.mesh_id);
  const std::string what = "MeshTopology '" + m.id + "'";
  try {
    if (m.id.empty()) throw std::invalid_argument("MeshTopology with an empty mesh_id");
    const auto v = wire::view(t.rest_vertices_m);
    if (v.size == 0 || v.size % 3 != 0)
      throw std::invalid_argument(what + ": rest_vertices_m has " + std::to_string(v.size) +
                                  " components (a positive multiple of 3 expected)");
    const std::size_t nv = v.size / 3;
    if (nv > std::numeric_limits<std::uint32_t>::max() / 3)
      throw std::invalid_argument(what + ": too many vertices");
    m.rest_m.resize(v.size);
    for (std::size_t i = 0; i < nv; ++i) {
      if (!finite3(&v[3 * i]))
        throw std::invalid_argument(what + ": vertex " + std::to_string(i) + " is not finite");
      for (std::size_t k = 0; k < 3; ++k) m.rest_m[3 * i + k] = static_cast<float>(v[3 * i + k]);
    }
    const auto tr = wire::view(t.surface_triangles);
    if (tr.size % 3 != 0)
      throw std::invalid_argument(what + ": surface_triangles has " + std::to_string(tr.size) +
                                  " ids (a multiple of 3 expected)");
    m.triangles.resize(tr.size);
    for (std::size_t i = 0; i < tr.size; ++i) {
      if (tr[i] < 0 || static_cast<std::size_t>(tr[i]) >= nv)
        throw std::invalid_argument(what + ": surface triangle " + std::to_string(i / 3) +
                                    " has vertex " + std::to_string(tr[i]) + " outside 0.." +
                                    std::to_string(nv - 1));
      m.triangles[i] = static_cast<std::uint32_t>(tr[i]);
    }
    const bool replaces =
        std::any_of(meshes_.begin(), meshes_.end(), [&](const Mesh& o) { return o.id == m.id; });
    if (!replaces && meshes_.size() >= std::numeric_limits<std::uint16_t>::max())
      throw std::invalid_argument(what + ": too many meshes");
  } catch (const std::invalid_argument& e) {
    ++counters_.malformed_topology;
    warn(kTopology, std::string("ignored a malformed sample: ") + e.what());
    return nullptr;
  }
  m.revision = t.revision;
  m.info_json = common::Json{{"material", std::string(wire::get_string(t.material_name))},
                             {"youngs_modulus_pa", t.youngs_modulus_pa},
                             {"poisson_ratio", t.poisson_ratio},
                             {"priority", t.priority},
                             {"provenance", std::string(wire::get_string(t.provenance))}}
                    .dump();
  scene_name_ = std::string(wire::get_string(t.scene_name));
  auto it =
      std::find_if(meshes_.begin(), meshes_.end(), [&](const Mesh& o) { return o.id == m.id; });
  if (it != meshes_.end())
    *it = std::move(m);
  else
    meshes_.push_back(std::move(m));
  std::sort(meshes_.begin(), meshes_.end(),
            [](const Mesh& a, const Mesh& b) { return a.id < b.id; });
  ++counters_.topologies;
  rebuild_topology();
  return topology_;
}

void ObserverState::rebuild_topology() {
  ++generation_;
  auto topo = std::make_shared<Topology>();
  topo->generation = generation_;
  topo->meshes = meshes_.size();
  common::Json list = common::Json::array();
  for (std::size_t i = 0; i < meshes_.size(); ++i) {
    Mesh& m = meshes_[i];
    m.last_full.reset();  // encoded for the previous generation
    common::Json j{{"index", i},
                   {"id", m.id},
                   {"vertices", m.vertex_count()},
                   {"triangles", m.triangles.size() / 3},
                   {"revision", m.revision}};
    const common::Json info = common::Json::parse(m.info_json);
    for (const auto& [k, v] : info.items()) j[k] = v;
    list.push_back(std::move(j));
  }
  common::Json head{{"type", "topology"},
                    {"generation", generation_},
                    {"scene", scene_name_},
                    {"meshes", std::move(list)}};
  topo->messages.push_back(text_message(head.dump()));
  for (std::size_t i = 0; i < meshes_.size(); ++i)
    topo->messages.push_back(std::make_shared<Message>(geometry_message(
        static_cast<std::uint16_t>(i), generation_, meshes_[i].rest_m, meshes_[i].triangles)));
  topology_ = std::move(topo);
}

FramePtr ObserverState::ingest_deformation(const neurosim_Deformation& d) {
  const std::string id(d.mesh_id);
  auto it = std::find_if(meshes_.begin(), meshes_.end(), [&](const Mesh& m) { return m.id == id; });
  if (it == meshes_.end() || it->revision != d.topology_revision) {
    ++counters_.frames_waiting;  // topology not here yet (or another revision / scene)
    return nullptr;
  }
  Mesh& m = *it;
  const std::string what = "Deformation '" + id + "' frame " + std::to_string(d.frame);
  const std::int32_t encoding = raw_enum(d.encoding);
  const bool full = encoding == neurosim_ENCODING_FULL;
  try {
    if (!full && encoding != neurosim_ENCODING_QUANTIZED_DELTA)
      throw std::invalid_argument(what + ": unknown encoding " + std::to_string(encoding));
    if (d.vertex_count != m.vertex_count())
      throw std::invalid_argument(what + ": vertex_count " + std::to_string(d.vertex_count) +
                                  ", the topology has " + std::to_string(m.vertex_count()));
    const std::size_t n = 3 * static_cast<std::size_t>(d.vertex_count);
    if (full) {
      const auto u = wire::view(d.displacement_m);
      if (u.size != n)
        throw std::invalid_argument(what + ": FULL frame with " + std::to_string(u.size) +
                                    " displacement components, " + std::to_string(n) + " expected");
      for (std::size_t i = 0; i < n; ++i)
        if (!std::isfinite(u[i]))
          throw std::invalid_argument(what + ": vertex " + std::to_string(i / 3) +
                                      " has a non-finite displacement");
    } else {
      const auto q = wire::view(d.delta_q);
      if (q.size != n)
        throw std::invalid_argument(what + ": delta frame with " + std::to_string(q.size) +
                                    " components, " + std::to_string(n) + " expected");
      // 0 when nothing moved since the FULL frame.
      if (!(std::isfinite(d.delta_scale_m) && d.delta_scale_m >= 0))
        throw std::invalid_argument(what + ": delta_scale_m " + std::to_string(d.delta_scale_m) +
                                    " is negative or not finite");
    }
    if (!std::isfinite(d.max_displacement_m))
      throw std::invalid_argument(what + ": max_displacement_m is not finite");
  } catch (const std::invalid_argument& e) {
    ++counters_.malformed_frame;
    warn(kFrame, std::string("ignored a malformed sample: ") + e.what());
    return nullptr;
  }
  auto f = std::make_shared<Frame>();
  f->mesh_index = static_cast<std::uint16_t>(it - meshes_.begin());
  f->generation = generation_;
  f->full = full;
  f->server_time_ns = d.server_time_ns;
  if (full) {
    f->full_serial = next_full_serial_++;
  } else {
    // A delta is only useful with the FULL frame it adds to (lost on the best-effort topic, or
    // sent before this bridge matched): wait for the next FULL one.
    if (!m.last_full || m.last_full_frame != d.base_frame) {
      ++counters_.frames_waiting;
      return nullptr;
    }
    f->full_serial = m.last_full->full_serial;
    f->base = m.last_full;
  }
  f->message = frame_message(d, f->mesh_index, generation_);
  if (full) {
    m.last_full = f;
    m.last_full_frame = d.frame;
  }
  ++counters_.frames;
  return f;
}

bool ObserverState::ingest_contact(const neurosim_ContactModel& c) {
  const std::string station(c.station_id);
  if (station.empty() || !finite3(c.f0_n) || !finite3(c.x0_position_m) ||
      !(std::isfinite(c.x0_orientation[0]) && finite3(c.x0_orientation + 1))) {
    ++counters_.malformed_contact;
    warn(kContact, "ignored a malformed ContactModel for station '" + station +
                       "': empty station id or non-finite force or pose");
    return false;
  }
  StationView& s = stations_[station];
  for (int k = 0; k < 3; ++k) {
    s.force_n[static_cast<std::size_t>(k)] = c.in_contact ? c.f0_n[k] : 0.0;
    s.tip_m[static_cast<std::size_t>(k)] = c.x0_position_m[k];
  }
  s.axis = common::shaft_axis(c.x0_orientation);
  s.in_contact = c.in_contact;
  s.mesh = std::string(c.contact_mesh_id);
  s.server_time_ns = c.server_time_ns;
  ++counters_.contacts;
  return true;
}

bool ObserverState::remove_station(std::string_view station) {
  return stations_.erase(std::string(station)) > 0;
}

bool ObserverState::ingest_status(const neurosim_SimStatus& st) {
  const std::int32_t raw_tier = raw_enum(st.tier);
  const char* tier = tier_text(raw_tier);
  const double rates[] = {st.step_rate_target_hz, st.step_rate_measured_hz, st.viewer_rate_hz,
                          st.status_rate_hz,      st.tier_update_rate_hz,   st.uptime_s};
  const bool rates_ok = std::all_of(std::begin(rates), std::end(rates),
                                    [](double r) { return std::isfinite(r) && r >= 0; });
  if (tier == nullptr || !rates_ok) {
    ++counters_.malformed_status;
    warn(kStatus, "ignored a malformed SimStatus from server '" + std::string(st.server_id) +
                      "': tier " + std::to_string(raw_tier) +
                      (tier == nullptr ? " (unknown)" : "") +
                      ", or a negative or non-finite rate or uptime");
    return false;
  }
  common::Json stations = common::Json::array();
  for (const auto& s : wire::view(st.stations))
    stations.push_back({{"id", std::string(s.station_id)},
                        {"alive", s.alive},
                        {"in_contact", s.in_contact},
                        {"samples_accepted", s.samples_accepted}});
  // Percentiles are NaN before the first steps: nlohmann writes them as null.
  status_json_ =
      common::Json{{"server_id", std::string(st.server_id)},
                   {"scene", std::string(wire::get_string(st.scene_name))},
                   {"tier", tier},
                   {"effects", std::string(wire::get_string(st.effects))},
                   {"step_rate_target_hz", st.step_rate_target_hz},
                   {"step_rate_measured_hz", st.step_rate_measured_hz},
                   {"viewer_rate_hz", st.viewer_rate_hz},
                   {"status_rate_hz", st.status_rate_hz},
                   {"tier_update_rate_hz", st.tier_update_rate_hz},
                   {"step_time_p50_us", st.step_time_p50_us},
                   {"step_time_p99_us", st.step_time_p99_us},
                   {"step_time_max_us", st.step_time_max_us},
                   {"steps", st.steps},
                   {"deadline_misses", st.deadline_misses},
                   {"uptime_s", st.uptime_s},
                   {"max_stations", st.max_stations},
                   // -1: not measured / unknown (a NaN would become null).
                   {"max_strain", std::isfinite(st.max_strain) ? st.max_strain : -1.0},
                   {"expected_force_error",
                    std::isfinite(st.expected_force_error) ? st.expected_force_error : -1.0},
                   // Against the converged answer (nested refinements extrapolated), -1: unknown.
                   {"discretization_error_estimate", std::isfinite(st.discretization_error_estimate)
                                                         ? st.discretization_error_estimate
                                                         : -1.0},
                   {"total_error_estimate",
                    std::isfinite(st.total_error_estimate) ? st.total_error_estimate : -1.0},
                   {"tier_update_failures", st.tier_update_failures},
                   {"columns_not_ready", st.columns_not_ready},
                   {"steps_with_rows_dropped", st.steps_with_rows_dropped},
                   {"steps_not_converged", st.steps_not_converged},
                   {"stations", std::move(stations)}}
          .dump();
  status_received_ = true;
  ++counters_.statuses;
  return true;
}

bool ObserverState::set_server_alive(bool alive) {
  if (alive == server_alive_) return false;
  server_alive_ = alive;
  if (alive)
    ++counters_.server_seen;
  else
    ++counters_.server_lost;
  return true;
}

MessagePtr ObserverState::stations_message() const {
  common::Json list = common::Json::array();
  for (const auto& [id, s] : stations_) {
    const double f = std::sqrt(s.force_n[0] * s.force_n[0] + s.force_n[1] * s.force_n[1] +
                               s.force_n[2] * s.force_n[2]);
    list.push_back({{"id", id},
                    {"force_n", array3(s.force_n)},
                    {"force_magnitude_n", f},
                    {"in_contact", s.in_contact},
                    {"tip_m", array3(s.tip_m)},
                    {"axis", array3(s.axis)},
                    {"mesh", s.mesh},
                    {"server_time_ns", s.server_time_ns}});
  }
  return text_message(common::Json{{"type", "stations"}, {"stations", std::move(list)}}.dump());
}

MessagePtr ObserverState::status_message(const BridgeRates& rates) const {
  common::Json j{{"type", "status"},
                 {"server_alive", server_alive_},
                 {"server", status_received_ ? common::Json::parse(status_json_) : common::Json()},
                 {"bridge",
                  {{"deformation_hz", rates.deformation_hz},
                   {"clients", rates.clients},
                   {"max_clients", rates.max_clients},
                   {"server_seen", counters_.server_seen},
                   {"server_lost", counters_.server_lost}}}};
  return text_message(j.dump());
}

}  // namespace neurosim::web
