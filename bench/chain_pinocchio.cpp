// Pinocchio's articulated-body algorithm on the n-link chain of
// bench/chain_peers.py (bench/chain_scaling.sh): revolute joints about +y,
// link i's joint L above the previous one, its centre of mass c above its
// joint, mass m, inertia J about every axis; the joint friction -b q' and the
// torque at joint 1 go into the joint torques. A C ABI for the C harness.
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/multibody.hpp>


namespace pin = pinocchio;

static pin::Model *model;
static pin::Data *data;
static Eigen::VectorXd q, v, tau;
static double friction;

extern "C" void pin_chain_new(int n, double m, double L, double c, double J, double b, double g) {
  model = new pin::Model();
  pin::JointIndex parent = 0;
  for (int i = 0; i < n; i++) {
    pin::SE3 place = pin::SE3::Identity();
    if (i > 0) place.translation() = Eigen::Vector3d(0, 0, L);
    parent = model->addJoint(parent, pin::JointModelRY(), place, "j" + std::to_string(i));
    model->appendBodyToJoint(parent, pin::Inertia(m, Eigen::Vector3d(0, 0, c), J * Eigen::Matrix3d::Identity()),
                             pin::SE3::Identity());
  }
  model->gravity.linear(Eigen::Vector3d(0, 0, -g));
  data = new pin::Data(*model);
  q.resize(n);
  v.resize(n);
  tau.resize(n);
  friction = b;
}

extern "C" void pin_chain_dyn(const double *x, const double *u, double *out) {
  const int n = (int)q.size();
  for (int i = 0; i < n; i++) {
    q[i] = x[i];
    v[i] = x[n + i];
    tau[i] = -friction * x[n + i];
  }
  tau[0] += u[0];
  pin::aba(*model, *data, q, v, tau);
  for (int i = 0; i < n; i++) {
    out[i] = x[n + i];
    out[n + i] = data->ddq[i];
  }
}
