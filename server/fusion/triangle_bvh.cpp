#include "server/fusion/triangle_bvh.hpp"

#include "server/fusion/cgal_aabb.hpp"

#include <boost/iterator/function_output_iterator.hpp>

#include <stdexcept>
#include <string>

namespace neurosim::fusion {
namespace {
using namespace cgal_aabb;
}  // namespace

struct TriangleBvh::Impl {
  std::vector<T3> triangles;
  Tree tree;
};

TriangleBvh::TriangleBvh(const std::vector<mesh::Vec3>& vertices_m,
                         const std::vector<mesh::Tri>& triangles)
    : impl_(std::make_unique<Impl>()) {
  if (triangles.empty()) throw std::invalid_argument("TriangleBvh: no triangles");
  impl_->triangles.reserve(triangles.size());
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k)
      if (triangles[t][k] < 0 || triangles[t][k] >= static_cast<int>(vertices_m.size()))
        throw std::invalid_argument("TriangleBvh: triangle " + std::to_string(t) +
                                    " has vertex index " + std::to_string(triangles[t][k]) +
                                    " outside [0, " + std::to_string(vertices_m.size()) + ")");
    impl_->triangles.emplace_back(to_point(vertices_m[triangles[t][0]]),
                                  to_point(vertices_m[triangles[t][1]]),
                                  to_point(vertices_m[triangles[t][2]]));
  }
  impl_->tree.insert(impl_->triangles.cbegin(), impl_->triangles.cend());
  impl_->tree.build();
  // No k-d tree of hints for closest-point queries: its search allocates on every query (and
  // its lazy build on the first), which a query inside a step must not.
  impl_->tree.do_not_accelerate_distance_queries();
}

TriangleBvh::~TriangleBvh() = default;
TriangleBvh::TriangleBvh(TriangleBvh&&) noexcept = default;
TriangleBvh& TriangleBvh::operator=(TriangleBvh&&) noexcept = default;

int TriangleBvh::size() const { return static_cast<int>(impl_->triangles.size()); }

void TriangleBvh::triangles_in_box(const mesh::Vec3& lo, const mesh::Vec3& hi,
                                   std::vector<int>& out) const {
  const CGAL::Bbox_3 box(lo.x(), lo.y(), lo.z(), hi.x(), hi.y(), hi.z());
  const TriIt begin = impl_->triangles.cbegin();
  impl_->tree.all_intersected_primitives(
      box, boost::make_function_output_iterator(
               [&](const TriIt& it) { out.push_back(static_cast<int>(it - begin)); }));
}

ClosestTriangle TriangleBvh::closest(const mesh::Vec3& p) const {
  const auto [point, it] = impl_->tree.closest_point_and_primitive(to_point(p));
  ClosestTriangle c;
  c.triangle = static_cast<int>(it - impl_->triangles.cbegin());
  c.point_m = mesh::Vec3(point.x(), point.y(), point.z());
  c.distance_m = (c.point_m - p).norm();
  return c;
}

}  // namespace neurosim::fusion
