// Tetrahedral mesh files: readers for Medit .mesh, Gmsh .msh (v2, v4 ASCII) and TetGen
// .node/.ele, small writers for Medit and TetGen. (The .vtu results writer is in vtu.hpp.)
//
// Every reader throws std::runtime_error("path:line: what was expected") on a broken file.
// Readers only parse: validation (finite, in range, orientation, degeneracy) is TetMesh::build.
//
// Hostile input (fuzz/ runs every reader on generated files): no input crashes or hangs a
// reader, and what it allocates is bounded. A file is read whole but never beyond
// kMaxMeshFileBytes (256 MiB, text_reader.hpp), so a FIFO or device that never ends is refused;
// every count a header states is checked against the bytes left in the file before anything is
// allocated for it (each number takes at least one byte), so a header claiming 4e8 vertices in
// a small file is refused at its line; a line holds at most the numbers its format allows. So
// the parsed data stays within about ten times the file's size. Running out of memory anyway
// is std::runtime_error("path: out of memory while reading").
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::mesh {

// A mesh as read from a file, before TetMesh::build.
struct MeshData {
  std::vector<Vec3> vertices_m;      // unit m (file coordinates times unit_m)
  std::vector<Tet> tets;             // 0-based indices into vertices_m
  std::vector<int> tet_labels;       // one per tetrahedron (subdomain; 0 when the file has none)
  std::vector<Tri> triangles;        // triangles listed in the file (boundaries, interfaces)
  std::vector<int> triangle_labels;  // one per triangle
  std::string source;                // the path it was read from
};

// unit_m: length of one file coordinate unit in metres (1e-3 for a file in mm); finite, > 0.

// Medit .mesh (as CGAL's output_to_medit writes): Vertices, Triangles, Tetrahedra with refs
// (ref -> label). Other sections (Edges, Corners, Ridges, ...) are skipped.
MeshData read_medit(const std::string& path, double unit_m = 1.0);
// The same file as a triangle surface (a rigid obstacle): Triangles required, Tetrahedra
// optional (read, not required). Closedness is checked by tri_surface.hpp, not here.
MeshData read_medit_surface(const std::string& path, double unit_m = 1.0);
// Gmsh .msh ASCII, format 2.x, 4.0 or 4.1. Tetrahedra (type 4; type 11 uses its 4 corners) and
// triangles (type 2). Label: the element's physical tag, else its elementary (entity) tag.
// Node tags may be sparse; vertices come out in file order.
MeshData read_gmsh(const std::string& path, double unit_m = 1.0);
// TetGen .node/.ele; path is either file or the common stem ("box.1"). 0- or 1-based numbering,
// point attributes and boundary markers ignored, the first tetrahedron attribute (the region
// attribute of -A) -> label; 10-node tetrahedra use their 4 corners.
MeshData read_tetgen(const std::string& path, double unit_m = 1.0);
// Dispatch by extension: .mesh, .msh, .node/.ele.
MeshData read_mesh(const std::string& path, double unit_m = 1.0);

// read_mesh + TetMesh::build (options.source defaults to path) + labels.
TetMesh load_tet_mesh(const std::string& path, double unit_m = 1.0, BuildOptions options = {});

// Writers (coordinates are written divided by unit_m). Labels may be empty (written as 0).
void write_medit(const std::string& path, const MeshData& mesh, double unit_m = 1.0);
// Writes stem.node and stem.ele (1-based, one region attribute when labels are present).
void write_tetgen(const std::string& stem, const MeshData& mesh, double unit_m = 1.0);
// MeshData view of a built mesh (vertices, tets, labels, surface as triangles).
MeshData to_mesh_data(const TetMesh& mesh);

}  // namespace neurosim::mesh
