// Angle units: the one home of degree/radian conversion. Options and reports
// that people read are in degrees (names end in _deg); maths is in radians.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

namespace slapse {

inline double DegToRad(double deg) { return deg * M_PI / 180.0; }
inline double RadToDeg(double rad) { return rad * 180.0 / M_PI; }

// Angle between two non-zero vectors, degrees in [0, 180].
inline double AngleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return RadToDeg(std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)));
}

}  // namespace slapse
