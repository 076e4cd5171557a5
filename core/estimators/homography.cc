#include "core/estimators/homography.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace slapse {
namespace {

// A minimal sample is degenerate when three of its points are (nearly) on a
// line: the height of the triangle over its longest side, relative to that
// side, is below this. 1e-2 is ~3 px off a 300 px line: such samples give a
// homography dominated by the MV noise (0.1-0.5 px) and are not worth scoring.
constexpr double kMinTriangleHeightRatio = 1e-2;
// The DLT system must have a one-dimensional null space: its 8th singular
// value relative to the largest (both in normalised coordinates) above this.
constexpr double kMinDltRankRatio = 1e-8;
// H (in normalised coordinates) is near-singular when sigma_3 / sigma_1 is below this.
constexpr double kMinHomographyConditionRatio = 1e-6;
// Residuals: w = (H x)_z at or below this fraction of |h31 u| + |h32 v| + |h33|
// counts as "mapped to or behind infinity".
constexpr double kMinRelativeW = 1e-10;

// Similarity T with T * [p; 1] centred on the centroid, mean distance sqrt(2).
// False when all points coincide.
bool HartleyNormalization(const std::vector<Eigen::Vector2d>& points, Eigen::Matrix3d* T,
                          std::vector<Eigen::Vector2d>* normalized) {
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (const auto& p : points) centroid += p;
  centroid /= static_cast<double>(points.size());
  double mean_dist = 0.0;
  for (const auto& p : points) mean_dist += (p - centroid).norm();
  mean_dist /= static_cast<double>(points.size());
  if (!(mean_dist > 1e-12 * (1.0 + centroid.norm())) || !std::isfinite(mean_dist)) return false;
  const double s = std::sqrt(2.0) / mean_dist;
  *T << s, 0, -s * centroid.x(), 0, s, -s * centroid.y(), 0, 0, 1;
  normalized->resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) (*normalized)[i] = s * (points[i] - centroid);
  return true;
}

bool HasCollinearTriple(const std::vector<Eigen::Vector2d>& p) {
  const int n = static_cast<int>(p.size());
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      for (int c = b + 1; c < n; ++c) {
        const Eigen::Vector2d ab = p[b] - p[a], ac = p[c] - p[a], bc = p[c] - p[b];
        const double longest = std::max({ab.norm(), ac.norm(), bc.norm()});
        const double twice_area = std::abs(ab.x() * ac.y() - ab.y() * ac.x());
        // height over the longest side = twice_area / longest; relative to longest:
        if (!(twice_area > kMinTriangleHeightRatio * longest * longest)) return true;
      }
    }
  }
  return false;
}

}  // namespace

void HomographyEstimator::Estimate(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                                   std::vector<M_t>* models) {
  models->clear();
  const int n = static_cast<int>(X.size());
  if (n < kMinNumSamples || Y.size() != X.size()) return;

  Eigen::Matrix3d Tx, Ty;
  std::vector<Eigen::Vector2d> xn, yn;
  if (!HartleyNormalization(X, &Tx, &xn) || !HartleyNormalization(Y, &Ty, &yn)) return;
  const bool minimal = n == kMinNumSamples;
  if (minimal && (HasCollinearTriple(xn) || HasCollinearTriple(yn))) return;

  // y x (H x) = 0 gives two independent rows per correspondence, with h the
  // row-major entries of H: [0, -x^T, v x^T] and [x^T, 0, -u x^T].
  Eigen::Matrix<double, Eigen::Dynamic, 9> A(2 * n, 9);
  for (int i = 0; i < n; ++i) {
    const Eigen::RowVector3d x(xn[i].x(), xn[i].y(), 1.0);
    const double u = yn[i].x(), v = yn[i].y();
    A.row(2 * i) << 0, 0, 0, -x, v * x;
    A.row(2 * i + 1) << x, 0, 0, 0, -u * x;
  }
  Eigen::JacobiSVD<Eigen::Matrix<double, Eigen::Dynamic, 9>> svd(A, Eigen::ComputeFullV);
  const Eigen::VectorXd& sv = svd.singularValues();
  if (!(sv(0) > 0.0) || !(sv(7) > kMinDltRankRatio * sv(0))) return;
  const Eigen::Matrix<double, 9, 1> h = svd.matrixV().col(8);
  Eigen::Matrix3d Hn;
  Hn << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);

  const Eigen::Vector3d hsv = Eigen::JacobiSVD<Eigen::Matrix3d>(Hn).singularValues();
  if (!(hsv(2) > kMinHomographyConditionRatio * hsv(0))) return;

  // Orientation: the sign of w = (H x)_z is the same in normalised and pixel
  // coordinates (T's last row is [0 0 1] and its scale is positive).
  int num_positive = 0, num_negative = 0;
  for (int i = 0; i < n; ++i) {
    const double w = Hn.row(2).dot(Eigen::Vector3d(xn[i].x(), xn[i].y(), 1.0));
    if (w > 0) ++num_positive;
    if (w < 0) ++num_negative;
  }
  if (minimal && num_positive != n && num_negative != n) return;  // straddles infinity
  if (num_negative > num_positive) Hn = -Hn;

  Eigen::Matrix3d H = Ty.inverse() * Hn * Tx;
  const double norm = H.norm();
  if (!(norm > 0.0) || !H.allFinite()) return;
  models->push_back(H / norm);
}

void HomographyEstimator::Residuals(const std::vector<X_t>& X, const std::vector<Y_t>& Y,
                                    const M_t& H, std::vector<double>* squared_residuals) {
  squared_residuals->resize(X.size());
  for (size_t i = 0; i < X.size(); ++i) {
    const Eigen::Vector3d hx = H * X[i].homogeneous();
    const double w_scale =
        std::abs(H(2, 0) * X[i].x()) + std::abs(H(2, 1) * X[i].y()) + std::abs(H(2, 2));
    if (!(hx.z() > kMinRelativeW * w_scale)) {
      (*squared_residuals)[i] = std::numeric_limits<double>::infinity();
      continue;
    }
    (*squared_residuals)[i] = (Y[i] - hx.hnormalized()).squaredNorm();
  }
}

}  // namespace slapse
