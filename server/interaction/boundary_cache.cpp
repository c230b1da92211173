#include "server/interaction/boundary_cache.hpp"

#include "common/cache_file.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace neurosim::interaction {

namespace {
// v2: G computed in the Cholesky form (coupled_body.cpp); v1 files hold the less accurate LU one.
// v3: a checksum of the matrices follows the sizes (a file damaged on disk, or one half-written
// by a writer that did not use the atomic rename, is detected, not used).
constexpr char kCacheMagic[8] = {'N', 'S', 'C', 'P', 'L', 'v', '3', '\0'};

std::uint64_t payload_checksum(const BoundaryOperator& op) {
  CacheKey sum;
  for (const Eigen::MatrixXd* mat : {&op.l_bb, &op.l_sb, &op.k_add, &op.g})
    sum.add_bytes(mat->data(), static_cast<std::size_t>(mat->size()) * sizeof(double));
  return sum.value();
}
}  // namespace

void CacheKey::add_bytes(const void* data, std::size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) {
    h_ ^= p[i];
    h_ *= 1099511628211ull;
  }
}

void CacheKey::add_mesh(const mesh::TetMesh& m, const fem::Material& mat) {
  add(m.vertices());
  add(m.tets());
  add_bytes(&mat.youngs_modulus_pa, sizeof(double));
  add_bytes(&mat.poisson_ratio, sizeof(double));
  // The element changes the operator; linear-tet adds nothing (keys of earlier caches hold).
  if (mat.element != fem::Element::kLinearTet) {
    const int element = static_cast<int>(mat.element);
    add_bytes(&element, sizeof element);
  }
}

bool load_boundary_operator(const std::string& file, std::uint64_t key, int m3_expected,
                            int s3_expected, BoundaryOperator& out) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  char magic[8];
  std::uint64_t stored_key = 0, stored_sum = 0;
  std::int32_t m3 = 0, s3 = 0;
  in.read(magic, sizeof magic);
  in.read(reinterpret_cast<char*>(&stored_key), sizeof stored_key);
  in.read(reinterpret_cast<char*>(&m3), sizeof m3);
  in.read(reinterpret_cast<char*>(&s3), sizeof s3);
  in.read(reinterpret_cast<char*>(&stored_sum), sizeof stored_sum);
  if (!in || std::memcmp(magic, kCacheMagic, sizeof magic) != 0 || stored_key != key ||
      m3 != m3_expected || s3 != s3_expected) {
    return false;
  }
  out.l_bb.resize(m3, m3);
  out.l_sb.resize(s3, m3);
  out.k_add.resize(m3, m3);
  out.g.resize(m3, m3);
  for (Eigen::MatrixXd* mat : {&out.l_bb, &out.l_sb, &out.k_add, &out.g})
    in.read(reinterpret_cast<char*>(mat->data()),
            static_cast<std::streamsize>(mat->size() * sizeof(double)));
  if (!in || in.peek() != std::char_traits<char>::eof()) {
    std::cerr << "CoupledBody: ignoring damaged compliance cache " << file
              << " (length does not match its header)\n";
    return false;
  }
  if (payload_checksum(out) != stored_sum || !out.l_bb.allFinite() || !out.l_sb.allFinite() ||
      !out.k_add.allFinite() || !out.g.allFinite()) {
    std::cerr << "CoupledBody: ignoring damaged compliance cache " << file
              << " (checksum mismatch)\n";
    return false;
  }
  return true;
}

void save_boundary_operator(const std::string& file, std::uint64_t key,
                            const BoundaryOperator& op) {
  common::write_cache_file(file, "CoupledBody", "compliance cache", [&](std::ostream& out) {
    const std::int32_t m3 = static_cast<std::int32_t>(op.l_bb.rows()),
                       s3 = static_cast<std::int32_t>(op.l_sb.rows());
    const std::uint64_t sum = payload_checksum(op);
    out.write(kCacheMagic, sizeof kCacheMagic);
    out.write(reinterpret_cast<const char*>(&key), sizeof key);
    out.write(reinterpret_cast<const char*>(&m3), sizeof m3);
    out.write(reinterpret_cast<const char*>(&s3), sizeof s3);
    out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
    for (const Eigen::MatrixXd* mat : {&op.l_bb, &op.l_sb, &op.k_add, &op.g})
      out.write(reinterpret_cast<const char*>(mat->data()),
                static_cast<std::streamsize>(mat->size() * sizeof(double)));
  });
}

}  // namespace neurosim::interaction
