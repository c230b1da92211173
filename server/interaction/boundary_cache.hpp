// The boundary operator of a coupled body and its disk cache: a second start with the same
// meshes, materials, fixed nodes and coupling map reads the operator instead of recomputing the
// boundary compliance solves (seconds on a brain-sized host). Files are keyed by a 64-bit FNV-1a
// hash of everything the operator depends on, and carry a checksum of the matrices; a file with
// another key, other sizes, another length, a checksum mismatch or non-finite values is ignored
// (with a message when damaged), never used.
#pragma once

#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace neurosim::interaction {

// L_A[b, b] (3m x 3m, unit m/N), L_A[contact dofs, b] (3s x 3m, unit m/N), K_add = sum over
// ties of J^T S_B J (3m x 3m, unit N/m), G = (I + K_add L_bb)^-1 K_add (3m x 3m, unit N/m).
struct BoundaryOperator {
  Eigen::MatrixXd l_bb;
  Eigen::MatrixXd l_sb;
  Eigen::MatrixXd k_add;
  Eigen::MatrixXd g;
};

// FNV-1a over the bytes of what is added (sizes included, so [1,2],[3] != [1],[2,3]).
class CacheKey {
 public:
  void add_bytes(const void* data, std::size_t bytes);
  template <class T>
  void add(const std::vector<T>& v) {
    const std::uint64_t n = v.size();
    add_bytes(&n, sizeof n);
    if (!v.empty()) add_bytes(v.data(), v.size() * sizeof(T));
  }
  // Vertices, tetrahedra, E and nu.
  void add_mesh(const mesh::TetMesh& mesh, const fem::Material& material);
  std::uint64_t value() const { return h_; }

 private:
  std::uint64_t h_{1469598103934665603ull};
};

// Reads the operator stored in `file` under `key` with 3m = m3 boundary and 3s = s3 contact
// dofs into `out`; false (out unspecified) if there is none or it does not match.
bool load_boundary_operator(const std::string& file, std::uint64_t key, int m3, int s3,
                            BoundaryOperator& out);
// Stores it (written under a per-process temporary name, then renamed: a concurrent reader sees
// the old file or the whole new one). A failure (disk full, read-only folder) is reported on
// stderr, the temporary removed, and otherwise ignored: the cache only saves time.
void save_boundary_operator(const std::string& file, std::uint64_t key,
                            const BoundaryOperator& op);

}  // namespace neurosim::interaction
