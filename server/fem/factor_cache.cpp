#include "server/fem/factor_cache.hpp"

#include "common/cache_file.hpp"

#include <cholmod.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <vector>

namespace neurosim::fem {

namespace {

// v1: the supernodal LL^T arrays of CHOLMOD 3 with int indices (itype CHOLMOD_INT).
// v2: the same arrays, the checksum by four lanes (WordHash).
constexpr char kMagic[8] = {'N', 'S', 'F', 'A', 'C', 'T', '2', '\0'};

// 64-bit hash over 8-byte words (FNV-1a's multiply, plus a shift so that high bits reach low
// ones) in four lanes, word k into lane k mod 4, so that four multiplies are in flight at once
// (one lane ran at ~1 byte per cycle, a third of a cached start's time). The value depends only
// on the bytes and where the 8-byte words fall: data added in pieces whose sizes are multiples
// of 8 hashes as added whole. The checksum of a 3 mm brain's factor costs a fraction of the read.
class WordHash {
 public:
  void add(const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    std::size_t k = 0;
    for (; k + 8 <= bytes && (words_ & 3) != 0; k += 8) mix(load(p + k));
    // The lanes in locals: `p` may alias the members, which would serialize the lanes again.
    std::uint64_t h0 = h_[0], h1 = h_[1], h2 = h_[2], h3 = h_[3];
    const std::size_t start = k;
    for (; k + 32 <= bytes; k += 32) {
      mix(h0, load(p + k));
      mix(h1, load(p + k + 8));
      mix(h2, load(p + k + 16));
      mix(h3, load(p + k + 24));
    }
    h_[0] = h0;
    h_[1] = h1;
    h_[2] = h2;
    h_[3] = h3;
    words_ += (k - start) / 8;
    for (; k + 8 <= bytes; k += 8) mix(load(p + k));
    for (; k < bytes; ++k) mix(p[k]);
  }
  std::uint64_t value() const {
    std::uint64_t v = h_[0];
    for (int i = 1; i < 4; ++i) mix(v, h_[i]);
    mix(v, words_);
    return v;
  }

 private:
  static std::uint64_t load(const unsigned char* p) {
    std::uint64_t w;
    std::memcpy(&w, p, 8);
    return w;
  }
  static void mix(std::uint64_t& h, std::uint64_t w) {
    h = (h ^ w) * 1099511628211ull;
    h ^= h >> 31;
  }
  void mix(std::uint64_t w) { mix(h_[words_++ & 3], w); }
  std::uint64_t h_[4]{1469598103934665603ull, 1469598103934665603ull ^ 1, 1469598103934665603ull ^ 2,
                      1469598103934665603ull ^ 3};
  std::uint64_t words_{0};
};

// The header after the magic, key and checksum (the checksum covers it and the arrays).
struct Header {
  std::int64_t n{0}, nsuper{0}, ssize{0}, xsize{0}, maxcsize{0}, maxesize{0}, ordering{0},
      is_monotonic{0};
  double lnz{0.0};
};

double factor_bytes(const Header& h) {
  return static_cast<double>(h.xsize) * sizeof(double) +
         static_cast<double>(h.ssize) * sizeof(int) +
         3.0 * static_cast<double>(h.nsuper + 1) * sizeof(int) +
         2.0 * static_cast<double>(h.n) * sizeof(int);
}

struct Array {
  void* data;
  std::size_t count;
  std::size_t size;
};

// The factor's arrays in file order: Perm, ColCount, super, pi, px, s, x.
std::vector<Array> arrays_of(const cholmod_factor& f) {
  const std::size_t ns = f.nsuper + 1;
  return {{f.Perm, f.n, sizeof(int)},   {f.ColCount, f.n, sizeof(int)}, {f.super, ns, sizeof(int)},
          {f.pi, ns, sizeof(int)},      {f.px, ns, sizeof(int)},        {f.s, f.ssize, sizeof(int)},
          {f.x, f.xsize, sizeof(double)}};
}

std::uint64_t checksum(const Header& h, const cholmod_factor& f) {
  WordHash sum;
  sum.add(&h, sizeof h);
  for (const Array& a : arrays_of(f)) sum.add(a.data, a.count * a.size);
  return sum.value();
}

// The arrays describe a supernodal factor of an n x n matrix that CHOLMOD can solve with: a
// permutation, supernodes covering 0..n-1, row patterns within 0..n-1 starting with their own
// columns, value blocks of nsrow x nscol, E workspace (maxesize) large enough.
bool consistent(const cholmod_factor& f) {
  const int n = static_cast<int>(f.n), ns = static_cast<int>(f.nsuper);
  const int* perm = static_cast<const int*>(f.Perm);
  const int* super = static_cast<const int*>(f.super);
  const int* pi = static_cast<const int*>(f.pi);
  const int* px = static_cast<const int*>(f.px);
  const int* s = static_cast<const int*>(f.s);
  std::vector<char> seen(f.n, 0);
  for (int k = 0; k < n; ++k) {
    if (perm[k] < 0 || perm[k] >= n || seen[perm[k]]) return false;
    seen[perm[k]] = 1;
  }
  if (super[0] != 0 || super[ns] != n || pi[0] != 0 || pi[ns] != static_cast<int>(f.ssize) ||
      px[0] != 0 || static_cast<std::size_t>(px[ns]) > f.xsize)
    return false;
  std::size_t maxe = 0;
  for (int j = 0; j < ns; ++j) {
    const long nscol = super[j + 1] - super[j], nsrow = pi[j + 1] - pi[j];
    if (nscol < 1 || nsrow < nscol || px[j + 1] - px[j] != nscol * nsrow) return false;
    for (long r = 0; r < nsrow; ++r) {
      const int row = s[pi[j] + r];
      if (row < 0 || row >= n || (r < nscol && row != super[j] + r)) return false;
    }
    maxe = std::max<std::size_t>(maxe, static_cast<std::size_t>(nsrow - nscol));
  }
  return f.maxesize >= maxe;
}

}  // namespace

std::uint64_t factor_key(const mesh::TetMesh& mesh, const MaterialMap& materials,
                         const std::vector<int>& fixed_nodes, int ordering) {
  WordHash key;
  auto add_count = [&](std::size_t n) {
    const std::int64_t v = static_cast<std::int64_t>(n);
    key.add(&v, sizeof v);
  };
  const std::int64_t version = kFactorKeyVersion, cholmod = CHOLMOD_VERSION, o = ordering;
  key.add(&version, sizeof version);
  key.add(&cholmod, sizeof cholmod);
  key.add(&o, sizeof o);
  // Counts before every array, so that [1,2],[3] and [1],[2,3] differ.
  add_count(mesh.num_vertices());
  key.add(mesh.vertices().data(), mesh.num_vertices() * sizeof(mesh::Vec3));
  add_count(mesh.num_tets());
  key.add(mesh.tets().data(), mesh.num_tets() * sizeof(mesh::Tet));
  add_count(materials.materials.size());
  for (const Material& m : materials.materials) {
    const std::int64_t element = static_cast<std::int64_t>(m.element);
    key.add(&m.youngs_modulus_pa, sizeof m.youngs_modulus_pa);
    key.add(&m.poisson_ratio, sizeof m.poisson_ratio);
    key.add(&element, sizeof element);
  }
  add_count(materials.tet_material.size());
  key.add(materials.tet_material.data(), materials.tet_material.size() * sizeof(int));
  add_count(fixed_nodes.size());
  key.add(fixed_nodes.data(), fixed_nodes.size() * sizeof(int));
  return key.value();
}

std::string factor_file(const std::string& dir, std::uint64_t key) {
  char name[64];
  std::snprintf(name, sizeof name, "factor_%016llx.bin", static_cast<unsigned long long>(key));
  return (std::filesystem::path(dir) / name).string();
}

FactorLoad load_factor(const std::string& file, std::uint64_t key, std::size_t n,
                       double max_bytes, cholmod_common& common) {
  FactorLoad out;
  std::ifstream in(file, std::ios::binary);
  if (!in) return out;
  char magic[8];
  std::uint64_t stored_key = 0, stored_sum = 0;
  Header h;
  in.read(magic, sizeof magic);
  in.read(reinterpret_cast<char*>(&stored_key), sizeof stored_key);
  in.read(reinterpret_cast<char*>(&stored_sum), sizeof stored_sum);
  in.read(reinterpret_cast<char*>(&h), sizeof h);
  if (!in || std::memcmp(magic, kMagic, sizeof magic) != 0 || stored_key != key ||
      h.n != static_cast<std::int64_t>(n) || h.nsuper < 1 || h.ssize < 1 || h.xsize < 1 ||
      h.maxesize < 0 || h.maxcsize < 0 || h.nsuper > h.n) {
    return out;
  }
  out.factor_bytes = factor_bytes(h);
  if (out.factor_bytes > max_bytes) {
    out.too_large = true;
    return out;
  }
  // A symbolic simplicial factor (Perm, ColCount), made supernodal numeric below; every array
  // from CHOLMOD's allocator with the sizes cholmod_free_factor frees.
  cholmod_factor* f = cholmod_allocate_factor(n, &common);
  if (f == nullptr) return out;
  auto fail = [&](const char* why) {
    if (why != nullptr)
      std::cerr << "StaticSolver: ignoring damaged factor cache " << file << " (" << why << ")\n";
    cholmod_free_factor(&f, &common);
    return out;
  };
  f->nsuper = static_cast<std::size_t>(h.nsuper);
  f->ssize = static_cast<std::size_t>(h.ssize);
  f->super = cholmod_malloc(f->nsuper + 1, sizeof(int), &common);
  f->pi = cholmod_malloc(f->nsuper + 1, sizeof(int), &common);
  f->px = cholmod_malloc(f->nsuper + 1, sizeof(int), &common);
  f->s = cholmod_malloc(f->ssize, sizeof(int), &common);
  if (!f->super || !f->pi || !f->px || !f->s) return fail(nullptr);
  f->xsize = static_cast<std::size_t>(h.xsize);
  f->x = cholmod_malloc(f->xsize, sizeof(double), &common);
  if (!f->x) {
    f->xsize = 0;
    return fail(nullptr);
  }
  f->xtype = CHOLMOD_REAL;
  f->is_ll = 1;
  f->is_super = 1;
  f->is_monotonic = static_cast<int>(h.is_monotonic);
  f->ordering = static_cast<int>(h.ordering);
  f->maxcsize = static_cast<std::size_t>(h.maxcsize);
  f->maxesize = static_cast<std::size_t>(h.maxesize);
  f->minor = n;
  // Read and checksummed in pieces (multiples of 8 bytes: the same sum as whole arrays), each
  // hashed while it is still in the cache.
  WordHash sum;
  sum.add(&h, sizeof h);
  constexpr std::size_t kPiece = std::size_t{1} << 17;
  for (const Array& a : arrays_of(*f)) {
    char* data = static_cast<char*>(a.data);
    const std::size_t bytes = a.count * a.size;
    for (std::size_t k = 0; k < bytes && in; k += kPiece) {
      const std::size_t piece = std::min(kPiece, bytes - k);
      in.read(data + k, static_cast<std::streamsize>(piece));
      sum.add(data + k, piece);
    }
  }
  if (!in || in.peek() != std::char_traits<char>::eof())
    return fail("length does not match its header");
  if (sum.value() != stored_sum) return fail("checksum mismatch");
  if (!consistent(*f)) return fail("the supernodes do not hold together");
  out.factor = f;
  out.lnz = h.lnz;
  return out;
}

void save_factor(const std::string& file, std::uint64_t key, const cholmod_factor& f,
                 double lnz) {
  if (!f.is_super || !f.is_ll || f.xtype != CHOLMOD_REAL || f.itype != CHOLMOD_INT ||
      f.dtype != CHOLMOD_DOUBLE || f.minor != f.n)
    return;
  Header h;
  h.n = static_cast<std::int64_t>(f.n);
  h.nsuper = static_cast<std::int64_t>(f.nsuper);
  h.ssize = static_cast<std::int64_t>(f.ssize);
  h.xsize = static_cast<std::int64_t>(f.xsize);
  h.maxcsize = static_cast<std::int64_t>(f.maxcsize);
  h.maxesize = static_cast<std::int64_t>(f.maxesize);
  h.ordering = f.ordering;
  h.is_monotonic = f.is_monotonic;
  h.lnz = lnz;
  common::write_cache_file(file, "StaticSolver", "factor cache", [&](std::ostream& out) {
    const std::uint64_t sum = checksum(h, f);
    out.write(kMagic, sizeof kMagic);
    out.write(reinterpret_cast<const char*>(&key), sizeof key);
    out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
    out.write(reinterpret_cast<const char*>(&h), sizeof h);
    for (const Array& a : arrays_of(f))
      out.write(static_cast<const char*>(a.data), static_cast<std::streamsize>(a.count * a.size));
  });
}

}  // namespace neurosim::fem
