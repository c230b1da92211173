// CGAL's AABB tree over triangles as the sources of neurosim::fusion use it (the inclusion
// decision, the coupling map, the triangle BVH of rigid obstacles): one kernel (exact predicates,
// inexact constructions), the triangle primitive over a std::vector, and the point conversion.
// Included by those .cpp files only, so CGAL stays private to neurosim::fusion.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <vector>

namespace neurosim::fusion::cgal_aabb {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using P3 = K::Point_3;
using T3 = K::Triangle_3;
using TriIt = std::vector<T3>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, TriIt>;
using Traits = CGAL::AABB_traits<K, Primitive>;
using Tree = CGAL::AABB_tree<Traits>;

inline P3 to_point(const mesh::Vec3& v) { return P3(v.x(), v.y(), v.z()); }

}  // namespace neurosim::fusion::cgal_aabb
