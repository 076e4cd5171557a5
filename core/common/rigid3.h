// Rigid transforms named by the frames they connect.
//
// Convention (used everywhere in slapse): a transform `b_from_a` maps a point
// expressed in frame a to frame b:  x_b = R * x_a + t.
// So `cam_from_world` projects world points into the camera, and
// `world_from_cam` is the camera's pose (its centre is world_from_cam.translation).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace slapse {

// The rotation is a unit quaternion: the constructors normalise it (Eigen's
// q * x and toRotationMatrix assume |q| = 1; a composition multiplies the
// norms, so an error of 1e-5 grew geometrically over a few hundred composed
// steps, to |q| = 31 and a trajectory 1e15 m long on a 60 fps H.264 drive).
// A matrix is taken to its nearest rotation's quaternion the same way.
struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& r, const Eigen::Vector3d& t)
      : rotation(r.normalized()), translation(t) {}
  Rigid3d(const Eigen::Matrix3d& r, const Eigen::Vector3d& t)
      : rotation(Eigen::Quaterniond(r).normalized()), translation(t) {}

  Eigen::Matrix3d R() const { return rotation.toRotationMatrix(); }
  Eigen::Vector3d operator*(const Eigen::Vector3d& x_a) const {
    return rotation * x_a + translation;
  }
  // c_from_a = c_from_b * b_from_a.
  Rigid3d operator*(const Rigid3d& b_from_a) const {
    return Rigid3d(rotation * b_from_a.rotation, rotation * b_from_a.translation + translation);
  }
  Rigid3d Inverse() const {
    const Eigen::Quaterniond r_inv = rotation.conjugate();
    return Rigid3d(r_inv, -(r_inv * translation));
  }
};

}  // namespace slapse
