// hold_controller.cpp: the joint-space hold of the Rust `hold-controller` in C++17 on
// rig_client.hpp (rig-client, issue 27).
//
//     hold_controller --rig NAME --scenario FILE.toml    (or: rig run --controller THIS_BINARY)
//
// tau = M(q) (Kp e - Kd qd) + C(q, qd) qd + g(q) by inverse dynamics (the rig's model, tool
// included), holding the first state's q; every joint a critically damped 10 Hz unit mass. The
// same arithmetic as tests/src/bin/hold_controller.rs, so in lockstep both send the same torques.
// Exits 0 on the plant's goodbye, 1 with one sentence when the plant is gone or silent.
#include <cstdio>
#include <cstring>
#include <optional>

#include "rig_client.hpp"

namespace {
constexpr double OMEGA = 2.0 * 3.141592653589793 * 10.0;  // rad/s (Rust: 2.0 * PI * 10.0)
constexpr double ZETA = 1.0;
constexpr int SILENCE_LIMIT_S = 5;  // 1 s waits without a state before giving up on a live plant
}  // namespace

int main(int argc, char** argv) {
    const char* rig_name = nullptr;
    const char* scenario = nullptr;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (std::strcmp(argv[i], "--rig") == 0) rig_name = argv[i + 1];
        if (std::strcmp(argv[i], "--scenario") == 0) scenario = argv[i + 1];
    }
    if (!rig_name) {
        std::fprintf(stderr, "usage: %s --rig NAME [--scenario FILE.toml]\n", argv[0]);
        return 2;
    }
    try {
        const rig::Model model(scenario);
        rig::Client client(rig_name, scenario, 120.0, "cpp-hold-controller");
        std::optional<rig::Vec6> hold;
        RigJointState st{};
        RigWrench w{};
        int silent = 0;
        for (;;) {
            const rig::Status s = client.wait(1.0, st, w);
            if (s == rig::Status::Timeout) {
                if (++silent < SILENCE_LIMIT_S) continue;
                std::fprintf(stderr, "hold_controller: error: rig %s: no state for %d s; exiting\n", rig_name, SILENCE_LIMIT_S);
                return 1;
            }
            silent = 0;
            if (s == rig::Status::ShuttingDown) return 0;
            if (s == rig::Status::PlantGone) {
                std::fprintf(stderr, "hold_controller: error: rig %s: the plant is gone; exiting\n", rig_name);
                return 1;
            }
            const rig::Vec6 q = rig::vec6(st.q), qd = rig::vec6(st.qd);
            if (!hold) hold = q;
            rig::Vec6 qdd{};
            for (int j = 0; j < 6; ++j) qdd[j] = ((*hold)[j] - q[j]) * (OMEGA * OMEGA) - qd[j] * (2.0 * ZETA * OMEGA);
            const rig::Vec6 tau = model.inverse_dynamics(q, qd, qdd);
            // Status 1 (starting) acknowledges a latched reflex; otherwise 0 (active).
            client.publish(st.tick, s == rig::Status::SafeStopToAcknowledge ? RIG_CONTROLLER_STARTING : RIG_CONTROLLER_ACTIVE, tau);
        }
    } catch (const rig::Error& e) {
        std::fprintf(stderr, "hold_controller: error: %s\n", e.what());
        return 1;
    }
}
