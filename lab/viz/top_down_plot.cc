#include "lab/viz/top_down_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

namespace slapse {

void TopDownPlot::AddPath(std::vector<Eigen::Vector2d> points, cv::Scalar colour, std::string label,
                          int thickness_px) {
  paths_.push_back({std::move(points), colour, std::move(label), thickness_px});
}

void TopDownPlot::AddPoints(std::vector<Eigen::Vector2d> points, cv::Scalar colour, int radius_px) {
  dots_.push_back({std::move(points), colour, radius_px});
}

void TopDownPlot::AddSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, cv::Scalar colour,
                             int thickness_px) {
  segments_.push_back({a, b, colour, thickness_px});
}

cv::Mat TopDownPlot::Render(int width_px, int height_px, const std::string& title,
                            const std::string& unit) const {
  cv::Mat out(height_px, width_px, CV_8UC3, cv::Scalar(255, 255, 255));
  Eigen::Vector2d lo(1e30, 1e30), hi(-1e30, -1e30);
  auto grow = [&](const Eigen::Vector2d& p) {
    if (!p.allFinite()) return;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  };
  // The extent: the paths (the drive) and what lies near them (the planes
  // seen, the facades along the road), not everything added (a simulated
  // city's facades would leave the drive a few pixels wide). Without paths,
  // everything.
  for (const Path& p : paths_) std::for_each(p.points.begin(), p.points.end(), grow);
  const bool have_paths = lo.x() <= hi.x();
  const double reach = have_paths ? kNearPathFraction * std::max((hi - lo).maxCoeff(), 1e-6) : 0;
  const Eigen::Vector2d near_lo = lo.array() - reach, near_hi = hi.array() + reach;
  auto grow_near = [&](const Eigen::Vector2d& p) {
    if (!have_paths ||
        ((p.array() >= near_lo.array()).all() && (p.array() <= near_hi.array()).all())) {
      grow(p);
    }
  };
  for (const Dots& d : dots_) std::for_each(d.points.begin(), d.points.end(), grow_near);
  for (const Segment& s : segments_) grow_near(s.a), grow_near(s.b);
  if (lo.x() > hi.x()) lo.setZero(), hi.setOnes();
  const double margin = 0.08 * std::max((hi - lo).maxCoeff(), 1e-6);
  lo.array() -= margin;
  hi.array() += margin;
  const double scale =
      std::min((width_px - 20) / (hi.x() - lo.x()), (height_px - 50) / (hi.y() - lo.y()));
  const Eigen::Vector2d centre = 0.5 * (lo + hi);
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point2d(width_px / 2.0 + (p.x() - centre.x()) * scale,
                       (height_px + 30) / 2.0 - (p.y() - centre.y()) * scale);
  };
  // Grid: a round step giving 5-12 lines across.
  const double span = (hi - lo).maxCoeff();
  double step = std::pow(10.0, std::floor(std::log10(span / 5)));
  if (span / step > 25)
    step *= 5;
  else if (span / step > 12)
    step *= 2;
  for (double u = std::floor(lo.x() / step) * step; u <= hi.x() + step; u += step) {
    cv::line(out, px({u, lo.y() - span}), px({u, hi.y() + span}), cv::Scalar(235, 235, 235), 1);
  }
  for (double v = std::floor(lo.y() / step) * step; v <= hi.y() + step; v += step) {
    cv::line(out, px({lo.x() - span, v}), px({hi.x() + span, v}), cv::Scalar(235, 235, 235), 1);
  }
  for (const Dots& d : dots_) {
    for (const Eigen::Vector2d& p : d.points) {
      if (p.allFinite() && (p - centre).cwiseAbs().maxCoeff() < 2 * span) {
        cv::circle(out, px(p), d.radius, d.colour, cv::FILLED, cv::LINE_AA);
      }
    }
  }
  for (const Segment& s : segments_) {
    cv::line(out, px(s.a), px(s.b), s.colour, s.thickness, cv::LINE_AA);
  }
  int legend_y = 40;
  for (const Path& p : paths_) {
    for (size_t i = 1; i < p.points.size(); ++i) {
      cv::line(out, px(p.points[i - 1]), px(p.points[i]), p.colour, p.thickness, cv::LINE_AA);
    }
    if (!p.points.empty()) cv::circle(out, px(p.points.front()), 4, p.colour, cv::FILLED);
    if (!p.label.empty()) {
      cv::line(out, {10, legend_y}, {34, legend_y}, p.colour, 3, cv::LINE_AA);
      cv::putText(out, p.label, {40, legend_y + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45,
                  cv::Scalar(40, 40, 40), 1, cv::LINE_AA);
      legend_y += 18;
    }
  }
  // Scale bar, bottom left: one grid step.
  const int bar_px = static_cast<int>(std::lround(step * scale));
  const cv::Point bar_from(12, height_px - 14), bar_to(12 + bar_px, height_px - 14);
  cv::line(out, bar_from, bar_to, cv::Scalar(0, 0, 0), 2);
  cv::line(out, bar_from - cv::Point(0, 5), bar_from + cv::Point(0, 5), cv::Scalar(0, 0, 0), 2);
  cv::line(out, bar_to - cv::Point(0, 5), bar_to + cv::Point(0, 5), cv::Scalar(0, 0, 0), 2);
  char bar_label[64];
  std::snprintf(bar_label, sizeof(bar_label), "%g %s", step, unit.c_str());
  cv::putText(out, bar_label, bar_to + cv::Point(8, 5), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  char caption[200];
  std::snprintf(caption, sizeof(caption), "%s   (grid %g %s)", title.c_str(), step, unit.c_str());
  cv::putText(out, caption, {10, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  return out;
}

}  // namespace slapse
