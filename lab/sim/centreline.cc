#include "lab/sim/centreline.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace slapse {

Centreline::Centreline(const Eigen::Vector2d& start, double heading_rad)
    : start_(start), start_heading_rad_(heading_rad) {}

double Centreline::length_m() const {
  return segments_.empty() ? 0.0 : segments_.back().s0_m + segments_.back().length_m;
}

void Centreline::AddArc(double length_m, double curvature) {
  CentrelineSegment seg;
  seg.length_m = length_m;
  seg.curvature = curvature;
  if (segments_.empty()) {
    seg.p0 = start_;
    seg.heading0_rad = start_heading_rad_;
  } else {
    const CentrelineSegment& prev = segments_.back();
    const int i = static_cast<int>(segments_.size()) - 1;
    seg.s0_m = prev.s0_m + prev.length_m;
    seg.p0 = PointOn(i, seg.s0_m);
    seg.heading0_rad = HeadingOn(i, seg.s0_m);
    seg.heading_integral0 = prev.heading_integral0 + prev.heading0_rad * prev.length_m +
                            0.5 * prev.curvature * prev.length_m * prev.length_m;
  }
  segments_.push_back(seg);
}

void Centreline::AddStraight(double length_m) { AddArc(length_m, 0.0); }

int Centreline::SegmentIndex(double s_m) const {
  if (segments_.empty()) return -1;
  // Last segment whose start is <= s.
  auto it = std::upper_bound(segments_.begin(), segments_.end(), s_m,
                             [](double s, const CentrelineSegment& seg) { return s < seg.s0_m; });
  if (it == segments_.begin()) return 0;
  return static_cast<int>(it - segments_.begin()) - 1;
}

Eigen::Vector2d Centreline::PointOn(int i, double s_m) const {
  const CentrelineSegment& seg = segments_[i];
  const double t = s_m - seg.s0_m;
  const double h0 = seg.heading0_rad;
  const double k = seg.curvature;
  const bool last = i + 1 == static_cast<int>(segments_.size());
  // Before the first segment: straight back along the start tangent.
  if (k == 0.0 || (i == 0 && t < 0.0)) {
    return seg.p0 + t * Eigen::Vector2d(std::cos(h0), std::sin(h0));
  }
  // On the arc; past the end of the last segment, straight along the end tangent.
  const double ta = last ? std::min(t, seg.length_m) : t;
  const double h = h0 + k * ta;
  Eigen::Vector2d p =
      seg.p0 + Eigen::Vector2d((std::sin(h) - std::sin(h0)) / k, (std::cos(h0) - std::cos(h)) / k);
  if (t > ta) p += (t - ta) * Eigen::Vector2d(std::cos(h), std::sin(h));
  return p;
}

double Centreline::HeadingOn(int i, double s_m) const {
  const CentrelineSegment& seg = segments_[i];
  const double t = std::clamp(s_m - seg.s0_m, i == 0 ? 0.0 : -1e300,
                              i + 1 == static_cast<int>(segments_.size()) ? seg.length_m : 1e300);
  return seg.heading0_rad + seg.curvature * std::max(t, 0.0);
}

Eigen::Vector2d Centreline::Point(double s_m) const {
  if (segments_.empty()) return start_;
  return PointOn(SegmentIndex(s_m), s_m);
}

double Centreline::Heading(double s_m) const {
  if (segments_.empty()) return start_heading_rad_;
  return HeadingOn(SegmentIndex(s_m), s_m);
}

double Centreline::Curvature(double s_m) const {
  if (segments_.empty() || s_m < 0.0 || s_m > length_m()) return 0.0;
  return segments_[SegmentIndex(s_m)].curvature;
}

Eigen::Vector2d Centreline::Tangent(double s_m) const {
  const double h = Heading(s_m);
  return {std::cos(h), std::sin(h)};
}

Eigen::Vector2d Centreline::Left(double s_m) const {
  const double h = Heading(s_m);
  return {-std::sin(h), std::cos(h)};
}

double Centreline::HeadingIntegral(double s_m) const {
  if (segments_.empty()) return start_heading_rad_ * s_m;
  if (s_m <= 0.0) return segments_[0].heading0_rad * s_m;
  const int i = SegmentIndex(s_m);
  const CentrelineSegment& seg = segments_[i];
  const double t = s_m - seg.s0_m;
  if (t <= seg.length_m) {
    return seg.heading_integral0 + seg.heading0_rad * t + 0.5 * seg.curvature * t * t;
  }
  // Past the end: constant end heading.
  const double he = seg.heading0_rad + seg.curvature * seg.length_m;
  return seg.heading_integral0 + seg.heading0_rad * seg.length_m +
         0.5 * seg.curvature * seg.length_m * seg.length_m + he * (t - seg.length_m);
}

void Centreline::Project(const Eigen::Vector2d& p, double* s_m, double* lateral_m,
                         int first_segment, int last_segment) const {
  const int n = static_cast<int>(segments_.size());
  const int i0 = first_segment < 0 ? 0 : std::min(first_segment, n - 1);
  const int i1 = last_segment < 0 ? n - 1 : std::min(last_segment, n - 1);
  double best_cost = std::numeric_limits<double>::infinity();
  double best_s = 0.0, best_l = 0.0;
  for (int i = i0; i <= i1; ++i) {
    const CentrelineSegment& seg = segments_[i];
    const Eigen::Vector2d t0(std::cos(seg.heading0_rad), std::sin(seg.heading0_rad));
    const Eigen::Vector2d n0(-t0.y(), t0.x());
    double t, l;
    if (seg.curvature == 0.0) {
      const Eigen::Vector2d d = p - seg.p0;
      t = d.dot(t0);
      l = d.dot(n0);
    } else {
      const Eigen::Vector2d c = seg.p0 + n0 / seg.curvature;
      const Eigen::Vector2d r0 = seg.p0 - c, r = p - c;
      const double phi = std::atan2(r0.x() * r.y() - r0.y() * r.x(), r0.dot(r));
      t = phi / seg.curvature;
      const double h = seg.heading0_rad + seg.curvature * t;
      l = (p - PointOn(i, seg.s0_m + t)).dot(Eigen::Vector2d(-std::sin(h), std::cos(h)));
    }
    // Cost: |lateral| inside the segment, else distance to the nearer end.
    double cost = std::abs(l);
    const bool open_start = i == 0, open_end = i == n - 1;
    if ((t < 0.0 && !open_start) || (t > seg.length_m && !open_end)) {
      const double tc = std::clamp(t, 0.0, seg.length_m);
      cost = (p - PointOn(i, seg.s0_m + tc)).norm() + 1e-9;
      if (cost < best_cost) {
        const double h = HeadingOn(i, seg.s0_m + tc);
        best_cost = cost;
        best_s = seg.s0_m + tc;
        best_l = (p - PointOn(i, best_s)).dot(Eigen::Vector2d(-std::sin(h), std::cos(h)));
      }
      continue;
    }
    if (cost < best_cost) {
      best_cost = cost;
      best_s = seg.s0_m + t;
      best_l = l;
    }
  }
  *s_m = best_s;
  *lateral_m = best_l;
}

}  // namespace slapse
