// Planes and their frames: the one home of the plane transform.
//
// A plane is n . X = d with unit normal n and distance d > 0 from the origin
// of its frame; in a camera it is also held as pi = n / d (so pi . X = 1).
// Moving it by b_from_a (x_b = R x_a + t, core/common/rigid3.h):
//   n_b = R n_a,   d_b = d_a + n_b . t.
#pragma once

#include <Eigen/Core>

#include "core/common/rigid3.h"

namespace slapse {

struct Plane3d {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit
  double distance = 0.0;                              // n . X = distance

  // The plane pi . X = 1 (pi = n / d, d > 0).
  static Plane3d FromInverseDepth(const Eigen::Vector3d& pi) {
    return {pi.normalized(), 1.0 / pi.norm()};
  }
  Eigen::Vector3d InverseDepth() const { return normal / distance; }
};

// The plane `plane_a` (in frame a) expressed in frame b.
inline Plane3d TransformPlane(const Rigid3d& b_from_a, const Plane3d& plane_a) {
  Plane3d plane_b;
  plane_b.normal = b_from_a.R() * plane_a.normal;
  plane_b.distance = plane_a.distance + plane_b.normal.dot(b_from_a.translation);
  return plane_b;
}

}  // namespace slapse
