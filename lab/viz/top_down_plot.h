// A top-down map (like the paper's Fig. 1(d)): paths, plane traces and
// labelled legend, fitted into a picture with equal axes and a grid.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace slapse {

class TopDownPlot {
 public:
  // Coordinates are map-plane (u, v) in one length unit, v drawn upwards.
  void AddPath(std::vector<Eigen::Vector2d> points, cv::Scalar colour, std::string label,
               int thickness_px = 2);
  void AddPoints(std::vector<Eigen::Vector2d> points, cv::Scalar colour, int radius_px = 2);
  void AddSegment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, cv::Scalar colour,
                  int thickness_px = 2);
  // Renders at the given size, fitted to the paths and what lies within
  // kNearPathFraction of their extent (everything when there is no path),
  // with a grid and a scale bar; `unit` names the length unit.
  cv::Mat Render(int width_px, int height_px, const std::string& title,
                 const std::string& unit) const;
  static constexpr double kNearPathFraction = 0.25;

 private:
  struct Path {
    std::vector<Eigen::Vector2d> points;
    cv::Scalar colour;
    std::string label;
    int thickness;
  };
  struct Dots {
    std::vector<Eigen::Vector2d> points;
    cv::Scalar colour;
    int radius;
  };
  struct Segment {
    Eigen::Vector2d a, b;
    cv::Scalar colour;
    int thickness;
  };
  std::vector<Path> paths_;
  std::vector<Dots> dots_;
  std::vector<Segment> segments_;
};

}  // namespace slapse
