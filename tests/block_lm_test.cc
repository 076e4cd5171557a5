// BlockLmProblem (core/refine/block_lm.h): Ceres' Levenberg-Marquardt step for
// step on a problem with a quaternion, vectors and a constant block; its
// contract errors; a cost that cannot be evaluated.
#include "core/refine/block_lm.h"

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <vector>

#include <ceres/ceres.h>
#include <Eigen/Geometry>

namespace slapse {
namespace {

// A camera (q world_from_cam, centre c) sees world point X at pixel u:
//   r = (f * dehom(R^T (X - c)) - u) / sigma,
// with X = s * X0 for a scale block s (so the problem mixes a rotation, a
// vector and a scalar, like the window refiner's poses and planes).
struct ProjectionResidual {
  ProjectionResidual(const Eigen::Vector3d& X0, const Eigen::Vector2d& u) : X0(X0), u(u) {}
  template <typename T>
  bool operator()(const T* q, const T* c, const T* s, T* r) const {
    const Eigen::Map<const Eigen::Quaternion<T>> qm(q);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> cm(c);
    const Eigen::Matrix<T, 3, 1> Xc = qm.conjugate() * (X0.cast<T>() * s[0] - cm);
    if (!(Xc.z() > T(1e-6))) return false;
    r[0] = (T(500.0) * Xc.x() / Xc.z() - T(u.x())) / T(0.5);
    r[1] = (T(500.0) * Xc.y() / Xc.z() - T(u.y())) / T(0.5);
    return true;
  }
  Eigen::Vector3d X0;
  Eigen::Vector2d u;
};

// r = a - b, to pass one block twice.
struct Difference {
  template <typename T>
  bool operator()(const T* a, const T* b, T* r) const {
    r[0] = a[0] - b[0];
    return true;
  }
};

// A prior on the scale: r = (s - 1) / 0.1.
struct ScalePrior {
  template <typename T>
  bool operator()(const T* s, T* r) const {
    r[0] = (s[0] - T(1.0)) / T(0.1);
    return true;
  }
};

struct Params {
  Eigen::Quaterniond q;
  Eigen::Vector3d c;
  double s = 1.0;
  Eigen::Vector3d fixed{0.5, 0.5, 0.5};  // a constant block no residual needs
};

struct Scene {
  std::vector<Eigen::Vector3d> X0;
  std::vector<Eigen::Vector2d> u;
};

// 40 points 4-12 m ahead, seen by a camera rotated ~6 deg and moved ~0.5 m
// from the guess, with 0.5 px noise (fixed seed).
Scene MakeScene(Params* guess) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> xy(-3, 3), depth(4, 12);
  std::normal_distribution<double> noise(0, 0.5);
  const Eigen::Quaterniond q_true(
      Eigen::AngleAxisd(0.1, Eigen::Vector3d(0.2, 1, 0.1).normalized()));
  const Eigen::Vector3d c_true(0.3, -0.2, 0.4);
  const double s_true = 1.05;
  Scene scene;
  for (int j = 0; j < 40; ++j) {
    const Eigen::Vector3d X0(xy(rng), xy(rng), depth(rng));
    const Eigen::Vector3d Xc = q_true.conjugate() * (s_true * X0 - c_true);
    scene.X0.push_back(X0);
    scene.u.push_back(500.0 * Xc.head<2>() / Xc.z() + Eigen::Vector2d(noise(rng), noise(rng)));
  }
  guess->q = Eigen::Quaterniond::Identity();
  guess->c = Eigen::Vector3d(0.0, 0.1, 0.0);
  guess->s = 1.0;
  return scene;
}

ceres::CostFunction* Projection(const Scene& scene, int j) {
  return new ceres::AutoDiffCostFunction<ProjectionResidual, 2, 4, 3, 1>(
      new ProjectionResidual(scene.X0[j], scene.u[j]));
}

// Ceres' own solve of the same problem, Levenberg-Marquardt, dense QR.
double SolveWithCeres(const Scene& scene, int iterations, Params* p) {
  ceres::Problem problem;
  problem.AddParameterBlock(p->q.coeffs().data(), 4, new ceres::EigenQuaternionManifold);
  for (size_t j = 0; j < scene.X0.size(); ++j) {
    problem.AddResidualBlock(Projection(scene, j), nullptr, p->q.coeffs().data(), p->c.data(),
                             &p->s);
  }
  problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ScalePrior, 1, 1>(new ScalePrior),
                           nullptr, &p->s);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = iterations;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return summary.final_cost;
}

BlockLmSummary SolveWithBlockLm(const Scene& scene, int iterations, Params* p) {
  BlockLmProblem problem;
  EXPECT_TRUE(problem.AddQuaternionBlock(p->q.coeffs().data()).ok());
  EXPECT_TRUE(problem.AddVectorBlock(p->c.data(), 3).ok());
  EXPECT_TRUE(problem.AddVectorBlock(&p->s, 1).ok());
  EXPECT_TRUE(problem.AddVectorBlock(p->fixed.data(), 3).ok());
  EXPECT_TRUE(problem.SetConstant(p->fixed.data()).ok());
  for (size_t j = 0; j < scene.X0.size(); ++j) {
    EXPECT_TRUE(problem
                    .AddResidualBlock(std::unique_ptr<ceres::CostFunction>(Projection(scene, j)),
                                      {p->q.coeffs().data(), p->c.data(), &p->s})
                    .ok());
  }
  EXPECT_TRUE(problem
                  .AddResidualBlock(std::make_unique<ceres::AutoDiffCostFunction<ScalePrior, 1, 1>>(
                                        new ScalePrior),
                                    {&p->s})
                  .ok());
  EXPECT_EQ(problem.num_residuals(), 81);
  BlockLmOptions options;
  options.max_iterations = iterations;
  BlockLmSummary summary;
  EXPECT_TRUE(problem.Solve(options, &summary).ok());
  return summary;
}

TEST(BlockLmTest, TakesCeresStepsAndReachesItsMinimum) {
  // After 1, 2 and 3 iterations (before any tolerance stops either), and at convergence.
  for (int iterations : {1, 2, 3, 50}) {
    SCOPED_TRACE(iterations);
    Params ours, theirs;
    const Scene scene = MakeScene(&ours);
    MakeScene(&theirs);
    const BlockLmSummary summary = SolveWithBlockLm(scene, iterations, &ours);
    const double ceres_cost = SolveWithCeres(scene, iterations, &theirs);
    EXPECT_LT(summary.final_cost, summary.initial_cost);
    EXPECT_NEAR(summary.final_cost, ceres_cost, 1e-9 * ceres_cost);
    EXPECT_LT(ours.q.angularDistance(theirs.q), 1e-9);
    EXPECT_LT((ours.c - theirs.c).norm(), 1e-9);
    EXPECT_NEAR(ours.s, theirs.s, 1e-9);
    EXPECT_NEAR(ours.q.norm(), 1.0, 1e-12);
    EXPECT_EQ(ours.fixed, Eigen::Vector3d(0.5, 0.5, 0.5));  // constant
    if (iterations == 50) {
      EXPECT_TRUE(summary.converged);
      EXPECT_LT(summary.iterations, 50);
      // 81 residuals at 0.5 px noise, normalised: cost ~ 81 / 2 at the minimum.
      EXPECT_LT(summary.final_cost, 81.0);
    }
  }
}

// r = 10 (x - 1), which cannot be evaluated for x in (0.8, 1.2) nor beyond 2.
class FailsNearTheMinimum : public ceres::SizedCostFunction<1, 1> {
 public:
  bool Evaluate(double const* const* p, double* r, double** j) const override {
    const double x = p[0][0];
    if ((x > 0.8 && x < 1.2) || x > 2.0) return false;
    r[0] = 10.0 * (x - 1.0);
    if (j != nullptr && j[0] != nullptr) j[0][0] = 10.0;
    return true;
  }
};

TEST(BlockLmTest, ACandidateThatCannotBeEvaluatedIsARejectedStep) {
  // From 1.9 the full step lands on 1, where the cost fails: the step is
  // rejected and shorter ones follow, which stop short of 1.2.
  double x = 1.9;
  {
    BlockLmProblem problem;
    ASSERT_TRUE(problem.AddVectorBlock(&x, 1).ok());
    ASSERT_TRUE(problem.AddResidualBlock(std::make_unique<FailsNearTheMinimum>(), {&x}).ok());
    BlockLmSummary summary;
    ASSERT_TRUE(problem.Solve(BlockLmOptions(), &summary).ok());
    EXPECT_GE(x, 1.2);
    EXPECT_LT(x, 1.3);
    EXPECT_GT(summary.iterations, summary.successful_steps);
    EXPECT_GT(summary.successful_steps, 0);
    EXPECT_NEAR(summary.final_cost, 0.5 * 100 * (x - 1) * (x - 1), 1e-12);
  }
  x = 2.5;  // an error when the start itself cannot be evaluated, the value untouched
  BlockLmProblem problem;
  ASSERT_TRUE(problem.AddVectorBlock(&x, 1).ok());
  ASSERT_TRUE(problem.AddResidualBlock(std::make_unique<FailsNearTheMinimum>(), {&x}).ok());
  const Status s = problem.Solve(BlockLmOptions(), nullptr);
  EXPECT_EQ(s.code(), StatusCode::kInternal) << s.ToString();
  EXPECT_EQ(x, 2.5);
}

// The scene's projection residuals as one NormalEquationsCost: its normal
// equations formed from the stacked autodiff Jacobians over the ambient
// coordinates (q's four, c's three, s), as a cost that knows its structure
// would form them more cheaply.
class StackedProjections : public NormalEquationsCost {
 public:
  explicit StackedProjections(const Scene& scene) {
    for (size_t j = 0; j < scene.X0.size(); ++j) parts_.emplace_back(Projection(scene, j));
    set_num_residuals(2 * static_cast<int>(parts_.size()));
    *mutable_parameter_block_sizes() = {4, 3, 1};
  }
  bool Evaluate(double const* const* p, double* r, double** jac) const override {
    for (size_t j = 0; j < parts_.size(); ++j) {
      double* part_jac[3] = {nullptr, nullptr, nullptr};
      for (int b = 0; b < 3 && jac != nullptr; ++b) {
        if (jac[b] != nullptr) part_jac[b] = jac[b] + 2 * j * parameter_block_sizes()[b];
      }
      if (!parts_[j]->Evaluate(p, r + 2 * j, jac != nullptr ? part_jac : nullptr)) return false;
    }
    return true;
  }
  bool EvaluateNormalEquations(double const* const* p, double* half, Eigen::VectorXd* g,
                               Eigen::MatrixXd* H) const override {
    const int m = num_residuals();
    std::vector<double> r(m), jq(m * 4), jc(m * 3), js(m);
    double* jac[3] = {jq.data(), jc.data(), js.data()};
    if (!Evaluate(p, r.data(), jac)) return false;
    Eigen::MatrixXd J(m, 8);
    for (int i = 0; i < m; ++i) {
      J.row(i) << jq[4 * i], jq[4 * i + 1], jq[4 * i + 2], jq[4 * i + 3], jc[3 * i], jc[3 * i + 1],
          jc[3 * i + 2], js[i];
    }
    const Eigen::Map<const Eigen::VectorXd> rv(r.data(), m);
    *half = 0.5 * rv.squaredNorm();
    *g = J.transpose() * rv;
    *H = J.transpose() * J;
    return true;
  }

 private:
  std::vector<std::unique_ptr<ceres::CostFunction>> parts_;
};

// The solve from the stacked block's normal equations takes the same steps as
// the one from the per-point Jacobians, with every block free and with the
// centre held constant (its rows of the ambient normal equations are then
// dropped).
TEST(BlockLmTest, NormalEquationsCostTakesTheSameSteps) {
  for (bool centre_constant : {false, true}) {
    for (int iterations : {1, 3, 50}) {
      SCOPED_TRACE(::testing::Message()
                   << "centre constant " << centre_constant << ", " << iterations << " iterations");
      Params a, b;
      const Scene scene = MakeScene(&a);
      MakeScene(&b);
      BlockLmSummary sa, sb;
      for (Params* p : {&a, &b}) {
        BlockLmProblem problem;
        ASSERT_TRUE(problem.AddQuaternionBlock(p->q.coeffs().data()).ok());
        ASSERT_TRUE(problem.AddVectorBlock(p->c.data(), 3).ok());
        ASSERT_TRUE(problem.AddVectorBlock(&p->s, 1).ok());
        if (centre_constant) {
          ASSERT_TRUE(problem.SetConstant(p->c.data()).ok());
        }
        const std::vector<double*> blocks = {p->q.coeffs().data(), p->c.data(), &p->s};
        if (p == &a) {
          for (size_t j = 0; j < scene.X0.size(); ++j) {
            ASSERT_TRUE(problem
                            .AddResidualBlock(
                                std::unique_ptr<ceres::CostFunction>(Projection(scene, j)), blocks)
                            .ok());
          }
        } else {
          ASSERT_TRUE(
              problem.AddResidualBlock(std::make_unique<StackedProjections>(scene), blocks).ok());
        }
        ASSERT_TRUE(
            problem
                .AddResidualBlock(
                    std::make_unique<ceres::AutoDiffCostFunction<ScalePrior, 1, 1>>(new ScalePrior),
                    {&p->s})
                .ok());
        BlockLmOptions options;
        options.max_iterations = iterations;
        ASSERT_TRUE(problem.Solve(options, p == &a ? &sa : &sb).ok());
      }
      EXPECT_LT(sb.final_cost, sb.initial_cost);
      EXPECT_NEAR(sb.final_cost, sa.final_cost, 1e-9 * sa.final_cost);
      EXPECT_EQ(sb.iterations, sa.iterations);
      EXPECT_LT(a.q.angularDistance(b.q), 1e-9);
      EXPECT_LT((a.c - b.c).norm(), 1e-9);
      EXPECT_NEAR(a.s, b.s, 1e-9);
      if (centre_constant) {
        EXPECT_EQ(b.c, Eigen::Vector3d(0.0, 0.1, 0.0));
      }
    }
  }
}

TEST(BlockLmTest, ContractErrors) {
  double x[3] = {0, 0, 0}, y = 0, q[4] = {0, 0, 0, 1};
  BlockLmProblem problem;
  ASSERT_TRUE(problem.AddVectorBlock(x, 3).ok());
  EXPECT_FALSE(problem.AddVectorBlock(x, 3).ok());  // twice
  EXPECT_FALSE(problem.AddVectorBlock(nullptr, 3).ok());
  EXPECT_FALSE(problem.AddVectorBlock(&y, 0).ok());
  EXPECT_FALSE(problem.SetConstant(&y).ok());  // unregistered
  ASSERT_TRUE(problem.AddQuaternionBlock(q).ok());
  EXPECT_FALSE(problem.AddQuaternionBlock(q).ok());
  // Wrong size, unregistered, wrong number of blocks, one block twice.
  EXPECT_FALSE(problem.AddResidualBlock(std::make_unique<FailsNearTheMinimum>(), {x}).ok());
  EXPECT_FALSE(problem.AddResidualBlock(std::make_unique<FailsNearTheMinimum>(), {&y}).ok());
  EXPECT_FALSE(problem.AddResidualBlock(std::make_unique<FailsNearTheMinimum>(), {}).ok());
  ASSERT_TRUE(problem.AddVectorBlock(&y, 1).ok());
  EXPECT_FALSE(
      problem
          .AddResidualBlock(
              std::make_unique<ceres::AutoDiffCostFunction<Difference, 1, 1, 1>>(new Difference),
              {&y, &y})
          .ok());
  EXPECT_EQ(problem.num_residuals(), 0);
  BlockLmOptions bad;
  bad.max_iterations = 0;
  EXPECT_EQ(bad.Check().code(), StatusCode::kInvalidArgument);
  bad = BlockLmOptions();
  bad.function_tolerance = 0;
  EXPECT_EQ(problem.Solve(bad, nullptr).code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(BlockLmOptions().Check().ok());
}

}  // namespace
}  // namespace slapse
