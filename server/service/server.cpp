// neurosim-server: the parts composed (docs/ARCHITECTURE.md "From a tool pose to a force and
// back"): StationAdmission on the DDS thread, StepLoop on the step thread, DeformationPublisher
// on the field thread, StatusPublisher from the step thread; here the DDS entities, the
// topologies published once, the threads started and stopped.
#include "server/service/server.hpp"

#include "common/clock.hpp"
#include "idl/wire/dds.hpp"
#include "server/interaction/rigid_obstacle.hpp"
#include "server/service/accuracy_table.hpp"
#include "server/service/deformation_publisher.hpp"
#include "server/service/discretization_table.hpp"
#include "server/service/station_admission.hpp"
#include "server/service/status_publisher.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace neurosim::service {

namespace wire = neurosim::wire;

namespace {

constexpr int kMaxStationsLimit = 64;  // SimStatus.stations is sequence<StationStatus, 64>

using common::monotonic_ns;

std::string describe_setup(const interaction::Simulation& sim) {
  const auto& st = sim.setup_stats();
  std::ostringstream os;
  os << "physics built in " << st.total_s << " s: meshes " << st.load_meshes_s << " s, factor "
     << st.factor_s << " s (" << st.factor_bytes / 1e6 << " MB), ";
  if (st.fusion_s == 0 && st.tied_nodes == 0)
    os << "inclusion decision: not run (no coupling)";
  else
    os << "inclusion decision + coupling map " << st.fusion_s << " s, condense " << st.condense_s
       << " s, boundary columns " << st.boundary_s << " s, coupling operator " << st.operator_s
       << " s (" << st.boundary_nodes << " boundary nodes, " << st.tied_nodes << " tied nodes, " << st.exposed_nodes
       << " exposed nodes untied)";
  os << ", contact columns " << st.columns_s << " s";
  // The column worker's bound per body (SimulationOptions::column_cache_budget_mb).
  std::vector<int> seen;
  for (int m = 0; m < sim.num_meshes(); ++m) {
    const int b = sim.body_index(m);
    if (b < 0 || std::find(seen.begin(), seen.end(), b) != seen.end()) continue;
    seen.push_back(b);
    const auto c = sim.column_cache(m);
    if (c.bytes_per_slot == 0) continue;
    os << "; column cache of '" << sim.mesh_id(m) << "': " << c.bytes_per_slot / 1e6 << " MB per node, ";
    if (c.capacity_slots > 0)
      os << "at most " << c.capacity_slots << " nodes (" << c.capacity_slots * c.bytes_per_slot / 1e6
         << " MB), the least recently reached evicted";
    else
      os << "not bounded";
  }
  return os.str();
}

// The ToolState reader as the admission's directory of writers.
class ReaderDirectory : public WriterDirectory {
 public:
  explicit ReaderDirectory(const wire::Reader<neurosim_ToolState>& r) : r_(r) {}
  wire::MatchedPublication matched(dds_instance_handle_t writer) const override {
    return r_.matched_publication(writer);
  }

 private:
  const wire::Reader<neurosim_ToolState>& r_;
};

// The ContactModel writer as the step loop's sink.
class WriterSink : public ContactModelSink {
 public:
  explicit WriterSink(wire::Writer<neurosim_ContactModel>& w) : w_(w) {}
  void write(const neurosim_ContactModel& m) override { w_.write(m); }
  void dispose(const neurosim_ContactModel& k) override { w_.dispose(k); }

 private:
  wire::Writer<neurosim_ContactModel>& w_;
};

// No stations (effects.tool_contact off): nothing is ever written.
class NullSink : public ContactModelSink {
 public:
  void write(const neurosim_ContactModel&) override {}
  void dispose(const neurosim_ContactModel&) override {}
};

}  // namespace

struct Server::Impl {
  Impl(const scene::Model& model, std::unique_ptr<interaction::Simulation> s, ServerOptions o,
       std::ostream& l)
      : settings(model), sim(std::move(s)), opt(std::move(o)), log_stream(l) {
    for (const auto& m : model.meshes) {
      MeshInfo mi{m.id, m.material, m.priority, m.provenance, {}, {}};
      for (const auto& t : m.tissues) {
        mi.region_labels.push_back(t.label);
        mi.region_names.push_back(t.name);
      }
      mesh_info.push_back(std::move(mi));
    }
    rigid_surfaces = model.rigid;
    if (!model.meshes.empty()) {
      host_vertices = model.meshes.front().mesh.num_vertices();
      host_tetrahedra = model.meshes.front().mesh.num_tets();
    }
  }

  // ---- Model (built once) --------------------------------------------------------------------
  scene::Settings settings;
  struct MeshInfo {  // what MeshTopology says of each scene mesh
    std::string id;
    fem::Material material;
    int priority;
    std::string provenance;
    std::vector<int> region_labels;         // scene tissues' labels (tet_region indexes these)
    std::vector<std::string> region_names;  // and their names
  };
  std::vector<MeshInfo> mesh_info;
  // The scene's host mesh as loaded (before any coupling removes tetrahedra from it): what the
  // discretization table is keyed by.
  std::size_t host_vertices{0}, host_tetrahedra{0};
  std::vector<scene::RigidSurface> rigid_surfaces;  // published as rigid MeshTopology samples
  std::unique_ptr<interaction::Simulation> sim;
  ServerOptions opt;
  std::ostream& log_stream;
  std::mutex log_mutex;

  double step_hz{1000}, viewer_hz{30}, status_hz{1};
  std::int64_t period_ns{1000000};
  std::uint64_t viewer_every{33}, status_every{1000};
  std::int64_t viewer_period_ns{33333333}, status_period_ns{1000000000};
  int max_stations{8};
  bool tool_contact{true};
  bool deformation_output{false};
  std::string effects_text;
  std::vector<double> tool_max_speed;  // per scene tool, m/s
  std::vector<std::string> tool_ids;
  Workspace workspace;                 // scene bounding box + opt.workspace_margin_m
  std::optional<AccuracyTable> accuracy;
  double discretization_error{-1.0};  // host vs converged answer (fraction), -1: unknown
  std::string host_element;
  double host_poisson_ratio{0.0};

  // ---- The parts -----------------------------------------------------------------------------
  // Declared before the participant: its topic filter points into it, so it must outlive it.
  std::optional<StationAdmission> stations;
  std::optional<wire::Participant> pp;
  std::optional<wire::Topic<neurosim_ToolState>> tool_topic;
  std::optional<wire::Topic<neurosim_ContactModel>> model_topic;
  std::optional<wire::Topic<neurosim_MeshTopology>> topo_topic;
  std::optional<wire::Topic<neurosim_SimStatus>> status_topic;
  std::optional<wire::Reader<neurosim_ToolState>> tools;
  std::optional<wire::Writer<neurosim_ContactModel>> models;
  std::optional<wire::Writer<neurosim_MeshTopology>> topologies;
  std::optional<wire::Writer<neurosim_SimStatus>> status_writer;
  std::optional<wire::Waitset> waitset;
  std::optional<ReaderDirectory> directory;
  std::optional<WriterSink> sink;
  NullSink null_sink;
  std::optional<StepLoop> loop;
  std::optional<DeformationPublisher> deformation;
  std::optional<StatusPublisher> status;
  std::int64_t next_viewer_ns{0};  // step thread

  std::atomic<bool> run{false};
  std::atomic<bool> started{false};
  std::atomic<bool> stopped{false};
  mutable std::mutex error_mutex;
  std::string error_text;
  std::thread dds_thread, step_thread;

  void log(const std::string& line) {
    std::lock_guard<std::mutex> lk(log_mutex);
    log_stream << "neurosim-server: " << line << '\n' << std::flush;
  }
  void fail(const std::string& where, const std::exception& e) {
    {
      std::lock_guard<std::mutex> lk(error_mutex);
      if (error_text.empty()) error_text = where + ": " + e.what();
    }
    log("error in " + where + ": " + e.what());
    run = false;
    if (waitset) {
      try {
        waitset->wake();
      } catch (...) {
      }
    }
  }

  void configure();
  void create_entities();
  void publish_topologies();
  static void set_regions(neurosim_MeshTopology& t, const std::vector<int>& labels,
                          std::size_t num_tets, const MeshInfo& info);
  void dds_loop();
  void step_thread_main();
  void dispose_all();
};

// ---------------------------------------------------------------------------------------------
void Server::Impl::configure() {
  const auto& r = settings.rates;
  step_hz = r.step_hz;
  viewer_hz = r.viewer_hz;
  status_hz = r.status_hz;
  if (!(std::isfinite(step_hz) && std::isfinite(viewer_hz) && std::isfinite(status_hz)))
    throw std::runtime_error(opt.scene_path + ": rates: not finite");
  period_ns = static_cast<std::int64_t>(std::llround(1e9 / step_hz));
  if (period_ns < 1000) throw std::runtime_error(opt.scene_path + ": rates.step_hz: above 1 MHz");
  viewer_every = std::max<std::uint64_t>(1, std::llround(step_hz / viewer_hz));
  status_every = std::max<std::uint64_t>(1, std::llround(step_hz / status_hz));
  // Viewer frames and SimStatus on the clock (event step mode steps at a varying rate).
  viewer_period_ns = static_cast<std::int64_t>(viewer_every) * period_ns;
  status_period_ns = static_cast<std::int64_t>(status_every) * period_ns;
  if (!(opt.max_step_rate_factor >= 1.0 && opt.max_step_rate_factor <= 100.0))
    throw std::invalid_argument("max_step_rate_factor " + std::to_string(opt.max_step_rate_factor) +
                                " must be in [1, 100]");
  for (const char* role : {"step", "dds", "field"}) (void)opt.threads.at(role);  // all three named
  max_stations = settings.max_stations;
  if (max_stations > kMaxStationsLimit)
    throw std::runtime_error(opt.scene_path + ": max_stations: " + std::to_string(max_stations) +
                             " is above " + std::to_string(kMaxStationsLimit));
  const auto& fx = settings.effects;
  tool_contact = fx.tool_contact;
  deformation_output = fx.deformation_output;
  std::string e;
  auto add = [&](bool on, const char* name) {
    if (!on) return;
    if (!e.empty()) e += ',';
    e += name;
  };
  add(fx.tool_contact, "contact");
  add(fx.coupling, "coupling");
  add(fx.deformation_output, "deformation");
  effects_text = e;
  for (const auto& t : settings.tools) {
    tool_ids.push_back(t.id);
    tool_max_speed.push_back(t.max_speed_m_per_s);
  }
  if (sim == nullptr) throw std::runtime_error("Server: no simulation");
  if (!(std::isfinite(opt.station_idle_timeout_s) && opt.station_idle_timeout_s >= 0.05 &&
        opt.station_idle_timeout_s <= 3600))
    throw std::runtime_error("station idle timeout " + std::to_string(opt.station_idle_timeout_s) +
                             " s is outside [0.05, 3600] s");
  if (opt.max_stations_per_participant < 1)
    throw std::runtime_error("max stations per participant " +
                             std::to_string(opt.max_stations_per_participant) + " is below 1");
  if (!(std::isfinite(opt.workspace_margin_m) && opt.workspace_margin_m >= 0 && opt.workspace_margin_m <= 100))
    throw std::runtime_error("workspace margin " + std::to_string(opt.workspace_margin_m) +
                             " m is outside [0, 100] m");
  if (!(std::isfinite(opt.max_future_s) && opt.max_future_s >= 0))
    throw std::runtime_error("max future " + std::to_string(opt.max_future_s) + " s is not finite and >= 0");
  if (!(std::isfinite(opt.max_station_rate_hz) && opt.max_station_rate_hz >= 10))
    throw std::runtime_error("max station rate " + std::to_string(opt.max_station_rate_hz) +
                             " Hz is not finite and >= 10 Hz");
  if (sim->num_meshes() != static_cast<int>(mesh_info.size()))
    throw std::runtime_error(opt.scene_path + ": the simulation has " +
                             std::to_string(sim->num_meshes()) + " meshes, the scene " +
                             std::to_string(mesh_info.size()));

  // Simulation::tier() promises the scene's tier and never another one; a simulation that runs
  // another would publish a SimStatus.tier the scene (and --tier) did not ask for: refuse it.
  if (sim->tier() != fx.tier)
    throw std::runtime_error(opt.scene_path + ": the simulation runs tier " +
                             scene::tier_name(sim->tier()) + ", not the tier asked for: " +
                             scene::tier_name(fx.tier) + " (from " + opt.tier_source + ")");

  if (!opt.accuracy_table.empty()) {
    accuracy = AccuracyTable::read(opt.accuracy_table);
    log("accuracy table " + opt.accuracy_table + ": " + std::to_string(accuracy->rows().size()) +
        " measured rows" +
        (deformation_output ? std::string()
                            : std::string(" (no strain measured: effects.deformation_output is "
                                          "off, so no expected error either)")) +
        "; the strain is measured in the fields solved for viewers, while one is matched");
  } else {
    log("no accuracy table: SimStatus.expected_force_error stays -1 (unknown)");
  }
  // The host (the scene's first deformable mesh): its element and nu choose the tier table's
  // rows, and with its size the discretization error against the converged answer.
  const fem::Material& host_material = mesh_info.at(0).material;
  host_element = fem::element_name(host_material.element);
  host_poisson_ratio = host_material.poisson_ratio;
  {
    std::ostringstream d;
    d << "error vs converged answer: host '" << mesh_info.at(0).id << "' (" << host_element
      << ", nu " << host_poisson_ratio << ", " << host_vertices << " vertices, "
      << host_tetrahedra << " tetrahedra as loaded): ";
    if (opt.discretization_table.empty()) {
      d << "discretization error unknown (no discretization table): SimStatus "
           "discretization_error_estimate and total_error_estimate stay -1";
    } else {
      const auto table = DiscretizationTable::read(opt.discretization_table);
      const auto row =
          table.find(host_material.element, host_poisson_ratio, host_vertices, host_tetrahedra);
      if (row) {
        discretization_error = row->discretization_error;
        d << "discretization error " << 100.0 * discretization_error << " % (measured on scene '"
          << row->scene << "', " << opt.discretization_table << ")";
      } else {
        d << "discretization error unknown: no row of " << opt.discretization_table
          << " for this element, nu and mesh (SimStatus total_error_estimate -1)";
      }
    }
    log(d.str());
  }
  // Workspace: the bounding box of every mesh's rest vertices, enlarged by the margin.
  WorkspaceBounds bounds;
  for (int m = 0; m < sim->num_meshes(); ++m)
    for (const auto& x : sim->mesh(m).vertices()) bounds.add(x.data());
  workspace = bounds.enlarged(opt.workspace_margin_m);
  {
    std::ostringstream w;
    w << "stations: workspace [" << workspace.min_m[0] << ", " << workspace.max_m[0] << "] x ["
      << workspace.min_m[1] << ", " << workspace.max_m[1] << "] x [" << workspace.min_m[2] << ", "
      << workspace.max_m[2] << "] m (scene bounding box + " << opt.workspace_margin_m
      << " m), idle timeout " << opt.station_idle_timeout_s << " s, at most "
      << opt.max_stations_per_participant << " per participant, at most " << opt.max_station_rate_hz
      << " samples/s each, source time at most " << opt.max_future_s << " s ahead";
    log(w.str());
  }
  const std::string setup = describe_setup(*sim);
  if (!setup.empty()) log(setup);
  std::ostringstream s;
  s << "scene '" << settings.name << "' (" << opt.scene_path << "): tier "
    << scene::tier_name(sim->tier()) << " (from " << opt.tier_source << "), effects ["
    << effects_text << "], step " << step_hz << " Hz, viewer " << viewer_hz << " Hz, status "
    << status_hz << " Hz, max " << max_stations << " stations";
  log(s.str());

  // Station admission: the slots exist only with tool contact.
  StationAdmissionDef ad;
  ad.max_stations = tool_contact ? max_stations : 0;
  ad.max_stations_per_participant = opt.max_stations_per_participant;
  ad.station_idle_timeout_s = opt.station_idle_timeout_s;
  ad.writers.max_per_participant =
      std::max<std::size_t>(ad.writers.max_per_participant,
                            2 * static_cast<std::size_t>(opt.max_stations_per_participant));
  ad.workspace = workspace;
  ad.max_future_s = opt.max_future_s;
  ad.max_station_rate_hz = opt.max_station_rate_hz;
  ad.tool_ids = tool_ids;
  ad.tool_max_speed_m_per_s = tool_max_speed;
  ad.log_lines_per_second = opt.log_lines_per_second;
  std::function<void()> on_pose;
  if (opt.step_mode == StepMode::kEvent) on_pose = [this] { if (loop) loop->wake(); };
  stations.emplace(std::move(ad), [this](const std::string& line) { log(line); }, std::move(on_pose));
}
void Server::Impl::create_entities() {
  wire::ParticipantOptions po;
  if (opt.domain >= 0) po.domain = static_cast<dds_domainid_t>(opt.domain);
  pp.emplace(po);
  const std::string& p = opt.topic_prefix;
  topo_topic.emplace(*pp, wire::topic_name<neurosim_MeshTopology>(p));
  topologies.emplace(*pp, *topo_topic);
  status_topic.emplace(*pp, wire::topic_name<neurosim_SimStatus>(p));
  status_writer.emplace(*pp, *status_topic);
  waitset.emplace(*pp);
  log("built: MeshTopology writer (" + std::to_string(sim->num_meshes()) +
      " meshes), SimStatus writer");

  if (tool_contact) {
    tool_topic.emplace(*pp, wire::topic_name<neurosim_ToolState>(p));
    // The identity filter before the reader exists (Cyclone: not thread-safe afterwards).
    stations->install_filter(tool_topic->handle());
    model_topic.emplace(*pp, wire::topic_name<neurosim_ContactModel>(p));
    tools.emplace(*pp, *tool_topic);
    models.emplace(*pp, *model_topic);
    waitset->attach_data(*tools, 1);
    waitset->attach_liveliness(*tools, 2);
    directory.emplace(*tools);
    stations->set_directory(&*directory);
    sink.emplace(*models);
  } else {
    log("not built: stations (effects.tool_contact off): no ToolState reader, no ContactModel");
  }
  // The step loop also runs without stations (the clock of Deformation and SimStatus).
  StepLoopDef ld;
  ld.period_ns = period_ns;
  ld.mode = opt.step_mode;
  ld.max_step_rate_factor = opt.max_step_rate_factor;
  loop.emplace(ld, *sim, *stations,
               sink ? static_cast<ContactModelSink&>(*sink) : static_cast<ContactModelSink&>(null_sink),
               [this](const std::string& line) { log(line); });
  if (tool_contact) {
    if (const interaction::RigidObstacle* rigid = sim->rigid_obstacle())
      log("built: rigid obstacles (" + std::to_string(rigid->num_triangles()) +
          " triangles), a tool proxy per station in the step (reach " + std::to_string(1e3 * sim->proxy_reach_m()) + " mm)");
    log("built: ToolState reader (partition " + std::string(wire::kToolStateReaderPartition) +
        ", station identity filter, at most " + std::to_string(stations->writers().limits().max_writers) +
        " writers, " + std::to_string(stations->writers().limits().max_per_participant) +
        " per participant), ContactModel writer, " + std::to_string(max_stations) + " station slots");
  }

  if (deformation_output) {
    deformation.emplace(*sim, *pp, p, opt.full_frame_period, [this](const std::string& line) { log(line); });
    log("built: Deformation writer, " + std::to_string(sim->num_meshes()) + " encoders (" +
        std::to_string(viewer_hz) + " Hz, FULL frame every " + std::to_string(opt.full_frame_period) +
        " frames); full-field solves only while a viewer is matched, " +
        "on the field thread from a snapshot of each step's forces");
  } else {
    log("not built: Deformation (effects.deformation_output off): no full-field solves");
  }

  StatusPublisherDef sd;
  sd.server_id = opt.server_id;
  sd.effects_text = effects_text;
  sd.step_hz = step_hz;
  sd.viewer_hz = deformation_output ? viewer_hz : 0.0;
  sd.status_hz = status_hz;
  sd.discretization_error = discretization_error;
  sd.host_element = host_element;
  sd.host_poisson_ratio = host_poisson_ratio;
  sd.status_period_ns = status_period_ns;
  sd.step_times_per_period =
      static_cast<std::size_t>(static_cast<double>(status_every) * (opt.max_step_rate_factor + 1.0)) + 64;
  status.emplace(sd, settings, *sim, *stations, &*loop, deformation ? &*deformation : nullptr,
                 std::move(accuracy), &*status_writer, [this](const std::string& line) { log(line); });
  loop->after_step = [this](std::uint64_t step) {
    if (deformation && monotonic_ns() >= next_viewer_ns) {  // the viewer rate, on the clock
      next_viewer_ns = std::max(next_viewer_ns + viewer_period_ns, monotonic_ns());
      deformation->tick(step, dds_time());
    }
  };
  loop->after_timing = [this](std::int64_t t0, std::int64_t t1) { status->after_step(t0, t1); };
}

void Server::Impl::publish_topologies() {
  for (int m = 0; m < sim->num_meshes(); ++m) {
    const auto& mesh = sim->mesh(m);
    const auto& id = sim->mesh_id(m);
    const MeshInfo* info = nullptr;
    for (const auto& mi : mesh_info)
      if (mi.id == id) info = &mi;
    wire::Sample<neurosim_MeshTopology> t;
    wire::set_string(t->mesh_id, id, "mesh_id");
    t->revision = 1;
    wire::set_string(t->scene_name, settings.name);
    std::vector<double> v;
    v.reserve(3 * mesh.num_vertices());
    for (const auto& x : mesh.vertices()) v.insert(v.end(), {x.x(), x.y(), x.z()});
    wire::assign(t->rest_vertices_m, v);
    std::vector<std::int32_t> tets;
    tets.reserve(4 * mesh.num_tets());
    for (const auto& te : mesh.tets()) tets.insert(tets.end(), te.begin(), te.end());
    wire::assign(t->tetrahedra, tets);
    std::vector<std::int32_t> tris;
    tris.reserve(3 * mesh.surface().size());
    for (const auto& tr : mesh.surface()) tris.insert(tris.end(), tr.begin(), tr.end());
    wire::assign(t->surface_triangles, tris);
    if (info != nullptr) {
      wire::set_string(t->material_name, info->material.name);
      t->youngs_modulus_pa = info->material.youngs_modulus_pa;
      t->poisson_ratio = info->material.poisson_ratio;
      t->priority = info->priority;
      wire::set_string(t->provenance, info->provenance);
      set_regions(*t, mesh.tet_labels(), mesh.num_tets(), *info);
    } else {
      wire::set_string(t->material_name, "");
      wire::set_string(t->provenance, "");
    }
    wire::set_string(t->volume_image_file, settings.image.file);
    t->volume_image_unit_m = settings.image.file_unit_m;
    topologies->write(*t);
    log("published MeshTopology '" + id + "': " + std::to_string(mesh.num_vertices()) +
        " vertices, " + std::to_string(mesh.num_tets()) + " tetrahedra, " +
        std::to_string(mesh.surface().size()) + " surface triangles");
  }
  // Rigid obstacles (the skull): surface only, never deformed (no Deformation frames).
  for (const scene::RigidSurface& r : rigid_surfaces) {
    wire::Sample<neurosim_MeshTopology> t;
    wire::set_string(t->mesh_id, r.id, "mesh_id");
    t->revision = 1;
    t->rigid = true;
    wire::set_string(t->scene_name, settings.name);
    std::vector<double> v;
    v.reserve(3 * r.vertices_m.size());
    for (const auto& x : r.vertices_m) v.insert(v.end(), {x.x(), x.y(), x.z()});
    wire::assign(t->rest_vertices_m, v);
    std::vector<std::int32_t> tris;
    tris.reserve(3 * r.triangles.size());
    for (const auto& tr : r.triangles) tris.insert(tris.end(), tr.begin(), tr.end());
    wire::assign(t->surface_triangles, tris);
    wire::set_string(t->material_name, "");
    wire::set_string(t->provenance, r.provenance);
    wire::set_string(t->volume_image_file, settings.image.file);
    t->volume_image_unit_m = settings.image.file_unit_m;
    topologies->write(*t);
    log("published MeshTopology '" + r.id + "' (rigid): " + std::to_string(r.vertices_m.size()) +
        " vertices, " + std::to_string(r.triangles.size()) + " surface triangles");
  }
}

// tet_region / region_names of a labelled mesh: each tetrahedron's label as the index of its
// scene tissue. Left empty when the scene names no tissues or the solved mesh's tetrahedra are
// not the labelled ones (a mesh rebuilt by the simulation).
void Server::Impl::set_regions(neurosim_MeshTopology& t, const std::vector<int>& labels,
                               std::size_t num_tets, const MeshInfo& info) {
  if (info.region_names.empty() || labels.size() != num_tets) return;
  if (info.region_names.size() > 16)
    throw std::invalid_argument("mesh '" + info.id + "': " +
                                std::to_string(info.region_names.size()) +
                                " tissues, MeshTopology carries at most 16 region names");
  std::vector<std::uint8_t> region(num_tets);
  for (std::size_t e = 0; e < num_tets; ++e) {
    const auto it = std::find(info.region_labels.begin(), info.region_labels.end(), labels[e]);
    if (it == info.region_labels.end())
      throw std::invalid_argument("mesh '" + info.id + "': tetrahedron " + std::to_string(e) +
                                  " has label " + std::to_string(labels[e]) +
                                  ", which no tissue lists");
    region[e] = static_cast<std::uint8_t>(it - info.region_labels.begin());
  }
  wire::assign(t.tet_region, region);
  wire::reserve(t.region_names, info.region_names.size());
  for (std::size_t i = 0; i < info.region_names.size(); ++i)
    wire::set_string(t.region_names._buffer[i], info.region_names[i], "region name");
  t.region_names._length = static_cast<std::uint32_t>(info.region_names.size());
}

// ---------------------------------------------------------------------------------------------
// DDS thread: samples and liveliness to the admission; every 100 ms its sweep.
void Server::Impl::dds_loop() {
  try {
    log(common::apply_to_this_thread(opt.threads.at("dds")));
    const std::size_t max_take = 64;  // wire::ReaderOptions default
    std::int64_t last_sweep = 0;
    while (run.load()) {
      const auto r = waitset->wait(DDS_MSECS(100));
      if (!run.load()) break;
      if (!tools) continue;
      for (;;) {
        const auto batch = tools->take();
        for (const auto& rx : batch) stations->handle(rx, ReceiveTime{monotonic_ns(), dds_time()});
        if (batch.size() < max_take) break;
      }
      if (r.has(2)) {
        const auto l = tools->liveliness();
        if (l.not_alive_count_change > 0) {
          log("ToolState writers lost liveliness: " + std::to_string(l.not_alive_count_change) +
              " (alive now " + std::to_string(l.alive_count) + ")");
          // The writer of the newest change: release its station at once (others: sweep).
          stations->writer_lost(l.last_publication_handle);
        }
      }
      const std::int64_t now = monotonic_ns();
      if (now - last_sweep >= 100000000) {
        last_sweep = now;
        stations->sweep(now, dds_time());
      }
    }
  } catch (const std::exception& e) {
    fail("DDS thread", e);
  }
}

// Step thread: the step loop with the status and deformation hooks.
void Server::Impl::step_thread_main() {
  try {
    log(common::apply_to_this_thread(opt.threads.at("step")));
    const std::int64_t start = monotonic_ns();
    status->begin(start);
    next_viewer_ns = start + viewer_period_ns;
    loop->run(run);
  } catch (const std::exception& e) {
    fail("step thread", e);
  }
}

void Server::Impl::dispose_all() {
  // Clients see the server leave: every instance we wrote is disposed.
  if (loop) loop->dispose_all();
  if (deformation) deformation->dispose_all();
  if (topologies)
    for (int m = 0; m < sim->num_meshes(); ++m) {
      wire::Sample<neurosim_MeshTopology> k;
      wire::set_string(k->mesh_id, sim->mesh_id(m), "mesh_id");
      topologies->dispose(*k);
    }
  if (topologies)
    for (const scene::RigidSurface& r : rigid_surfaces) {
      wire::Sample<neurosim_MeshTopology> k;
      wire::set_string(k->mesh_id, r.id, "mesh_id");
      topologies->dispose(*k);
    }
  if (status) status->dispose();
}

// ---------------------------------------------------------------------------------------------
Server::Server(const scene::Model& model, std::unique_ptr<interaction::Simulation> sim,
               ServerOptions options, std::ostream& log)
    : impl_(std::make_unique<Impl>(model, std::move(sim), std::move(options), log)) {
  impl_->configure();
}

Server::~Server() {
  try {
    stop();
  } catch (const std::exception& e) {
    impl_->log(std::string("error while stopping: ") + e.what());
  }
}

common::ThreadPlan default_server_threads() {
  common::ThreadPlan p;
  p.threads = {{"step", "ns-step", 50, {}}, {"dds", "ns-dds", 45, {}}, {"field", "ns-field", 0, {}}};
  return p;
}

void Server::start() {
  auto& d = *impl_;
  if (d.started.exchange(true)) throw std::logic_error("Server::start called twice");
  d.create_entities();
  d.publish_topologies();
  d.run = true;
  d.status->begin(monotonic_ns());
  d.status->publish(monotonic_ns());  // so SimStatus is readable before the first status period
  d.dds_thread = std::thread([&d] { d.dds_loop(); });
  d.step_thread = std::thread([&d] { d.step_thread_main(); });
  if (d.deformation)
    d.deformation->start([&d] { d.log(common::apply_to_this_thread(d.opt.threads.at("field"))); },
                         [&d](const std::exception& e) { d.fail("field worker thread", e); });
  d.log("serving (DDS domain " + (d.opt.domain >= 0 ? std::to_string(d.opt.domain) : std::string("default")) +
        ", server id '" + d.opt.server_id + "')");
}

void Server::stop() {
  auto& d = *impl_;
  if (!d.started.load() || d.stopped.exchange(true)) return;
  d.run = false;
  if (d.waitset) d.waitset->wake();
  if (d.loop) d.loop->stop();  // the step thread need not wait for its deadline
  if (d.dds_thread.joinable()) d.dds_thread.join();
  if (d.step_thread.joinable()) d.step_thread.join();
  if (d.deformation) d.deformation->stop();
  try {
    d.dispose_all();
  } catch (const std::exception& e) {
    d.log(std::string("error disposing instances: ") + e.what());
  }
  const ServerCounters c = counters();
  d.log("stopped after " + std::to_string(c.steps) + " steps (" + std::to_string(c.deadline_misses) +
        " deadline misses, rejected " + std::to_string(c.rejected_nonfinite) + " non-finite + " +
        std::to_string(c.rejected_jump) + " jump + " + std::to_string(c.rejected_workspace) +
        " workspace + " + std::to_string(c.rejected_time) + " time + " +
        std::to_string(c.rejected_sequence) + " sequence + " + std::to_string(c.rejected_identity) +
        " identity + " + std::to_string(c.rejected_rate) + " rate samples, reclaimed " +
        std::to_string(c.stations_reclaimed) + " idle stations, refused " +
        std::to_string(c.stations_refused) + " stations, evicted " + std::to_string(c.writers_evicted) +
        " writers, reset " + std::to_string(c.step_failures) + " stations after a failed step; " +
        std::to_string(c.deformation_frames) + " Deformation frames, " +
        std::to_string(c.deformation_skipped) + " viewer ticks skipped); " +
        step_mode_name(d.opt.step_mode) + " step mode: " + std::to_string(c.steps_on_sample) +
        " steps on a sample, " + std::to_string(c.steps_on_deadline) + " on the deadline");
}

bool Server::running() const { return impl_->run.load(); }

std::string Server::error() const {
  std::lock_guard<std::mutex> lk(impl_->error_mutex);
  return impl_->error_text;
}

ServerCounters Server::counters() const {
  const auto& d = *impl_;
  ServerCounters c;
  if (d.loop) {
    const auto& l = d.loop->counters();
    c.steps = l.steps.load();
    c.deadline_misses = l.deadline_misses.load();
    c.steps_on_sample = l.steps_on_sample.load();
    c.steps_on_deadline = l.steps_on_deadline.load();
    c.step_failures = l.step_failures.load();
  }
  if (d.stations) {
    const auto& a = d.stations->counters;
    c.rejected_nonfinite = a.rejected_nonfinite.load();
    c.rejected_jump = a.rejected_jump.load();
    c.stations_refused = a.stations_refused.load();
    c.rejected_workspace = a.rejected_workspace.load();
    c.rejected_time = a.rejected_time.load();
    c.rejected_sequence = a.rejected_sequence.load();
    c.rejected_identity = d.stations->rejected_identity();
    c.rejected_rate = a.rejected_rate.load();
    c.stations_reclaimed = a.stations_reclaimed.load();
    c.writers_evicted = a.writers_evicted.load();
  }
  if (d.deformation) {
    const auto& f = d.deformation->counters();
    c.deformation_frames = f.frames.load();
    c.full_field_solves = f.full_field_solves.load();
    c.deformation_skipped = f.skipped.load();
  }
  return c;
}

}  // namespace neurosim::service
