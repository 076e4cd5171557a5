// The street's centreline: a planar curve (world z = 0) built from straights
// and circular arcs, parametrised by arc length s (metres).
//
// Conventions: heading is the tangent's angle in the world xy plane, radians,
// counter-clockwise from +x, unwrapped (continuous, may leave [-pi, pi]).
// Curvature is signed: > 0 turns left (counter-clockwise). Lateral offsets are
// signed along the left normal: > 0 is left of the centreline, < 0 right.
// Outside [0, length] the curve continues as straight lines along the end
// tangents (the generator starts and ends the street with straights).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace slapse {

struct CentrelineSegment {
  double s0_m = 0.0;                             // arc length at the segment's start
  double length_m = 0.0;                         // arc length of the segment
  double curvature = 0.0;                        // 1/m, signed (> 0 left turn); 0 for a straight
  Eigen::Vector2d p0 = Eigen::Vector2d::Zero();  // start point, world xy
  double heading0_rad = 0.0;                     // start heading
  double heading_integral0 = 0.0;                // integral of heading over [0, s0_m], rad*m
};

class Centreline {
 public:
  // Starts at `start` with heading `heading_rad`.
  explicit Centreline(const Eigen::Vector2d& start = Eigen::Vector2d::Zero(),
                      double heading_rad = 0.0);

  void AddStraight(double length_m);
  // A circular arc with signed curvature (1/m).
  void AddArc(double length_m, double curvature);

  double length_m() const;
  const std::vector<CentrelineSegment>& segments() const { return segments_; }

  Eigen::Vector2d Point(double s_m) const;
  double Heading(double s_m) const;
  double Curvature(double s_m) const;
  Eigen::Vector2d Tangent(double s_m) const;
  // Unit normal pointing left of the direction of travel.
  Eigen::Vector2d Left(double s_m) const;
  // Point at arc length s and signed lateral offset (left positive).
  Eigen::Vector2d Offset(double s_m, double lateral_m) const {
    return Point(s_m) + lateral_m * Left(s_m);
  }
  // Integral of the (unwrapped) heading over [0, s]; used to average headings.
  double HeadingIntegral(double s_m) const;

  // Curvilinear coordinates (s, lateral) of a world point: the foot point on
  // the segment whose perpendicular is shortest. Only meaningful within the
  // smallest radius of curvature of the curve. Segments with index outside
  // [first_segment, last_segment] are ignored (-1: no limit).
  void Project(const Eigen::Vector2d& p, double* s_m, double* lateral_m, int first_segment = -1,
               int last_segment = -1) const;

  // Index of the segment containing s (clamped to the first/last segment).
  int SegmentIndex(double s_m) const;

 private:
  // Local evaluation on segment `i` at arc length s (may lie outside the segment).
  Eigen::Vector2d PointOn(int i, double s_m) const;
  double HeadingOn(int i, double s_m) const;

  Eigen::Vector2d start_;
  double start_heading_rad_;
  std::vector<CentrelineSegment> segments_;
};

}  // namespace slapse
