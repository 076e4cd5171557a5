// Levenberg-Marquardt for small least-squares problems: a few parameter blocks
// (unit quaternions and vectors), residual blocks that are ceres::CostFunction
// objects, and the normal equations held dense.
//
// Why not ceres::Solve: the window refiner's problems have 30-60 tangent
// parameters and ~300 macroblock residuals, solved at every anchor pair.
// There Ceres' general machinery (program building, block-sparse Jacobian,
// CHOLMOD) took most of a solve's time; accumulating J^T J block by block into
// a dense matrix and factoring it with Eigen gives the same iterates at a
// fraction of the cost (docs/BENCHMARKS.md "Window refinement").
//
// The minimiser is Ceres' trust-region Levenberg-Marquardt, step for step:
//   cost(x)  = 1/2 sum_k |r_k(x)|^2
//   step dx: (J^T J + D / radius) dx = -J^T r,  D = diag(J^T J) clamped as
//            Ceres clamps it in its Jacobi-scaled variables ([1e-6, 1e32]);
//   rho      = (cost(x) - cost(x [+] dx)) / (-(g^T dx + 1/2 dx^T J^T J dx));
//   accepted when rho > 1e-3: radius /= max(1/3, 1 - (2 rho - 1)^3), the
//   decrease factor back to 2; else radius /= factor, factor *= 2.
// It stops after max_iterations steps (taken or not), or when a step changes
// the cost by at most function_tolerance * cost, its length is at most
// parameter_tolerance * (|x| + parameter_tolerance), or the gradient's max
// norm is at most gradient_tolerance.
//
// Quaternion blocks are Eigen's coefficient order (x, y, z, w), updated on
// the left: q [+] d = Exp(d) q with d a rotation vector (rad). The damping
// D is invariant to the tangent's scale, so this takes the same steps as
// ceres::EigenQuaternionManifold (whose tangent is half the angle).
//
// A residual block that is a NormalEquationsCost gives its J^T J and J^T r
// itself instead of its Jacobian (below); the solve is the same.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <ceres/cost_function.h>
#include <Eigen/Core>

#include "core/common/status.h"

namespace slapse {

// A cost whose many residuals depend on the parameters only through a few
// intermediate values (the window refiner's plane transfer: a block's ~100
// macroblocks through one 3x3 homography) can form its normal equations from
// the intermediates' small normal matrix, J^T J = D^T (A^T A) D with
// A = dr/dh and D = dh/dp, which is much cheaper than the m x p Jacobian and
// its rank update. BlockLmProblem then calls EvaluateNormalEquations where it
// needs the Jacobian; Evaluate still serves the cost alone.
class NormalEquationsCost : public ceres::CostFunction {
 public:
  // At `parameters`: *half_squared_norm = 1/2 |r|^2, *gradient = J^T r and
  // *normal = J^T J (symmetric), over the ambient coordinates of all the
  // parameter blocks in order (a quaternion's four), p = the sum of the
  // block sizes; the outputs are resized to p. False exactly where Evaluate
  // would fail.
  virtual bool EvaluateNormalEquations(double const* const* parameters, double* half_squared_norm,
                                       Eigen::VectorXd* gradient,
                                       Eigen::MatrixXd* normal) const = 0;
};

struct BlockLmOptions {
  int max_iterations = 50;
  double initial_radius = 1e4;
  double function_tolerance = 1e-6;
  double parameter_tolerance = 1e-8;
  double gradient_tolerance = 1e-10;

  // InvalidArgument unless max_iterations >= 1 and every other field > 0.
  Status Check(const std::string& who = "BlockLmOptions") const;
};

struct BlockLmSummary {
  double initial_cost = 0;  // 1/2 sum r^2 at the start
  double final_cost = 0;    // at the returned parameters
  int iterations = 0;       // steps tried, taken or not
  int successful_steps = 0;
  bool converged = false;  // a tolerance was met (else max_iterations ran out)
};

class BlockLmProblem {
 public:
  BlockLmProblem() = default;
  BlockLmProblem(const BlockLmProblem&) = delete;
  BlockLmProblem& operator=(const BlockLmProblem&) = delete;

  // Registers parameters owned by the caller (they must outlive Solve, which
  // updates them in place). Registering one pointer twice is an error.
  Status AddQuaternionBlock(double* q_xyzw);
  Status AddVectorBlock(double* x, int size);
  // Held at their values (no column in the normal equations).
  Status SetConstant(const double* block);
  // `blocks` in the order of cost's parameter blocks, each registered, with
  // the sizes the cost declares.
  Status AddResidualBlock(std::unique_ptr<ceres::CostFunction> cost,
                          const std::vector<double*>& blocks);

  int num_residuals() const { return num_residuals_; }

  // Minimises from the blocks' current values. An error when the cost cannot
  // be evaluated at the start (a cost returned false, or a non-finite value);
  // a candidate that cannot be evaluated is a rejected step.
  Status Solve(const BlockLmOptions& options, BlockLmSummary* summary);

 private:
  struct Block {
    double* data = nullptr;
    int size = 0;     // ambient (4 for a quaternion)
    int tangent = 0;  // 3 for a quaternion
    bool quaternion = false;
    bool constant = false;
    int offset = -1;  // in the tangent vector; -1 when constant
  };
  struct Residual {
    std::unique_ptr<ceres::CostFunction> cost;
    const NormalEquationsCost* normal = nullptr;  // cost, when it is one
    std::vector<int> blocks;                      // indices into blocks_
  };
  class Evaluator;

  int FindBlock(const double* data) const;
  std::vector<double> Save() const;
  void Restore(const std::vector<double>& values);
  bool PlusOrConverged(const Eigen::VectorXd& dx, double parameter_tolerance);

  std::vector<Block> blocks_;
  std::vector<Residual> residuals_;
  int num_residuals_ = 0;
};

}  // namespace slapse
