// Native Pinocchio timing of the same bare IRB 2400 model (thesis Tables 7.1 and E.1), for the
// comparison in robot/README.md. Build against the `pin` wheel (pip install pin) and Eigen
// (apt-get install libeigen3-dev):
//
//   P=$(python3 -c "import cmeel, os; print(os.path.join(os.path.dirname(cmeel.__file__), '..', 'cmeel.prefix'))")
//   g++ -O3 -DNDEBUG -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_MPL_LIMIT_LIST_SIZE=30 \
//       -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_FUSION_INVOKE_MAX_ARITY=12 -std=c++17 \
//       -I$P/include -I/usr/include/eigen3 robot/tools/pinocchio_bench.cpp -o pinocchio_bench \
//       -L$P/lib -lpinocchio_default -Wl,-rpath,$P/lib
//   ./pinocchio_bench
//
// Prints the median and minimum over 300 batches of 2000 calls, same state as benches/dynamics.rs.
#include <pinocchio/multibody.hpp>

#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <chrono>
#include <vector>
#include <algorithm>
#include <cstdio>
#include <cmath>
using namespace pinocchio;
int main() {
  double dh[6][3] = {{0.615,0.1,-M_PI/2},{0,0.705,0},{0,0.135,-M_PI/2},{0.755,0,M_PI/2},{0,0,-M_PI/2},{0.085,0,0}};
  double m[6] = {150,47,40,18,0.97,0.57};
  double c[6][3] = {{-0.070,0.17,0.019},{-0.38,0.037,-0.0027},{-0.019,0.010,-0.0011},{0.00030,-0.20,0.0010},{0.00096,4e-7,-0.00019},{-9.1e-5,-9e-7,-0.047}};
  double I[6][6] = {{7.6,1.0,5.8,0.30,-0.10,5.0},{0.38,0.094,2.0,0.0027,-0.025,2.1},{0.93,-0.010,0.91,-0.053,0.011,0.32},{0.52,-0.00038,0.044,-4.3e-5,-0.0036,0.51},{0.00085,0,0.0014,6.9e-6,-2.8e-8,0.00091},{0.00047,0,0.00047,1e-6,0,6.2e-5}};
  Model model; JointIndex parent = 0; SE3 placement = SE3::Identity();
  for (int i = 0; i < 6; ++i) {
    JointIndex j = model.addJoint(parent, JointModelRZ(), placement, "j" + std::to_string(i));
    SE3 X(Eigen::AngleAxisd(dh[i][2], Eigen::Vector3d::UnitX()).toRotationMatrix(), Eigen::Vector3d(dh[i][1], 0, dh[i][0]));
    Eigen::Matrix3d In; In << I[i][0], I[i][1], I[i][3], I[i][1], I[i][2], I[i][4], I[i][3], I[i][4], I[i][5];
    Inertia Y(m[i], Eigen::Vector3d(c[i][0], c[i][1], c[i][2]), In);
    model.appendBodyToJoint(j, X.act(Y), SE3::Identity());
    parent = j; placement = X;
  }
  model.addFrame(Frame("flange", parent, 0, placement, OP_FRAME));
  FrameIndex fid = model.getFrameId("flange");
  Data data(model);
  Eigen::VectorXd q(6), qd(6), qdd(6); q << 0.1, -1.2, 0.4, 0.2, 0.9, -0.3; qd << 0.5, -0.3, 0.4, 1.0, -1.5, 2.0; qdd << 1.0, 2.0, -1.0, 3.0, 0.5, -2.0;
  Eigen::VectorXd tau = rnea(model, data, q, qd, qdd);
  Data::Matrix6x J(6, 6); J.setZero();
  auto bench = [&](const char* name, auto f) {
    std::vector<double> per; volatile double sink = 0;
    for (int b = 0; b < 300; ++b) {
      auto t0 = std::chrono::steady_clock::now();
      for (int k = 0; k < 2000; ++k) { f(); sink = sink + data.tau[0]; }
      per.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() / 2000);
    }
    std::sort(per.begin(), per.end());
    printf("%-22s median %7.1f ns  min %7.1f ns\n", name, per[per.size() / 2], per[0]);
  };
  bench("pinocchio rnea", [&] { rnea(model, data, q, qd, qdd); });
  bench("pinocchio crba", [&] { crba(model, data, q); });
  bench("pinocchio aba", [&] { aba(model, data, q, qd, tau); });
  bench("pinocchio frame jac", [&] { computeFrameJacobian(model, data, q, fid, LOCAL_WORLD_ALIGNED, J); });
  return 0;
}
