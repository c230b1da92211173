// The factor's disk cache (SolverOptions::factor_cache_dir): a second solver of the same matrix
// reads the factor and answers bit for bit as the one that factored it (and as one without the
// cache) without assembling K until it is asked for; the key is made of K_ff's inputs, and
// another vertex, material, element, per-tetrahedron material, set of fixed nodes or ordering
// misses; a damaged, truncated or foreign file is ignored with a message, never used; a too
// large cached factor is still refused.
#include "server/fem/static_solver.hpp"

#include "server/fem/factor_cache.hpp"

#include "fem_test_meshes.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

namespace neurosim::fem {
namespace {

namespace fs = std::filesystem;
using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

const Material kBrain{1.0e6, 0.45, "brain"};

mesh::TetMesh cube(unsigned seed = 3) {
  return box_mesh(BoxSpec{6, 5, 7, {0, 0, 0}, {0.1, 0.08, 0.12}, 0.2, seed});
}

std::vector<int> bottom(const mesh::TetMesh& m) {
  return nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
}

SolverOptions cached_in(const fs::path& dir) {
  SolverOptions o;
  o.factor_cache_dir = dir.string();
  return o;
}

// Forces on every node, different per node (N).
Eigen::VectorXd load(const StaticSolver& s) {
  Eigen::VectorXd f(s.num_dofs());
  for (int i = 0; i < f.size(); ++i) f[i] = 0.01 * std::sin(0.37 * i + 0.1);
  return f;
}

bool same_bits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

std::vector<fs::path> files_in(const fs::path& dir) {
  std::vector<fs::path> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path());
  return out;
}

TEST(fem_factor_cache, SecondSolverReadsTheSameFactor) {
  const auto dir = neurosim::testing::temp_dir("factor_cache");
  const auto m = cube();
  const StaticSolver plain(m, MaterialMap::uniform(kBrain), bottom(m));
  const StaticSolver first(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir));
  EXPECT_FALSE(first.factor_info().from_cache);
  ASSERT_EQ(files_in(dir).size(), 1u);
  const StaticSolver second(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir));
  EXPECT_TRUE(second.factor_info().from_cache);
  EXPECT_EQ(second.factor_info().analyze_s, 0.0);
  EXPECT_EQ(second.factor_info().factorize_s, 0.0);
  for (const StaticSolver* s : {&first, &second}) {
    EXPECT_EQ(s->factor_info().factor_nnz, plain.factor_info().factor_nnz);
    EXPECT_EQ(s->factor_info().factor_bytes, plain.factor_info().factor_bytes);
    EXPECT_EQ(s->factor_info().rcond, plain.factor_info().rcond);
  }
  // One right-hand side and a block of them: bit for bit.
  const Eigen::VectorXd f = load(plain);
  const Eigen::VectorXd u = plain.solve(f);
  EXPECT_TRUE(same_bits(first.solve(f), u));
  EXPECT_TRUE(same_bits(second.solve(f), u));
  Eigen::MatrixXd b = Eigen::MatrixXd::Random(plain.num_free_dofs(), 70), x_plain, x_cached;
  plain.solve_reduced(b, x_plain);
  second.solve_reduced(b, x_cached);
  EXPECT_TRUE(same_bits(x_plain, x_cached));
  fs::remove_all(dir);
}

// The same mesh with one interior vertex moved by `delta_m` along x.
mesh::TetMesh with_vertex_moved(const mesh::TetMesh& m, double delta_m) {
  std::vector<mesh::Vec3> x = m.vertices();
  int v = 0;
  while (std::binary_search(m.surface_vertices().begin(), m.surface_vertices().end(), v)) ++v;
  x[v].x() += delta_m;
  return mesh::TetMesh::build(std::move(x), m.tets());
}

bool same_matrix(const SparseMatrix& a, const SparseMatrix& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() && a.nonZeros() == b.nonZeros() &&
         std::equal(a.outerIndexPtr(), a.outerIndexPtr() + a.cols() + 1, b.outerIndexPtr()) &&
         std::equal(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros(), b.innerIndexPtr()) &&
         std::memcmp(a.valuePtr(), b.valuePtr(), sizeof(double) * a.nonZeros()) == 0;
}

TEST(fem_factor_cache, KeyIsMadeOfTheInputsOfK) {
  const auto m = cube();
  const auto fixed = bottom(m);
  const auto uniform = MaterialMap::uniform(kBrain);
  const int order = static_cast<int>(FactorOrdering::kNodeMetis);
  const std::uint64_t base = factor_key(m, uniform, fixed, order);
  EXPECT_EQ(factor_key(cube(), uniform, fixed, order), base);  // the same inputs again
  // What does not enter K: the name, the relaxation kernel.
  Material renamed = kBrain;
  renamed.name = "other";
  renamed.viscoelastic.terms.push_back({0.5, 0.1});
  EXPECT_EQ(factor_key(m, MaterialMap::uniform(renamed), fixed, order), base);
  // Each input of K_ff changed alone.
  std::vector<std::uint64_t> keys{base};
  keys.push_back(factor_key(with_vertex_moved(m, 1e-6), uniform, fixed, order));
  keys.push_back(factor_key(m, MaterialMap::uniform({1.0e6 * (1 + 1e-12), 0.45, "brain"}), fixed,
                            order));
  keys.push_back(factor_key(m, MaterialMap::uniform({1.0e6, 0.46, "brain"}), fixed, order));
  Material anp = kBrain;
  anp.element = Element::kAnpTet;
  keys.push_back(factor_key(m, MaterialMap::uniform(anp), fixed, order));
  std::vector<int> tet_material(m.num_tets(), 0);
  tet_material[5] = 1;
  keys.push_back(factor_key(
      m, MaterialMap::per_tet({kBrain, {2.0e6, 0.45, "stiff"}}, tet_material), fixed, order));
  auto fewer = fixed;
  fewer.pop_back();
  keys.push_back(factor_key(m, uniform, fewer, order));
  auto other = fixed;
  other.back() += 1;
  keys.push_back(factor_key(m, uniform, other, order));
  keys.push_back(factor_key(m, uniform, fixed, static_cast<int>(FactorOrdering::kAmd)));
  std::vector<std::uint64_t> distinct = keys;
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  EXPECT_EQ(distinct.size(), keys.size());
}

TEST(fem_factor_cache, HitAssemblesKOnlyWhenAskedFor) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_lazy");
  const auto m = cube();
  const StaticSolver plain(m, MaterialMap::uniform(kBrain), bottom(m));
  { const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir)); }
  SolverOptions checked = cached_in(dir);
  const StaticSolver hit(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir));
  ASSERT_TRUE(hit.factor_info().from_cache);
  EXPECT_EQ(hit.factor_info().assembly_s, 0.0);
  EXPECT_EQ(hit.factor_info().stiffness_nnz, 0);
  // What needs K assembles it then: reactions, the residual check, K itself; all as without
  // the cache, bit for bit.
  const auto top = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.12 - 1e-9; });
  const Eigen::VectorXd down = Eigen::VectorXd::Constant(3 * static_cast<int>(top.size()), -1e-3);
  const PrescribedSolution a = plain.solve_prescribed(top, down);
  const PrescribedSolution b = hit.solve_prescribed(top, down);
  EXPECT_TRUE(same_bits(a.displacement_m, b.displacement_m));
  EXPECT_TRUE(same_bits(a.reaction_n, b.reaction_n));
  EXPECT_TRUE(same_matrix(hit.stiffness(), plain.stiffness()));
  checked.check_residual = true;
  const StaticSolver residual(m, MaterialMap::uniform(kBrain), bottom(m), checked);
  ASSERT_TRUE(residual.factor_info().from_cache);
  EXPECT_TRUE(same_bits(residual.solve(load(plain)), plain.solve(load(plain))));
  fs::remove_all(dir);
}

TEST(fem_factor_cache, AnotherVertexElementTetMaterialOrOrderingMisses) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_miss_inputs");
  const auto m = cube();
  const auto fixed = bottom(m);
  { const StaticSolver s(m, MaterialMap::uniform(kBrain), fixed, cached_in(dir)); }
  auto misses = [&](const mesh::TetMesh& mesh, const MaterialMap& materials,
                    const SolverOptions& options, const char* what) {
    const StaticSolver s(mesh, materials, fixed, options);
    EXPECT_FALSE(s.factor_info().from_cache) << what;
    // And answers its own problem: as without the cache.
    SolverOptions plain_options = options;
    plain_options.factor_cache_dir.clear();
    const StaticSolver plain(mesh, materials, fixed, plain_options);
    EXPECT_TRUE(same_bits(s.solve(load(s)), plain.solve(load(plain)))) << what;
  };
  misses(with_vertex_moved(m, 1e-6), MaterialMap::uniform(kBrain), cached_in(dir), "vertex");
  Material anp = kBrain;
  anp.element = Element::kAnpTet;
  misses(m, MaterialMap::uniform(anp), cached_in(dir), "element");
  std::vector<int> tet_material(m.num_tets(), 0);
  tet_material[7] = 1;
  misses(m, MaterialMap::per_tet({kBrain, {3.0e6, 0.45, "stiff"}}, tet_material), cached_in(dir),
         "one tetrahedron's material");
  SolverOptions amd = cached_in(dir);
  amd.ordering = FactorOrdering::kAmd;
  misses(m, MaterialMap::uniform(kBrain), amd, "ordering");
  EXPECT_EQ(files_in(dir).size(), 5u);
  // The first problem still hits.
  const StaticSolver again(m, MaterialMap::uniform(kBrain), fixed, cached_in(dir));
  EXPECT_TRUE(again.factor_info().from_cache);
  fs::remove_all(dir);
}

TEST(fem_factor_cache, AnotherMaterialMeshOrSupportMisses) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_miss");
  const auto m = cube();
  { const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir)); }
  const Material stiffer{1.1e6, 0.45, "brain"};
  const StaticSolver e(m, MaterialMap::uniform(stiffer), bottom(m), cached_in(dir));
  EXPECT_FALSE(e.factor_info().from_cache);
  const auto moved = cube(4);  // other jitter: the same pattern, other values
  const StaticSolver v(moved, MaterialMap::uniform(kBrain), bottom(moved), cached_in(dir));
  EXPECT_FALSE(v.factor_info().from_cache);
  auto fixed = bottom(m);
  fixed.pop_back();
  const StaticSolver f(m, MaterialMap::uniform(kBrain), fixed, cached_in(dir));
  EXPECT_FALSE(f.factor_info().from_cache);
  EXPECT_EQ(files_in(dir).size(), 4u);
  // Each answers its own problem: the same as without the cache.
  const StaticSolver ref(m, MaterialMap::uniform(stiffer), bottom(m));
  EXPECT_TRUE(same_bits(e.solve(load(e)), ref.solve(load(ref))));
  fs::remove_all(dir);
}

TEST(fem_factor_cache, DamagedFilesAreIgnored) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_damage");
  const auto m = cube();
  const StaticSolver plain(m, MaterialMap::uniform(kBrain), bottom(m));
  const Eigen::VectorXd u = plain.solve(load(plain));
  { const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir)); }
  const fs::path file = files_in(dir).at(0);
  const auto size = fs::file_size(file);
  auto reload = [&](const char* expected_message) {
    ::testing::internal::CaptureStderr();
    const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir));
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_FALSE(s.factor_info().from_cache) << expected_message;
    EXPECT_NE(err.find(expected_message), std::string::npos) << err;
    EXPECT_TRUE(same_bits(s.solve(load(s)), u));
  };
  // One value of the factor flipped on disk.
  {
    std::fstream io(file, std::ios::in | std::ios::out | std::ios::binary);
    io.seekp(static_cast<std::streamoff>(size - 100));
    char c = 0;
    io.read(&c, 1);
    c = static_cast<char>(c ^ 0x10);
    io.seekp(static_cast<std::streamoff>(size - 100));
    io.write(&c, 1);
  }
  reload("checksum mismatch");  // and rewritten whole
  ASSERT_EQ(fs::file_size(file), size);
  fs::resize_file(file, size - 8);
  reload("length does not match");
  // Another matrix's file under this one's name (its key inside differs): a miss, said nothing.
  const auto dir2 = neurosim::testing::temp_dir("factor_cache_other");
  const Material stiffer{1.1e6, 0.45, "brain"};
  { const StaticSolver s(m, MaterialMap::uniform(stiffer), bottom(m), cached_in(dir2)); }
  fs::copy_file(files_in(dir2).at(0), file, fs::copy_options::overwrite_existing);
  {
    ::testing::internal::CaptureStderr();
    const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir));
    EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
    EXPECT_FALSE(s.factor_info().from_cache);
    EXPECT_TRUE(same_bits(s.solve(load(s)), u));
  }
  fs::remove_all(dir2);
  fs::remove_all(dir);
}

TEST(fem_factor_cache, CachedFactorTooLargeIsStillRefused) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_large");
  const auto m = cube();
  { const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(dir)); }
  SolverOptions small = cached_in(dir);
  small.max_factor_bytes = 1000.0;
  EXPECT_THROW(StaticSolver(m, MaterialMap::uniform(kBrain), bottom(m), small), FactorTooLarge);
  fs::remove_all(dir);
}

TEST(fem_factor_cache, UnwritableFolderOnlyCostsTheCache) {
  const auto dir = neurosim::testing::temp_dir("factor_cache_unwritable");
  const fs::path not_a_folder = dir / "file";
  std::ofstream(not_a_folder) << "x";
  const auto m = cube();
  ::testing::internal::CaptureStderr();
  const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), cached_in(not_a_folder));
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("could not write factor cache"), std::string::npos) << err;
  const StaticSolver plain(m, MaterialMap::uniform(kBrain), bottom(m));
  EXPECT_TRUE(same_bits(s.solve(load(s)), plain.solve(load(plain))));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::fem
