// Times pinocchio::aba on the states alnlab gives it, for `alnlab bench sim
// --pinocchio`. Usage: aba ROBOT.urdf fixed|free STATES.txt PASSES
//
// STATES.txt (written by alnlab): `joints N name…`, `states M`, then M
// lines: for a free base its position, orientation (x y z w), linear and
// angular velocity (base frame); then per joint its position, velocity and
// effort. Joints are matched by name (Pinocchio numbers them depth first);
// a continuous joint's position becomes (cos, sin). Prints
// `ns_per_call <x>`: the wall time of PASSES passes over the M states,
// per call.
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

// The parser first: it brings in the model and data (whose headers moved
// between Pinocchio 3 and 4).
#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

int main(int argc, char** argv) {
  if (argc != 5) {
    std::cerr << "usage: aba ROBOT.urdf fixed|free STATES.txt PASSES\n";
    return 2;
  }
  const std::string base = argv[2];
  pinocchio::Model model;
  if (base == "free") {
    pinocchio::urdf::buildModel(argv[1], pinocchio::JointModelFreeFlyer(), model);
  } else {
    pinocchio::urdf::buildModel(argv[1], model);
  }
  model.gravity.linear(Eigen::Vector3d(0, 0, -9.81));
  pinocchio::Data data(model);

  std::ifstream in(argv[3]);
  std::string word;
  std::size_t joints = 0, count = 0;
  in >> word >> joints;
  std::vector<pinocchio::JointIndex> ids(joints);
  for (auto& id : ids) {
    in >> word;
    if (!model.existJointName(word)) {
      std::cerr << "pinocchio has no joint " << word << "\n";
      return 1;
    }
    id = model.getJointId(word);
  }
  in >> word >> count;
  std::vector<Eigen::VectorXd> qs, vs, taus;
  for (std::size_t s = 0; s < count; ++s) {
    Eigen::VectorXd q = pinocchio::neutral(model);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(model.nv);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    if (base == "free") {
      for (int k = 0; k < 7; ++k) in >> q[k];
      for (int k = 0; k < 6; ++k) in >> v[k];
    }
    for (auto id : ids) {
      const auto& joint = model.joints[id];
      double position, velocity, effort;
      in >> position >> velocity >> effort;
      if (joint.nq() == 2) {
        q[joint.idx_q()] = std::cos(position);
        q[joint.idx_q() + 1] = std::sin(position);
      } else {
        q[joint.idx_q()] = position;
      }
      v[joint.idx_v()] = velocity;
      tau[joint.idx_v()] = effort;
    }
    if (!in) {
      std::cerr << "cannot read state " << s << " of " << argv[3] << "\n";
      return 1;
    }
    qs.push_back(q);
    vs.push_back(v);
    taus.push_back(tau);
  }
  const long passes = std::stol(argv[4]);
  double sink = 0;
  const auto start = std::chrono::steady_clock::now();
  for (long p = 0; p < passes; ++p) {
    for (std::size_t s = 0; s < count; ++s) {
      sink += pinocchio::aba(model, data, qs[s], vs[s], taus[s])[0];
    }
  }
  const auto end = std::chrono::steady_clock::now();
  const double ns = std::chrono::duration<double, std::nano>(end - start).count();
  std::cout << "ns_per_call " << ns / (double(passes) * double(count)) << "\n";
  std::cerr << "checksum " << sink << "\n";
  return 0;
}
