// The disk cache of a CHOLMOD supernodal factor: a second start with the same stiffness reads
// the factor of K_ff instead of analysing and factoring it again (tens of seconds on a 3 mm
// brain, bench/RESULTS.md "scale_bench"). A file is keyed by a 64-bit hash of what determines
// the factored matrix K_ff: the mesh (vertices, tetrahedra), the material map (every material's
// E, nu and element, the per-tetrahedron indices), the fixed nodes, the ordering, the CHOLMOD
// version and the key's own format version (kFactorKeyVersion), so another mesh, material,
// element, set of fixed nodes or ordering is another key, and a start that reads the factor
// need not assemble K at all. It carries a checksum of its arrays; a file with another key, other sizes, another length,
// a checksum mismatch or a structure that does not hold together is ignored (with a message when
// damaged), never used.
// The factor read is the stored one bit for bit: solves with it give bit-identical answers.
#pragma once

#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

// CHOLMOD stays out of the headers (cholmod_factor and cholmod_common are these structs).
struct cholmod_factor_struct;
struct cholmod_common_struct;

namespace neurosim::fem {

// The key's format: raised whenever what K_ff is made of changes without its inputs changing
// (the assembly's formulas, the elimination of fixed nodes, the file layout), so that files
// written before are not read. 2: the inputs of K_ff (1 was K_ff's own values).
inline constexpr std::int64_t kFactorKeyVersion = 2;

// Hash of the inputs of K_ff: the mesh's vertex coordinates and tetrahedra (with their counts),
// the material map (per material E, nu and element; the per-tetrahedron indices), the fixed
// nodes as given (StaticSolver passes them sorted and unique), the ordering (an integer naming
// it: another ordering is another factor), the CHOLMOD version and kFactorKeyVersion. A
// material's name and viscoelastic kernel do not enter K and are not hashed.
std::uint64_t factor_key(const mesh::TetMesh& mesh, const MaterialMap& materials,
                         const std::vector<int>& fixed_nodes, int ordering);

// The cache file of `key` in `dir` (dir/factor_<key hex>.bin).
std::string factor_file(const std::string& dir, std::uint64_t key);

struct FactorLoad {
  cholmod_factor_struct* factor{nullptr};  // the factor read (owned by the caller), or null
  double factor_bytes{0.0};  // a matching file's factor size (values + structure), unit byte
  bool too_large{false};     // a matching file whose factor exceeds max_bytes (not read)
  double lnz{0.0};           // nnz(L) as CHOLMOD's analysis counted it (Common::lnz)
};

// Reads the supernodal LL^T factor stored in `file` under `key` for an n x n matrix, allocated
// with `common` (free it with cholmod_free_factor on the same common). No factor if there is no
// file, it does not match, or its factor needs more than max_bytes (unit byte; too_large says
// so, before anything is allocated).
FactorLoad load_factor(const std::string& file, std::uint64_t key, std::size_t n,
                       double max_bytes, cholmod_common_struct& common);

// Stores a numeric supernodal LL^T factor (written under a per-process temporary name, then
// renamed: a concurrent reader sees the old file or the whole new one). A failure (disk full,
// read-only folder) is reported on stderr, the temporary removed, and otherwise ignored: the
// cache only saves time. Another kind of factor (simplicial) is not stored.
void save_factor(const std::string& file, std::uint64_t key, const cholmod_factor_struct& factor,
                 double lnz);

}  // namespace neurosim::fem
