// fusion_bench: the paper's Table 3 (time to define the new boundary, cylinder inside cube)
// reproduced with Algorithm 1 as written (brute force, once) and the fast version (median of
// several runs), then a brain-sized pair. Single-threaded; times are this thread's CPU time
// (the table mode also shows the fast version's median wall time).
//
//   fusion_bench [--csv] [--min-vertices N] [--max-vertices N] [--repeats R] [--no-brain]
//                [--no-brute] [--table PATH]
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/stats.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/paper_models.hpp"

#include <sys/resource.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using namespace neurosim;
using common::Clock;
using common::ms_since;
// CPU time of this thread (ms): what one core spends, not what a loaded machine's scheduler
// adds on top (the machine is shared).
using common::thread_cpu_ms;

bool same(const fusion::NewBoundary& a, const fusion::NewBoundary& b) {
  return a.triangles == b.triangles && a.source_tet == b.source_tet &&
         a.stats.intersected_faces == b.stats.intersected_faces &&
         a.stats.intersected_tets == b.stats.intersected_tets &&
         a.stats.partial_tets == b.stats.partial_tets;
}

struct Row {
  std::string label;
  std::size_t vertices{0}, tets{0}, embedded_tets{0}, s_prime{0}, inside{0};
  double paper_ms{-1}, brute_ms{0}, fast_ms{0}, fast_min_ms{0};
  double fast_wall_ms{0};                   // median wall-clock time of the fast version
  double no_validate_ms{0}, no_cull_ms{0};  // fast variants: B trusted as closed; per-face descents
  bool agree{false};
  std::size_t bvh_bytes{0}, tets_checked{0}, face_queries{0}, point_queries{0};
};

Row measure(const std::string& label, const fusion::MeshPair& pair, double paper_ms, int repeats,
            bool run_brute) {
  const fusion::TriangleSurface b = fusion::TriangleSurface::of(pair.embedded, "embedded");
  Row r;
  r.label = label;
  r.vertices = pair.host.num_vertices();
  r.tets = pair.host.num_tets();
  r.embedded_tets = pair.embedded.num_tets();
  r.paper_ms = paper_ms;
  auto t0 = Clock::now();
  const double c0 = thread_cpu_ms();
  fusion::NewBoundary brute;
  if (run_brute) brute = fusion::find_new_boundary_bruteforce(pair.host, b);
  r.brute_ms = run_brute ? thread_cpu_ms() - c0 : 0.0;
  std::vector<double> times;
  fusion::NewBoundary fast;
  std::vector<double> wall;
  for (int i = 0; i < repeats; ++i) {
    t0 = Clock::now();
    const double c1 = thread_cpu_ms();
    fast = fusion::find_new_boundary(pair.host, b);
    times.push_back(thread_cpu_ms() - c1);
    wall.push_back(ms_since(t0));
  }
  r.fast_wall_ms = common::percentile(wall, 0.5);
  r.fast_ms = common::percentile(times, 0.5);
  r.fast_min_ms = *std::min_element(times.begin(), times.end());
  // Where the time goes: without B's validation (closedness sort, collinearity), and with one
  // hierarchy descent per face instead of one per tetrahedron.
  auto median_of = [&](const fusion::InclusionOptions& o) {
    std::vector<double> t;
    for (int i = 0; i < repeats; ++i) {
      const double c2 = thread_cpu_ms();
      const fusion::NewBoundary v = fusion::find_new_boundary(pair.host, b, o);
      t.push_back(thread_cpu_ms() - c2);
      if (v.triangles != fast.triangles) throw std::logic_error(label + ": option changed S'");
    }
    return common::percentile(t, 0.5);
  };
  fusion::InclusionOptions o;
  o.validate_embedded = false;
  r.no_validate_ms = median_of(o);
  o = {};
  o.candidates_per_tetrahedron = false;
  r.no_cull_ms = median_of(o);
  r.agree = run_brute && same(brute, fast);
  r.s_prime = fast.triangles.size();
  r.inside = fast.stats.inside_triangles;
  r.bvh_bytes = fast.stats.bvh_bytes;
  r.tets_checked = fast.stats.tets_checked;
  r.face_queries = fast.stats.face_queries;
  r.point_queries = fast.stats.point_queries;
  return r;
}

long peak_rss_kb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;  // kB on Linux
}

}  // namespace

int main(int argc, char** argv) {
  try {
    bool csv = false, brain = true, brute = true;
    int min_vertices = 0, max_vertices = 1 << 30, repeats = 21;
    std::string table = std::string(NEUROSIM_SOURCE_DIR) + "/bench/data/paper_table3.csv";
    bool no_brain = false, no_brute = false;
    neurosim::cli::Parser cli("fusion_bench",
                              "The new boundary S' on the paper's Table 3 pairs (and a brain-sized "
                              "pair), fast path vs brute force.");
    cli.add_flag("--csv", csv, "print CSV");
    cli.add_option("--min-vertices", min_vertices, "smallest cube (vertices)");
    cli.add_option("--max-vertices", max_vertices, "largest cube (vertices)");
    cli.add_option("--repeats", repeats, "runs per row (at least 1)")->capture_default_str();
    cli.add_flag("--no-brain", no_brain, "no brain-sized row");
    cli.add_flag("--no-brute", no_brute, "no brute-force reference (profiling the fast path)");
    cli.add_option("--table", table, "the paper's Table 3 as CSV")->capture_default_str();
    if (auto rc = cli.parse(argc, argv)) return *rc;
    brain = !no_brain;
    brute = !no_brute;
    repeats = std::max(1, repeats);
    std::vector<Row> rows;
    for (const fusion::PaperRow& p : fusion::read_paper_table3(table)) {
      if (p.cube_vertices > max_vertices || p.cube_vertices < min_vertices) continue;
      const fusion::MeshPair pair = fusion::make_cube_cylinder(p.cube_vertices);
      rows.push_back(
          measure(std::to_string(pair.host.num_vertices()), pair, p.time_ms, repeats, brute));
      std::cerr << "cube " << p.cube_vertices << " (paper) -> " << pair.description << "\n";
    }
    if (brain) {
      const fusion::MeshPair pair = fusion::make_brain_like();
      rows.push_back(measure("brain_like", pair, -1.0, repeats, brute));
      std::cerr << "brain_like: " << pair.description << "\n";
    }
    if (csv) {
      std::printf(
          "cube_vertices,cube_tets,new_boundary_triangles,inside_triangles,paper_ms,brute_ms,"
          "fast_ms,agree\n");
      for (const Row& r : rows) {
        char paper[32] = "nan";  // the paper has no time for the brain-sized pair
        if (r.paper_ms > 0) std::snprintf(paper, sizeof paper, "%.1f", r.paper_ms);
        std::printf("%s,%zu,%zu,%zu,%s,%.1f,%.4f,%d\n", r.label.c_str(), r.tets, r.s_prime,
                    r.inside, paper, r.brute_ms, r.fast_ms, r.agree ? 1 : 0);
      }
    } else {
      std::printf("%-12s %7s %9s %6s %8s %9s %10s %9s %9s %9s %9s %9s %5s %8s %7s %7s %7s\n",
                  "host_verts", "tets", "emb_tets", "S'", "inside", "paper_ms", "brute_ms",
                  "fast_ms", "fast_min", "fast_wall", "no_valid", "per_face", "agree", "bvh_kB",
                  "checked", "faces", "points");
      for (const Row& r : rows) {
        std::printf(
            "%-12s %7zu %9zu %6zu %8zu %9.1f %10.1f %9.4f %9.4f %9.4f %9.4f %9.4f %5d %8.1f %7zu "
            "%7zu %7zu\n",
            r.label.c_str(), r.tets, r.embedded_tets, r.s_prime, r.inside, r.paper_ms, r.brute_ms,
            r.fast_ms, r.fast_min_ms, r.fast_wall_ms, r.no_validate_ms, r.no_cull_ms,
            r.agree ? 1 : 0, r.bvh_bytes / 1024.0, r.tets_checked, r.face_queries, r.point_queries);
      }
    }
    for (const Row& r : rows) {
      std::cerr << "memory " << r.label << ": hierarchy over B " << r.bvh_bytes << " bytes\n";
    }
    std::cerr << "peak RSS " << peak_rss_kb() << " kB (whole process, meshing included)\n";
    bool all = true;
    for (const Row& r : rows) all = all && r.agree;
    return all ? 0 : 1;
  } catch (const std::exception& e) {
    std::cerr << "fusion_bench: " << e.what() << "\n";
    return 1;
  }
}
