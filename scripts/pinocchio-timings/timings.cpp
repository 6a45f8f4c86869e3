// pinocchio's cost per call on this machine, as the anchor of `chaosd-bench compute`'s robot
// model table. Built and run by run.sh beside this file; writes one JSON file.
//
// The same method as the Rust side (bench/src/model_timing.rs): 1024 random states drawn once
// (q uniform within the URDF's limits, q̇ in [-2, 2], q̈ in [-5, 5], τ in ±0.5·effort), each call
// on the next state, calls timed in batches (one clock read costs more than a short call), the
// operations interleaved in rounds so that they all see the same load, and the per-call time of
// each batch recorded; percentiles are over batches.
//
// The model comes as pinocchio's own text serialisation (run.sh writes it from the URDF with the
// wheel's Python module): the wheel's URDF parser is compiled for baseline x86-64, and a model it
// fills is laid out differently from one this file sees when compiled with -march=native.
//
// Usage: timings MODEL.txt TIP_FRAME OUT.json [--urdf PATH] [--core N] [--rounds R]
//                [--batches B] [--batch K]

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/serialization.hpp>

#include <sched.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#ifndef TIMINGS_FLAGS
#define TIMINGS_FLAGS "unknown"
#endif

namespace {

using Clock = std::chrono::steady_clock;
using pinocchio::Convention;

// Keeps the compiler from dropping a computation whose result is only in memory.
template <typename T> inline void escape(T &x) { asm volatile("" : : "g"(&x) : "memory"); }

struct Series {
  std::string key;
  std::string label;
  std::function<void(std::size_t)> call;
  std::vector<double> per_call_ns;
};

double quantile(std::vector<double> sorted, double q) {
  if (sorted.empty()) return NAN;
  std::size_t i = static_cast<std::size_t>(std::ceil(q * sorted.size()));
  i = std::min(sorted.size() - 1, i == 0 ? 0 : i - 1);
  return sorted[i];
}

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) {
      auto c = line.find(':');
      if (c != std::string::npos) return line.substr(c + 2);
    }
  }
  return "unknown CPU";
}

std::string json_escape(const std::string &s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out.push_back('\\');
    out.push_back(c);
  }
  return out;
}

}  // namespace

int main(int argc, char **argv) {
  if (argc < 4) {
    std::cerr << "usage: " << argv[0]
              << " MODEL.txt TIP_FRAME OUT.json [--urdf PATH] [--core N] [--rounds R] [--batches B]"
                 " [--batch K]\n";
    return 2;
  }
  const std::string model_path = argv[1], tip = argv[2], out_path = argv[3];
  std::string urdf = model_path;
  int core = 0;
  std::size_t rounds = 10, batches = 10000, batch = 100;
  for (int i = 4; i + 1 < argc; i += 2) {
    std::string a = argv[i];
    if (a == "--urdf") {
      urdf = argv[i + 1];
      continue;
    }
    long v = std::strtol(argv[i + 1], nullptr, 10);
    if (a == "--core") core = static_cast<int>(v);
    else if (a == "--rounds") rounds = static_cast<std::size_t>(v);
    else if (a == "--batches") batches = static_cast<std::size_t>(v);
    else if (a == "--batch") batch = static_cast<std::size_t>(v);
    else {
      std::cerr << "unknown option " << a << "\n";
      return 2;
    }
  }
  if (core >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(core, &set);
    if (sched_setaffinity(0, sizeof(set), &set) != 0)
      std::cerr << "timings: warning: cannot pin to core " << core << "\n";
  }

  pinocchio::Model model;
  model.loadFromText(model_path);
  pinocchio::Data data(model);
  if (!model.existFrame(tip)) {
    std::cerr << "timings: no frame " << tip << " in " << model_path << "\n";
    return 1;
  }
  const auto fid = model.getFrameId(tip);
  const int n = model.nv;
  if (model.nq != model.nv) {
    std::cerr << "timings: continuous joints (nq != nv) are not handled\n";
    return 1;
  }

  // The states.
  const std::size_t S = 1024;
  std::mt19937_64 rng(2026);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::VectorXd> q(S), qd(S), qdd(S), tau(S);
  for (std::size_t s = 0; s < S; ++s) {
    q[s].resize(n);
    qd[s].resize(n);
    qdd[s].resize(n);
    tau[s].resize(n);
    for (int j = 0; j < n; ++j) {
      double lo = model.lowerPositionLimit[j], hi = model.upperPositionLimit[j];
      if (!std::isfinite(lo) || !std::isfinite(hi)) lo = -M_PI, hi = M_PI;
      q[s][j] = lo + (hi - lo) * u(rng);
      qd[s][j] = -2.0 + 4.0 * u(rng);
      qdd[s][j] = -5.0 + 10.0 * u(rng);
      const double ub = model.upperEffortLimit[j];
      const double e = ub > 0 && std::isfinite(ub) ? ub : 20.0;
      tau[s][j] = (u(rng) - 0.5) * e;
    }
  }
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);

  // Self-check: ABA inverts RNEA (a broken build would time garbage).
  {
    Eigen::VectorXd t = pinocchio::rnea(model, data, q[3], qd[3], qdd[3]);
    Eigen::VectorXd back = pinocchio::aba(model, data, q[3], qd[3], t);
    if ((back - qdd[3]).norm() > 1e-9) {
      std::cerr << "timings: aba(rnea(qdd)) != qdd: " << (back - qdd[3]).norm() << "\n";
      return 1;
    }
  }

  pinocchio::Data::Matrix6x J(6, n);
  J.setZero();
  pinocchio::Motion acc;
  std::vector<Series> series = {
      {"rnea", "RNEA", [&](std::size_t s) {
         pinocchio::rnea(model, data, q[s], qd[s], qdd[s]);
         escape(data.tau);
       }, {}},
      {"crba", "CRBA (default convention, LOCAL)", [&](std::size_t s) {
         pinocchio::crba(model, data, q[s]);
         escape(data.M);
       }, {}},
      {"crba_world", "CRBA (Convention::WORLD)", [&](std::size_t s) {
         pinocchio::crba(model, data, q[s], Convention::WORLD);
         escape(data.M);
       }, {}},
      {"aba", "ABA (default convention, LOCAL)", [&](std::size_t s) {
         pinocchio::aba(model, data, q[s], qd[s], tau[s]);
         escape(data.ddq);
       }, {}},
      {"aba_world", "ABA (Convention::WORLD)", [&](std::size_t s) {
         pinocchio::aba(model, data, q[s], qd[s], tau[s], Convention::WORLD);
         escape(data.ddq);
       }, {}},
      {"gravity", "computeGeneralizedGravity", [&](std::size_t s) {
         pinocchio::computeGeneralizedGravity(model, data, q[s]);
         escape(data.g);
       }, {}},
      {"fk_jacobian", "forwardKinematics(q) + computeJointJacobians + getFrameJacobian (LOCAL_WORLD_ALIGNED)",
       [&](std::size_t s) {
         pinocchio::forwardKinematics(model, data, q[s]);
         pinocchio::computeJointJacobians(model, data);
         pinocchio::getFrameJacobian(model, data, fid, pinocchio::LOCAL_WORLD_ALIGNED, J);
         escape(J);
       }, {}},
      {"fk_jdot_qd", "forwardKinematics(q, q̇, 0) + getFrameClassicalAcceleration (LOCAL_WORLD_ALIGNED)",
       [&](std::size_t s) {
         pinocchio::forwardKinematics(model, data, q[s], qd[s], zero);
         acc = pinocchio::getFrameClassicalAcceleration(model, data, fid, pinocchio::LOCAL_WORLD_ALIGNED);
         escape(acc);
       }, {}},
      {"fk_jacobian_jdot_qd", "forwardKinematics(q, q̇, 0) + computeJointJacobians + getFrameJacobian + getFrameClassicalAcceleration",
       [&](std::size_t s) {
         pinocchio::forwardKinematics(model, data, q[s], qd[s], zero);
         pinocchio::computeJointJacobians(model, data);
         pinocchio::getFrameJacobian(model, data, fid, pinocchio::LOCAL_WORLD_ALIGNED, J);
         acc = pinocchio::getFrameClassicalAcceleration(model, data, fid, pinocchio::LOCAL_WORLD_ALIGNED);
         escape(J);
         escape(acc);
       }, {}},
  };

  // Warm-up, then interleaved rounds.
  for (auto &se : series)
    for (std::size_t i = 0; i < 20 * batch; ++i) se.call(i % S);
  std::size_t per_round = std::max<std::size_t>(1, batches / std::max<std::size_t>(1, rounds));
  std::size_t next = 0;
  for (std::size_t r = 0; r < rounds; ++r) {
    for (auto &se : series) {
      for (std::size_t b = 0; b < per_round; ++b) {
        auto t0 = Clock::now();
        for (std::size_t i = 0; i < batch; ++i) se.call((next + i) % S);
        auto ns = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
        next = (next + batch) % S;
        se.per_call_ns.push_back(ns / static_cast<double>(batch));
      }
    }
  }

  std::ostringstream js;
  js.setf(std::ios::fixed);
  js.precision(1);
  js << "{\n";
  js << "  \"pinocchio_version\": \"" << PINOCCHIO_VERSION << "\",\n";
  js << "  \"compiler\": \"" << json_escape("g++ " __VERSION__) << "\",\n";
  js << "  \"flags\": \"" << json_escape(TIMINGS_FLAGS) << "\",\n";
#ifdef PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION
  js << "  \"template_instantiation\": true,\n";
#else
  js << "  \"template_instantiation\": false,\n";
#endif
  js << "  \"cpu\": \"" << json_escape(cpu_model()) << "\",\n";
  js << "  \"urdf\": \"" << json_escape(urdf) << "\",\n";
  js << "  \"tip\": \"" << json_escape(tip) << "\",\n";
  js << "  \"dof\": " << n << ",\n";
  js << "  \"states\": " << S << ",\n";
  js << "  \"batch\": " << batch << ",\n";
  js << "  \"batches\": " << per_round * rounds << ",\n";
  js << "  \"rows\": {\n";
  for (std::size_t k = 0; k < series.size(); ++k) {
    auto v = series[k].per_call_ns;
    std::sort(v.begin(), v.end());
    js << "    \"" << series[k].key << "\": {\"label\": \"" << json_escape(series[k].label) << "\", "
       << "\"p50_ns\": " << quantile(v, 0.5) << ", \"p90_ns\": " << quantile(v, 0.9)
       << ", \"p99_ns\": " << quantile(v, 0.99) << ", \"p999_ns\": " << quantile(v, 0.999)
       << ", \"max_ns\": " << v.back() << "}" << (k + 1 < series.size() ? "," : "") << "\n";
    std::printf("%-22s p50 %8.1f ns  p99 %8.1f ns  max %8.1f ns\n", series[k].key.c_str(),
                quantile(v, 0.5), quantile(v, 0.99), v.back());
  }
  js << "  }\n}\n";
  std::ofstream out(out_path);
  out << js.str();
  if (!out) {
    std::cerr << "timings: cannot write " << out_path << "\n";
    return 1;
  }
  return 0;
}
