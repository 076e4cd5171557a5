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

// The world plane `plane_world` in the camera whose pose is `world_from_cam`
// (the inverse direction of TransformPlane, without inverting the pose):
//   n_c = R_wc^T n_w,   d_c = d_w - n_w . t_wc.
// The result is flipped to d_c >= 0 (the side the camera is on) when
// `facing_camera` is set.
inline Plane3d PlaneInCamera(const Rigid3d& world_from_cam, const Plane3d& plane_world,
                             bool facing_camera = false) {
  Plane3d plane_c;
  plane_c.normal = world_from_cam.rotation.conjugate() * plane_world.normal;
  plane_c.distance = plane_world.distance - plane_world.normal.dot(world_from_cam.translation);
  if (facing_camera && plane_c.distance < 0) {
    plane_c.normal = -plane_c.normal;
    plane_c.distance = -plane_c.distance;
  }
  return plane_c;
}

}  // namespace slapse
