// Scene -> Model: meshes built, node sets resolved, couplings checked (see compile.hpp).
#include "server/scene/compile.hpp"

#include "common/process_stats.hpp"
#include "server/mesh/generate.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/text_reader.hpp"
#include "server/mesh/tri_surface.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

namespace neurosim::scene {

fem::Material to_material(const Material& material, const std::string& what) {
  fem::Material m;
  m.youngs_modulus_pa = material.youngs_modulus_pa();
  m.poisson_ratio = material.poisson_ratio();
  m.name = material.name().empty() ? what : material.name();
  if (material.element().empty()) {
    m.element = fem::kDefaultSceneElement;
  } else if (const auto e = fem::parse_element(material.element())) {
    m.element = *e;
  } else {
    throw std::runtime_error(what + ".element: unknown element \"" + material.element() +
                             "\" (known: " + fem::element_names() + ")");
  }
  m.viscoelastic = to_viscoelastic(material.viscoelastic());
  try {
    m.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(what + ": " + e.what());
  }
  return m;
}

fem::Viscoelastic to_viscoelastic(const Viscoelastic& v) {
  fem::Viscoelastic out;
  out.source = v.source();
  for (const auto& t : v.terms()) out.terms.push_back(fem::PronyTerm{t.g(), t.tau_s()});
  return out;
}

std::vector<int> select_nodes(const mesh::TetMesh& mesh, const Region& region,
                              const std::string& what) {
  std::vector<int> nodes;
  const auto& x = mesh.vertices();
  const int n = static_cast<int>(x.size());
  switch (region.select_case()) {
    case Region::kNodes:
      for (int id : region.nodes().ids()) {
        if (id < 0 || id >= n) {
          throw std::runtime_error(what + ": node id " + std::to_string(id) +
                                   " out of range (mesh has " + std::to_string(n) + " nodes)");
        }
        nodes.push_back(id);
      }
      break;
    case Region::kBox: {
      const auto lo = to_vec3(region.box().min_m()), hi = to_vec3(region.box().max_m());
      for (int i = 0; i < n; ++i) {
        if ((x[i].array() >= lo.array()).all() && (x[i].array() <= hi.array()).all()) {
          nodes.push_back(i);
        }
      }
      break;
    }
    case Region::kHalfSpace: {
      const auto p = to_vec3(region.half_space().point_m());
      const auto nrm = to_vec3(region.half_space().normal()).normalized();
      for (int i = 0; i < n; ++i) {
        if ((x[i] - p).dot(nrm) <= 0.0) nodes.push_back(i);
      }
      break;
    }
    case Region::SELECT_NOT_SET:
      throw std::runtime_error(what + ": empty region");
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  if (nodes.empty()) throw std::runtime_error(what + ": region selects no node");
  return nodes;
}

namespace {

// Refuses a mesh of `vertices` whose load and simulation build would need more memory than this
// process can get (mesh::expected_load_bytes against common::memory_available_bytes), naming
// `what` (the scene, the mesh, the field or file), the estimate and the bound.
void check_load_memory(double vertices, const std::string& what, const std::string& fix) {
  const char* bound = nullptr;
  const double available = common::memory_available_bytes(&bound);
  const double need = mesh::expected_load_bytes(vertices);
  if (need <= available) return;
  std::ostringstream msg;
  msg.precision(3);
  msg << what << ": loading a mesh of about " << vertices
      << " vertices and building its simulation needs about " << need / 1e9 << " GB ("
      << mesh::kLoadBytesPerVertex / 1e3 << " kB per vertex, measured), but this process can get "
      << available / 1e9 << " GB (" << bound << "): " << fix;
  throw std::runtime_error(msg.str());
}

}  // namespace

LoadedMesh load_mesh(const Mesh& entry, const std::filesystem::path& scene_dir,
                     const std::string& source, GeneratedMeshes* generated_meshes) {
  const std::string what = source + ": mesh \"" + entry.id() + "\"";
  LoadedMesh out;
  out.id = entry.id();
  out.material = to_material(entry.material(), what + " material");
  out.priority = entry.priority();
  out.provenance = entry.provenance();
  out.material_source = entry.material().source();
  if (entry.source_case() == Mesh::kFile) {
    std::filesystem::path file = entry.file();
    if (file.is_relative()) file = scene_dir / file;
    const double unit = entry.has_file_unit_m() ? entry.file_unit_m() : 1.0;
    mesh::MeshData data = mesh::read_mesh(file.string(), unit);
    check_load_memory(static_cast<double>(data.vertices_m.size()), what + ": " + file.string(),
                      "use a coarser mesh or a machine with more memory");
    if (entry.labels_size() > 0) {
      // Keep only the tetrahedra of the requested subdomains.
      std::set<int> keep(entry.labels().begin(), entry.labels().end());
      std::vector<mesh::Tet> tets;
      std::vector<int> labels;
      for (std::size_t t = 0; t < data.tets.size(); ++t) {
        if (keep.count(data.tet_labels[t])) {
          tets.push_back(data.tets[t]);
          labels.push_back(data.tet_labels[t]);
        }
      }
      if (tets.empty()) throw std::runtime_error(what + ": no tetrahedron has the given labels");
      data.tets = std::move(tets);
      data.tet_labels = std::move(labels);
    }
    mesh::BuildOptions build;
    build.source = file.string();
    out.mesh = mesh::guard_out_of_memory(file.string(), [&] {
      return mesh::TetMesh::build(std::move(data.vertices_m), std::move(data.tets), build);
    });
    out.mesh.set_tet_labels(std::move(data.tet_labels));
  } else {
    const auto& g = entry.generate();
    mesh::MeshingOptions options;
    options.target_vertices = g.target_vertices();
    options.cell_size_m = g.cell_size_m();
    options.seed = g.seed();
    // An absurd size is refused before the mesher runs, naming the scene field (a cell size of
    // a micrometre in a box of centimetres would mesh for days).
    const double r = g.cylinder().radius_m();
    const mesh::Vec3 extent =
        g.has_box() ? mesh::Vec3(to_vec3(g.box().max_m()) - to_vec3(g.box().min_m()))
                    : mesh::Vec3(2 * r, 2 * r, to_vec3(g.cylinder().axis_m()).norm());
    const double expected = mesh::expected_tetrahedra(extent, options);
    if (!(expected <= options.max_tetrahedra)) {
      std::ostringstream msg;
      msg.precision(3);
      msg << what << ": generate."
          << (options.target_vertices > 0 ? "target_vertices" : "cell_size_m") << ": about "
          << expected << " tetrahedra expected, above the limit of " << options.max_tetrahedra
          << " (give a larger cell_size_m or fewer target_vertices)";
      throw std::runtime_error(msg.str());
    }
    // Memory: refused before the mesher runs (a mesh within the limits above can still be far
    // too large for this machine).
    const double vertices = options.target_vertices > 0
                                ? static_cast<double>(options.target_vertices)
                                : expected / mesh::kTetsPerVertex;
    check_load_memory(vertices,
                      what + ": generate." +
                          (options.target_vertices > 0
                               ? "target_vertices: " + std::to_string(options.target_vertices)
                               : std::string("cell_size_m")),
                      options.target_vertices > 0 ? "give fewer target_vertices"
                                                  : "give a larger cell_size_m");
    const auto generate = [&] {
      return g.has_box()
                 ? mesh::generate_box(to_vec3(g.box().min_m()), to_vec3(g.box().max_m()), options)
                 : mesh::generate_cylinder(to_vec3(g.cylinder().base_center_m()),
                                           to_vec3(g.cylinder().axis_m()), r, options);
    };
    mesh::GeneratedMesh generated;
    try {
      generated = generated_meshes != nullptr ? generated_meshes->get(g, generate) : generate();
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(what + ": generate: " + e.what());
    } catch (const std::bad_alloc&) {
      throw std::runtime_error(what + ": generate: out of memory while meshing");
    }
    out.mesh = std::move(generated.mesh);
    out.generator_cell_size_m = generated.cell_size_m;
  }
  for (int r = 0; r < entry.fixed_size(); ++r) {
    auto nodes = select_nodes(out.mesh, entry.fixed(r), what + " fixed[" + std::to_string(r) + "]");
    out.fixed_nodes.insert(out.fixed_nodes.end(), nodes.begin(), nodes.end());
  }
  std::sort(out.fixed_nodes.begin(), out.fixed_nodes.end());
  out.fixed_nodes.erase(std::unique(out.fixed_nodes.begin(), out.fixed_nodes.end()),
                        out.fixed_nodes.end());
  resolve_tissues(entry, what, out);
  return out;
}

void resolve_tissues(const Mesh& entry, const std::string& what, LoadedMesh& out) {
  out.materials = fem::MaterialMap::uniform(out.material);
  out.tissues.clear();
  if (entry.tissues_size() == 0) return;
  // materials[0] is the mesh's; a tissue with its own material adds one.
  std::vector<fem::Material> materials{out.material};
  std::vector<int> material_of_tissue;
  bool any_own = false;
  for (int k = 0; k < entry.tissues_size(); ++k) {
    const auto& t = entry.tissues(k);
    TissueDef d;
    d.label = t.label();
    d.name = t.name();
    d.provenance = t.provenance();
    d.own_material = t.has_material();
    d.material = out.material;
    d.material_source = out.material_source;
    if (d.own_material) {
      d.material = to_material(t.material(), what + " tissues[" + std::to_string(k) + "] (" +
                                                 t.name() + ") material");
      d.material_source = t.material().source();
      if (t.material().element().empty()) d.material.element = out.material.element;
      // One relaxation kernel per mesh: a tissue's material without one takes the mesh's.
      if (!t.material().has_viscoelastic()) {
        d.material.viscoelastic = out.material.viscoelastic;
      } else if (!d.material.viscoelastic.same_kernel(out.material.viscoelastic)) {
        throw std::runtime_error(what + " tissues[" + std::to_string(k) + "] (" + t.name() +
                                 ") material.viscoelastic: differs from the mesh's (one relaxation "
                                 "kernel per mesh; leave it out to take the mesh's)");
      }
      materials.push_back(d.material);
      any_own = true;
    }
    material_of_tissue.push_back(d.own_material ? static_cast<int>(materials.size()) - 1 : 0);
    out.tissues.push_back(std::move(d));
  }
  // Every tetrahedron belongs to a listed tissue: an unnamed label is a mismatch between the
  // scene and the mesh file, not a default.
  const auto& labels = out.mesh.tet_labels();
  std::vector<int> tet_material(out.mesh.num_tets(), 0);
  for (std::size_t t = 0; t < out.mesh.num_tets(); ++t) {
    const int label = t < labels.size() ? labels[t] : 0;
    int k = 0;
    while (k < static_cast<int>(out.tissues.size()) && out.tissues[k].label != label) ++k;
    if (k == static_cast<int>(out.tissues.size()))
      throw std::runtime_error(what + ": tetrahedron " + std::to_string(t) + " has label " +
                               std::to_string(label) + ", which no tissue lists");
    tet_material[t] = material_of_tissue[k];
  }
  if (any_own) out.materials = fem::MaterialMap::per_tet(std::move(materials), std::move(tet_material));
}

RigidSurface load_rigid(const Mesh& entry, const std::filesystem::path& scene_dir,
                        const std::string& source) {
  const std::string what = source + ": mesh \"" + entry.id() + "\" (rigid)";
  std::filesystem::path file = entry.file();
  if (file.is_relative()) file = scene_dir / file;
  const double unit = entry.has_file_unit_m() ? entry.file_unit_m() : 1.0;
  mesh::MeshData data = mesh::read_medit_surface(file.string(), unit);
  mesh::require_closed_outward(data.vertices_m, data.triangles, file.string() + " (" + what + ")");
  RigidSurface r;
  r.id = entry.id();
  r.file = file.string();
  r.provenance = entry.provenance();
  r.vertices_m = std::move(data.vertices_m);
  r.triangles = std::move(data.triangles);
  r.enclosed_volume_m3 = mesh::check_closed(r.vertices_m, r.triangles).volume_m3;
  for (const auto& o : entry.openings()) {
    RigidOpening d;
    d.center_m = to_vec3(o.center_m());
    d.axis = to_vec3(o.axis()).normalized();
    d.radius_m = o.radius_m();
    d.half_length_m = o.half_length_m();
    d.provenance = o.provenance();
    r.openings.push_back(std::move(d));
  }
  return r;
}

namespace {

// Plausible size of one mesh of a surgical scene: the bounding-box diagonal of a head is about
// 0.3 m and the smallest structure worth meshing (a vessel segment) about a millimetre, so a
// mesh outside [kMinMeshDiagonalM, kMaxMeshDiagonalM] was almost certainly read in the wrong unit
// (a file in mm read as m is 1000 times too large). A warning, not an error: the physics runs in
// any unit, only the scene is wrong.
constexpr double kMaxMeshDiagonalM = 2.0;
constexpr double kMinMeshDiagonalM = 1e-3;

// The size check of one built mesh; "" when its size is plausible.
std::string size_warning(const Mesh& entry, const LoadedMesh& lm, const std::string& source) {
  mesh::Vec3 lo, hi;
  lm.mesh.bounds(lo, hi);
  const mesh::Vec3 extent = hi - lo;
  const double diagonal = extent.norm();
  if (diagonal <= kMaxMeshDiagonalM && diagonal >= kMinMeshDiagonalM) return "";
  const bool large = diagonal > kMaxMeshDiagonalM;
  std::ostringstream w;
  w.precision(4);
  w << source << ": mesh \"" << lm.id << "\": bounding box " << extent.x() << " x " << extent.y()
    << " x " << extent.z() << " m (diagonal " << diagonal << " m) is "
    << (large ? "larger than " : "smaller than ") << (large ? kMaxMeshDiagonalM : kMinMeshDiagonalM)
    << " m, implausible for a surgical scene: ";
  if (entry.source_case() == Mesh::kFile) {
    const double unit = entry.has_file_unit_m() ? entry.file_unit_m() : 1.0;
    if (large && unit == 1.0) {
      w << "is the file in mm? set file_unit_m: 0.001 on the mesh";
    } else if (!large && unit != 1.0) {
      w << "is the file already in m? file_unit_m is " << unit
        << " (file coordinates x file_unit_m must be metres; remove it for a file in m)";
    } else {
      w << "check the file's unit: file coordinates x file_unit_m (" << unit << ") must be metres";
    }
  } else {
    w << "the generator's sizes are in m (is the box or cylinder given in mm? divide by 1000)";
  }
  return w.str();
}

CouplingDef compile_coupling(const Scene& scene, const Model& model, int c,
                             const std::string& source) {
  const auto& cp = scene.couplings(c);
  const std::string what = source + ": couplings[" + std::to_string(c) + "] (" + cp.host() +
                           " / " + cp.embedded() + ")";
  CouplingDef def;
  def.host = model.find_mesh(cp.host());
  def.embedded = model.find_mesh(cp.embedded());
  if (def.host < 0 || def.embedded < 0 || def.host == def.embedded)
    throw std::runtime_error(what + ": unknown or identical meshes");
  switch (cp.kind()) {
    case Coupling::TIE: def.kind = CouplingKind::kTie; break;
    case Coupling::SLIDING: def.kind = CouplingKind::kSliding; break;
    default:
      throw std::runtime_error(what + ": unknown coupling kind " + std::to_string(cp.kind()));
  }
  switch (cp.method()) {
    case Coupling::EXACT: def.method = CouplingMethod::kExact; break;
    case Coupling::ITERATIVE: def.method = CouplingMethod::kIterative; break;
    default:
      throw std::runtime_error(what + ": unknown coupling method " + std::to_string(cp.method()));
  }
  if (def.kind == CouplingKind::kSliding && def.method == CouplingMethod::kIterative) {
    throw std::runtime_error(what +
                             ": method ITERATIVE is the tie baseline; SLIDING is solved exactly "
                             "(method EXACT)");
  }
  // Priority decides which mesh gets the new boundary (paper 2.4): the embedded mesh (the vessel)
  // has the higher one; equal priorities would make the overlap ambiguous.
  const int ph = model.meshes[def.host].priority, pe = model.meshes[def.embedded].priority;
  if (ph == pe) {
    throw std::runtime_error(what + ": equal priorities (" + std::to_string(ph) +
                             ") make the overlap ambiguous; the embedded mesh needs the higher one");
  }
  if (ph > pe) {
    throw std::runtime_error(what + ": the host must have the lower priority (host " +
                             std::to_string(ph) + ", embedded " + std::to_string(pe) + ")");
  }
  return def;
}

}  // namespace

Model compile(const Scene& scene, const std::string& source, GeneratedMeshes* generated_meshes) {
  validate_scene(scene, source);
  Model model;
  static_cast<Settings&>(model) = read_settings(scene, source);
  const std::filesystem::path dir = std::filesystem::path(source).parent_path();
  for (int i = 0; i < scene.meshes_size(); ++i) {
    if (scene.meshes(i).rigid()) {
      model.rigid.push_back(load_rigid(scene.meshes(i), dir, source));
      continue;
    }
    model.meshes.push_back(load_mesh(scene.meshes(i), dir, source, generated_meshes));
    std::string w = size_warning(scene.meshes(i), model.meshes.back(), source);
    if (!w.empty()) model.warnings.push_back(std::move(w));
  }

  // Couplings: roles, one host per embedded mesh, no nesting.
  std::vector<int> host_of(model.meshes.size(), -1);
  std::vector<char> is_host(model.meshes.size(), 0);
  for (int c = 0; c < scene.couplings_size(); ++c) {
    const CouplingDef def = compile_coupling(scene, model, c, source);
    if (host_of[def.embedded] >= 0) {
      throw std::runtime_error(source + ": couplings[" + std::to_string(c) + "]: mesh " +
                               model.meshes[def.embedded].id + " is embedded twice");
    }
    host_of[def.embedded] = def.host;
    is_host[def.host] = 1;
    model.couplings.push_back(def);
    // A tied body relaxes with its host's kernel (server/interaction/viscoelastic_history.hpp).
    const auto& hv = model.meshes[def.host].material.viscoelastic;
    const auto& ev = model.meshes[def.embedded].material.viscoelastic;
    if (def.kind == CouplingKind::kTie && model.effects.coupling && !hv.same_kernel(ev)) {
      model.warnings.push_back(
          source + ": couplings[" + std::to_string(c) + "]: mesh " + model.meshes[def.embedded].id +
          " is tied to " + model.meshes[def.host].id +
          " whose relaxation kernel differs; the tied body relaxes with the host's kernel "
          "(exact only for a shared kernel; docs/accuracy.md bounds the approximation)");
    }
  }
  for (std::size_t m = 0; m < model.meshes.size(); ++m) {
    if (is_host[m] && host_of[m] >= 0) {
      throw std::runtime_error(source + ": mesh " + model.meshes[m].id +
                               " is both host and embedded (nested couplings are not supported)");
    }
    if (is_host[m] && model.effects.coupling && model.meshes[m].fixed_nodes.empty()) {
      throw std::runtime_error(source + ": host mesh " + model.meshes[m].id +
                               " has no fixed nodes (it must hold its embedded meshes)");
    }
  }
  if (model.effects.tool_contact && model.tools.empty())
    throw std::runtime_error(source + ": effects.tool_contact is set but the scene has no tools");

  // Loads and prescribed displacements, resolved on the meshes they name.
  for (int i = 0; i < scene.loads_size(); ++i) {
    const auto& l = scene.loads(i);
    LoadDef def;
    def.mesh = model.find_mesh(l.mesh());
    const auto& lm = model.meshes[def.mesh];
    def.nodes = select_nodes(lm.mesh, l.region(), source + ": loads[" + std::to_string(i) + "]");
    def.force_per_node_n = to_vec3(l.force_n());
    if (l.distribution() == Load::TOTAL_SPLIT_EQUALLY)
      def.force_per_node_n /= static_cast<double>(def.nodes.size());
    model.loads.push_back(std::move(def));
  }
  for (int i = 0; i < scene.prescribed_size(); ++i) {
    const auto& p = scene.prescribed(i);
    const std::string what = source + ": prescribed[" + std::to_string(i) + "]";
    PrescribedDef def;
    def.mesh = model.find_mesh(p.mesh());
    def.nodes = select_nodes(model.meshes[def.mesh].mesh, p.region(), what);
    def.displacement_m = to_vec3(p.displacement_m());
    if (!p.components().empty()) {
      def.components = {false, false, false};
      for (char c : p.components()) def.components[c - 'x'] = true;
    }
    // A node held twice with different values is a contradiction, not a choice.
    for (std::size_t j = 0; j < model.prescribed.size(); ++j) {
      const auto& other = model.prescribed[j];
      if (other.mesh != def.mesh) continue;
      std::vector<int> both;
      std::set_intersection(def.nodes.begin(), def.nodes.end(), other.nodes.begin(),
                            other.nodes.end(), std::back_inserter(both));
      for (int node : both) {
        for (int a = 0; a < 3; ++a) {
          if (def.components[a] && other.components[a] &&
              def.displacement_m[a] != other.displacement_m[a]) {
            throw std::runtime_error(what + ": node " + std::to_string(node) + " of mesh " +
                                     p.mesh() + " is also held by prescribed[" +
                                     std::to_string(j) + "] with another " +
                                     std::string(1, static_cast<char>('x' + a)) + " value");
          }
        }
      }
    }
    // Fixed (all components zero) and prescribed: refused unless the prescribed value is zero.
    const auto& fixed = model.meshes[def.mesh].fixed_nodes;
    std::vector<int> both;
    std::set_intersection(def.nodes.begin(), def.nodes.end(), fixed.begin(), fixed.end(),
                          std::back_inserter(both));
    if (!both.empty()) {
      throw std::runtime_error(what + ": node " + std::to_string(both.front()) + " of mesh " +
                               p.mesh() + " is both fixed and prescribed");
    }
    model.prescribed.push_back(std::move(def));
  }
  return model;
}

Model load_model(const std::filesystem::path& path) {
  return compile(read_scene(path), path.string());
}

}  // namespace neurosim::scene
