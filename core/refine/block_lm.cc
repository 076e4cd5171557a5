#include "core/refine/block_lm.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/common/so3.h"

namespace slapse {
namespace {

using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// d(Exp(d) q)/dd at d = 0 in Eigen's coefficient order (x, y, z, w): with
// Exp(d) ~ (1, d/2), the product's vector part is v + (w d + d x v) / 2 and
// its scalar part w - d.v / 2 (d x v = -[v]x d).
Eigen::Matrix<double, 4, 3> QuaternionPlusJacobian(const double* q_xyzw) {
  const Eigen::Vector3d v(q_xyzw[0], q_xyzw[1], q_xyzw[2]);
  const double w = q_xyzw[3];
  Eigen::Matrix<double, 4, 3> P;
  P.topRows<3>() = w * Eigen::Matrix3d::Identity() - Skew(v);
  P.row(3) = -v.transpose();
  return 0.5 * P;
}

// q [+] d = Exp(d) q, renormalised.
void QuaternionPlus(const double* q_xyzw, const double* d, double* out_xyzw) {
  const Eigen::Vector3d delta(d[0], d[1], d[2]);
  const double angle = delta.norm();
  Eigen::Quaterniond exp_d = Eigen::Quaterniond::Identity();
  if (angle > 0) exp_d = Eigen::Quaterniond(Eigen::AngleAxisd(angle, delta / angle));
  const Eigen::Quaterniond q(q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]);
  Eigen::Map<Eigen::Quaterniond> out(out_xyzw);
  out = (exp_d * q).normalized();
}

}  // namespace

Status BlockLmOptions::Check(const std::string& who) const {
  if (max_iterations < 1 || !(initial_radius > 0) || !(function_tolerance > 0) ||
      !(parameter_tolerance > 0) || !(gradient_tolerance > 0)) {
    return InvalidArgumentError(who +
                                ": max_iterations must be >= 1 and every tolerance and "
                                "the initial radius > 0");
  }
  return Status::Ok();
}

int BlockLmProblem::FindBlock(const double* data) const {
  for (size_t i = 0; i < blocks_.size(); ++i) {
    if (blocks_[i].data == data) return static_cast<int>(i);
  }
  return -1;
}

Status BlockLmProblem::AddQuaternionBlock(double* q_xyzw) {
  if (q_xyzw == nullptr || FindBlock(q_xyzw) >= 0) {
    return InvalidArgumentError("BlockLmProblem: a null or already registered quaternion block");
  }
  blocks_.push_back({q_xyzw, 4, 3, true, false, -1});
  return Status::Ok();
}

Status BlockLmProblem::AddVectorBlock(double* x, int size) {
  if (x == nullptr || size < 1 || FindBlock(x) >= 0) {
    return InvalidArgumentError("BlockLmProblem: a null, empty or already registered block");
  }
  blocks_.push_back({x, size, size, false, false, -1});
  return Status::Ok();
}

Status BlockLmProblem::SetConstant(const double* block) {
  const int i = FindBlock(block);
  if (i < 0) return InvalidArgumentError("BlockLmProblem::SetConstant: an unregistered block");
  blocks_[i].constant = true;
  return Status::Ok();
}

Status BlockLmProblem::AddResidualBlock(std::unique_ptr<ceres::CostFunction> cost,
                                        const std::vector<double*>& blocks) {
  if (cost == nullptr || cost->parameter_block_sizes().size() != blocks.size()) {
    return InvalidArgumentError(
        "BlockLmProblem::AddResidualBlock: the cost's parameter blocks and the given ones differ "
        "in number");
  }
  Residual r;
  for (size_t k = 0; k < blocks.size(); ++k) {
    const int i = FindBlock(blocks[k]);
    if (i < 0 || blocks_[i].size != cost->parameter_block_sizes()[k]) {
      return InvalidArgumentError("BlockLmProblem::AddResidualBlock: parameter block " +
                                  std::to_string(k) +
                                  " is unregistered or not of the size the cost declares");
    }
    if (std::find(r.blocks.begin(), r.blocks.end(), i) != r.blocks.end()) {
      return InvalidArgumentError("BlockLmProblem::AddResidualBlock: parameter block " +
                                  std::to_string(k) + " is passed twice");
    }
    r.blocks.push_back(i);
  }
  num_residuals_ += cost->num_residuals();
  r.normal = dynamic_cast<const NormalEquationsCost*>(cost.get());
  r.cost = std::move(cost);
  residuals_.push_back(std::move(r));
  return Status::Ok();
}

// Evaluates the residual blocks at the blocks' current values: the cost, and
// on request the gradient g = J^T r and the normal matrix H = J^T J over the
// tangent parameters, accumulated block by block (a residual block touching
// b tangent parameters adds b x b entries).
class BlockLmProblem::Evaluator {
 public:
  Evaluator(const std::vector<Block>& blocks, const std::vector<Residual>& residuals, int n)
      : blocks_(blocks), residuals_(residuals), n_(n) {}

  // False when a cost returns false or is not finite.
  bool Evaluate(bool with_jacobian, double* cost, Eigen::VectorXd* g, Eigen::MatrixXd* H) {
    *cost = 0;
    if (with_jacobian) {
      g->setZero(n_);
      H->setZero(n_, n_);
    }
    for (const Residual& res : residuals_) {
      const int m = res.cost->num_residuals();
      const size_t nb = res.blocks.size();
      r_.resize(m);
      params_.resize(nb);
      jac_ptrs_.assign(nb, nullptr);
      size_t jac_size = 0;
      for (size_t k = 0; k < nb; ++k) {
        const Block& b = blocks_[res.blocks[k]];
        params_[k] = b.data;
        if (with_jacobian && !b.constant) jac_size += static_cast<size_t>(m) * b.size;
      }
      if (with_jacobian && res.normal != nullptr) {
        double half = 0;
        if (!res.normal->EvaluateNormalEquations(params_.data(), &half, &g_ambient_, &H_ambient_) ||
            !std::isfinite(half) || !AccumulateNormal(res, g, H)) {
          return false;
        }
        *cost += half;
        continue;
      }
      if (jac_.size() < jac_size) jac_.resize(jac_size);
      for (size_t k = 0, at = 0; k < nb && with_jacobian; ++k) {
        const Block& b = blocks_[res.blocks[k]];
        if (b.constant) continue;
        jac_ptrs_[k] = jac_.data() + at;
        at += static_cast<size_t>(m) * b.size;
      }
      if (!res.cost->Evaluate(params_.data(), r_.data(),
                              with_jacobian ? jac_ptrs_.data() : nullptr))
        return false;
      double sq = 0;
      for (double v : r_) sq += v * v;
      if (!std::isfinite(sq)) return false;
      *cost += 0.5 * sq;
      if (with_jacobian && !Accumulate(res, m, g, H)) return false;
    }
    return std::isfinite(*cost);
  }

 private:
  // The block's Jacobian in tangent coordinates J (row-major, m x t: a
  // quaternion's 4 columns times its plus-Jacobian), then g += J^T r and
  // H += J^T J scattered to the blocks' offsets. J^T J is one triangle
  // (Eigen's symmetric rank update, half a general product's work); the
  // buffers live across blocks, so nothing is allocated per block.
  bool Accumulate(const Residual& res, int m, Eigen::VectorXd* g, Eigen::MatrixXd* H) {
    int t = 0;
    global_.clear();
    for (size_t k = 0; k < res.blocks.size(); ++k) {
      const Block& b = blocks_[res.blocks[k]];
      if (b.constant) continue;
      for (int c = 0; c < b.tangent; ++c) global_.push_back(b.offset + c);
      t += b.tangent;
    }
    if (t == 0) return true;
    J_.assign(static_cast<size_t>(m) * t, 0.0);
    for (size_t k = 0, col = 0; k < res.blocks.size(); ++k) {
      const Block& b = blocks_[res.blocks[k]];
      if (b.constant) continue;
      const double* jac = jac_ptrs_[k];  // row-major m x b.size
      if (b.quaternion) {
        const Eigen::Matrix<double, 4, 3> P = QuaternionPlusJacobian(b.data);
        for (int i = 0; i < m; ++i) {
          for (int c = 0; c < 3; ++c) {
            double v = 0;
            for (int a = 0; a < 4; ++a) v += jac[i * 4 + a] * P(a, c);
            J_[static_cast<size_t>(i) * t + col + c] = v;
          }
        }
      } else {
        for (int i = 0; i < m; ++i) {
          for (int c = 0; c < b.size; ++c)
            J_[static_cast<size_t>(i) * t + col + c] = jac[i * b.size + c];
        }
      }
      col += b.tangent;
    }
    JtJ_.resize(static_cast<size_t>(t) * t);
    Jtr_.resize(t);
    const Eigen::Map<const RowMajorMatrix> J(J_.data(), m, t);
    // J^T J's lower triangle (column-major), read below as the upper one of
    // the row-major layout: JtJ_[a * t + b], b >= a.
    Eigen::Map<Eigen::MatrixXd> JtJ(JtJ_.data(), t, t);
    JtJ.setZero();
    JtJ.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
    Eigen::Map<Eigen::VectorXd>(Jtr_.data(), t).noalias() =
        J.transpose() * Eigen::Map<const Eigen::VectorXd>(r_.data(), m);
    return Scatter(t, g, H);
  }

  // A NormalEquationsCost's ambient g_a and H_a (g_ambient_, H_ambient_) in
  // tangent coordinates: with T the ambient-from-tangent map of the
  // non-constant blocks (block diagonal: a quaternion's plus-Jacobian P,
  // else the identity; a constant block has no column), J_t = J_a T, so
  // J_t^T r = T^T g_a and J_t^T J_t = T^T H_a T, formed block by block
  // (rows R = T^T H_a, then R T).
  bool AccumulateNormal(const Residual& res, Eigen::VectorXd* g, Eigen::MatrixXd* H) {
    int p = 0, t = 0;
    global_.clear();
    for (int i : res.blocks) {
      p += blocks_[i].size;
      if (blocks_[i].constant) continue;
      for (int c = 0; c < blocks_[i].tangent; ++c) global_.push_back(blocks_[i].offset + c);
      t += blocks_[i].tangent;
    }
    if (g_ambient_.size() != p || H_ambient_.rows() != p || H_ambient_.cols() != p) return false;
    if (t == 0) return true;
    Jtr_.resize(t);
    Eigen::Map<Eigen::VectorXd> Jtr(Jtr_.data(), t);
    R_.resize(t, p);
    int a = 0, row = 0;
    for (int i : res.blocks) {
      const Block& b = blocks_[i];
      if (b.constant) {
        a += b.size;
        continue;
      }
      if (b.quaternion) {
        const Eigen::Matrix<double, 4, 3> P = QuaternionPlusJacobian(b.data);
        R_.middleRows<3>(row).noalias() = P.transpose() * H_ambient_.middleRows<4>(a);
        Jtr.segment<3>(row).noalias() = P.transpose() * g_ambient_.segment<4>(a);
      } else {
        R_.middleRows(row, b.size) = H_ambient_.middleRows(a, b.size);
        Jtr.segment(row, b.size) = g_ambient_.segment(a, b.size);
      }
      a += b.size;
      row += b.tangent;
    }
    JtJ_.resize(static_cast<size_t>(t) * t);
    // Column-major t x t; symmetric, so Scatter may read it as row-major.
    Eigen::Map<Eigen::MatrixXd> JtJ(JtJ_.data(), t, t);
    a = 0;
    int col = 0;
    for (int i : res.blocks) {
      const Block& b = blocks_[i];
      if (!b.constant) {
        if (b.quaternion) {
          JtJ.middleCols<3>(col).noalias() = R_.middleCols<4>(a) * QuaternionPlusJacobian(b.data);
        } else {
          JtJ.middleCols(col, b.size) = R_.middleCols(a, b.size);
        }
        col += b.tangent;
      }
      a += b.size;
    }
    return Scatter(t, g, H);
  }

  // g += Jtr_ and H += JtJ_ (its upper triangle, row-major t x t) at the
  // blocks' offsets (global_).
  bool Scatter(int t, Eigen::VectorXd* g, Eigen::MatrixXd* H) {
    for (int a = 0; a < t; ++a) {
      if (!std::isfinite(Jtr_[a])) return false;
      (*g)[global_[a]] += Jtr_[a];
      for (int b = a; b < t; ++b) {
        const double v = JtJ_[static_cast<size_t>(a) * t + b];
        (*H)(global_[a], global_[b]) += v;
        if (b != a) (*H)(global_[b], global_[a]) += v;
      }
    }
    return true;
  }

  const std::vector<Block>& blocks_;
  const std::vector<Residual>& residuals_;
  const int n_;
  std::vector<double> r_;
  std::vector<const double*> params_;
  std::vector<double*> jac_ptrs_;
  std::vector<double> jac_;  // the cost's Jacobians, block after block
  std::vector<int> global_;  // tangent column -> index in g and H
  std::vector<double> J_, JtJ_, Jtr_;
  Eigen::VectorXd g_ambient_;  // a NormalEquationsCost's outputs
  Eigen::MatrixXd H_ambient_, R_;
};

// The blocks' values, to undo a rejected step.
std::vector<double> BlockLmProblem::Save() const {
  std::vector<double> values;
  for (const Block& b : blocks_) values.insert(values.end(), b.data, b.data + b.size);
  return values;
}

void BlockLmProblem::Restore(const std::vector<double>& values) {
  size_t at = 0;
  for (Block& b : blocks_) {
    std::copy(values.begin() + at, values.begin() + at + b.size, b.data);
    at += b.size;
  }
}

// x [+] dx, and |dx| <= parameter_tolerance (|x| + parameter_tolerance)
// (then nothing is changed and true is returned).
bool BlockLmProblem::PlusOrConverged(const Eigen::VectorXd& dx, double parameter_tolerance) {
  double x_norm2 = 0;
  for (const Block& b : blocks_) {
    if (!b.constant) x_norm2 += Eigen::Map<const Eigen::VectorXd>(b.data, b.size).squaredNorm();
  }
  if (dx.norm() <= parameter_tolerance * (std::sqrt(x_norm2) + parameter_tolerance)) return true;
  for (Block& b : blocks_) {
    if (b.constant) continue;
    if (b.quaternion) {
      double q[4];
      QuaternionPlus(b.data, dx.data() + b.offset, q);
      std::copy(q, q + 4, b.data);
    } else {
      for (int i = 0; i < b.size; ++i) b.data[i] += dx[b.offset + i];
    }
  }
  return false;
}

namespace {

// The damped step (H + D / radius) dx = -g, D = diag(H) clamped as Ceres
// clamps it in Jacobi-scaled variables (column scale 1 / (1 + sqrt(H_ii))).
bool DampedStep(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, double radius,
                Eigen::VectorXd* dx) {
  Eigen::MatrixXd A = H;
  for (int i = 0; i < H.rows(); ++i) {
    const double scale = 1.0 / (1.0 + std::sqrt(std::max(H(i, i), 0.0)));
    const double d_scaled = std::clamp(H(i, i) * scale * scale, 1e-6, 1e32);
    A(i, i) += d_scaled / (scale * scale) / radius;
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(A);
  if (llt.info() != Eigen::Success) return false;
  *dx = llt.solve(-g);
  return dx->allFinite();
}

}  // namespace

Status BlockLmProblem::Solve(const BlockLmOptions& options, BlockLmSummary* summary) {
  if (Status s = options.Check(); !s.ok()) return s;
  BlockLmSummary local;
  BlockLmSummary& sum = summary != nullptr ? *summary : local;
  sum = BlockLmSummary();
  int n = 0;
  for (Block& b : blocks_) {
    b.offset = b.constant ? -1 : n;
    if (!b.constant) n += b.tangent;
  }
  Evaluator eval(blocks_, residuals_, n);
  double cost = 0;
  Eigen::VectorXd g, dx;
  Eigen::MatrixXd H;
  if (!eval.Evaluate(true, &cost, &g, &H)) {
    return InternalError("BlockLmProblem::Solve: the cost cannot be evaluated at the start");
  }
  sum.initial_cost = sum.final_cost = cost;
  double radius = options.initial_radius, decrease_factor = 2.0;
  while (true) {
    if (n == 0 || g.lpNorm<Eigen::Infinity>() <= options.gradient_tolerance) {
      sum.converged = true;
      break;
    }
    if (sum.iterations >= options.max_iterations || radius < 1e-32) break;
    ++sum.iterations;
    bool rejected = !DampedStep(H, g, radius, &dx);
    if (!rejected) {
      const std::vector<double> saved = Save();
      if (PlusOrConverged(dx, options.parameter_tolerance)) {
        sum.converged = true;
        break;
      }
      const double model_change = -(g.dot(dx) + 0.5 * dx.dot(H * dx));
      double new_cost = 0;
      rejected = !(model_change > 0) || !eval.Evaluate(false, &new_cost, nullptr, nullptr);
      if (!rejected && std::abs(cost - new_cost) <= options.function_tolerance * cost) {
        Restore(saved);  // as Ceres: converged, at the point before the step
        sum.converged = true;
        break;
      }
      const double rho = rejected ? 0.0 : (cost - new_cost) / model_change;
      rejected = rejected || !(rho > 1e-3);
      if (rejected) {
        Restore(saved);
      } else {
        radius = std::min(1e16, radius / std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3)));
        decrease_factor = 2.0;
        ++sum.successful_steps;
        if (!eval.Evaluate(true, &cost, &g, &H)) {
          return InternalError("BlockLmProblem::Solve: the Jacobian cannot be evaluated");
        }
        continue;
      }
    }
    radius /= decrease_factor;
    decrease_factor *= 2.0;
  }
  sum.final_cost = cost;
  return Status::Ok();
}

}  // namespace slapse
