// rig_client.hpp: header-only C++17 wrapper of rig_client.h (rig-client, issue 27).
//
// RAII owners of the C handles (rig::Client, rig::Model: move-only, closed in the destructor),
// joint vectors as std::array<double, 6>, matrices as row-major std::array<double, 36>.
//
// Errors are exceptions (rig::Error, with the library's code and one-sentence message): they
// happen where a controller cannot go on anyway (opening, a contract version mismatch, a failed
// send), and a constructor has no other way to fail. What happens every tick is not an error and
// is never thrown: rig::Client::wait returns a rig::Status (ok, timeout, shutting down, plant
// gone, safe stop to acknowledge), so the 1 kHz path has no exceptions, allocations or locks.
#ifndef RIG_CLIENT_HPP
#define RIG_CLIENT_HPP

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "rig_client.h"

namespace rig {

using Vec6 = std::array<double, 6>;
using Mat6 = std::array<double, 36>;  // row-major
using Pose = std::array<double, 16>;  // 4x4 homogeneous transform, row-major

/// A failure of the library: `code()` is a RIG_ERR_* value, `what()` the one-sentence detail.
class Error : public std::runtime_error {
public:
    explicit Error(int32_t code)
        : std::runtime_error(message(code)), code_(code) {}
    int32_t code() const noexcept { return code_; }

private:
    static std::string message(int32_t code) {
        std::string s = rig_client_error_message(code);
        const char* detail = rig_client_last_error();
        if (detail && *detail) s = s + ": " + detail;
        return s;
    }
    int32_t code_;
};

/// Outcome of Client::wait (the non-negative codes of rig_client.h).
enum class Status : int32_t {
    Ok = RIG_OK,
    Timeout = RIG_TIMEOUT,
    ShuttingDown = RIG_SHUTTING_DOWN,
    PlantGone = RIG_PLANT_GONE,
    SafeStopToAcknowledge = RIG_SAFE_STOP_TO_ACKNOWLEDGE,
};

namespace detail {
inline void check(int32_t code) {
    if (code < 0) throw Error(code);
}
}  // namespace detail

/// The rig's robot model of a scenario (IRB 2400 with the scenario's tool), like libfranka's Model.
class Model {
public:
    /// `scenario_path` nullptr: the default scenario.
    explicit Model(const char* scenario_path = nullptr) { detail::check(rig_model_open(scenario_path, &m_)); }
    ~Model() { rig_model_close(m_); }
    Model(const Model&) = delete;
    Model& operator=(const Model&) = delete;
    Model(Model&& o) noexcept : m_(std::exchange(o.m_, nullptr)) {}
    Model& operator=(Model&& o) noexcept {
        std::swap(m_, o.m_);
        return *this;
    }

    Pose tcp_pose(const Vec6& q) const {
        Pose p{};
        detail::check(rig_model_tcp_pose(m_, q.data(), p.data()));
        return p;
    }
    Mat6 jacobian_tcp(const Vec6& q) const {
        Mat6 j{};
        detail::check(rig_model_jacobian_tcp(m_, q.data(), j.data()));
        return j;
    }
    Mat6 mass_matrix(const Vec6& q) const {
        Mat6 m{};
        detail::check(rig_model_mass_matrix(m_, q.data(), m.data()));
        return m;
    }
    Vec6 gravity(const Vec6& q) const {
        Vec6 t{};
        detail::check(rig_model_gravity(m_, q.data(), t.data()));
        return t;
    }
    Vec6 coriolis(const Vec6& q, const Vec6& qd) const {
        Vec6 t{};
        detail::check(rig_model_coriolis(m_, q.data(), qd.data(), t.data()));
        return t;
    }
    Vec6 inverse_dynamics(const Vec6& q, const Vec6& qd, const Vec6& qdd) const {
        Vec6 t{};
        detail::check(rig_model_inverse_dynamics(m_, q.data(), qd.data(), qdd.data(), t.data()));
        return t;
    }

private:
    RigModel* m_ = nullptr;
};

/// One controller's connection to a rig (see rig_client_open). Use it from one thread.
class Client {
public:
    Client(const std::string& rig, const char* scenario_path = nullptr, double timeout_s = 120.0,
           const char* node_role = "rig-client-cpp") {
        detail::check(rig_client_open(rig.c_str(), node_role, scenario_path, timeout_s, &c_));
    }
    ~Client() { rig_client_close(c_); }
    Client(const Client&) = delete;
    Client& operator=(const Client&) = delete;
    Client(Client&& o) noexcept : c_(std::exchange(o.c_, nullptr)) {}
    Client& operator=(Client&& o) noexcept {
        std::swap(c_, o.c_);
        return *this;
    }

    /// Wait for the next state and the wrench of its tick; throws only on errors.
    Status wait(double timeout_s, RigJointState& state, RigWrench& wrench) {
        int32_t rc = rig_client_wait(c_, timeout_s, &state, &wrench);
        detail::check(rc);
        return static_cast<Status>(rc);
    }

    /// Answer tick `tick` (controller_status: RIG_CONTROLLER_*); diagnostics optional.
    void publish(uint64_t tick, uint32_t controller_status, const Vec6& tau,
                 const RigControllerDiagnostics* diag = nullptr) {
        detail::check(rig_client_publish(c_, tick, controller_status, tau.data(), diag));
    }

    uint64_t controller_id() const { return rig_client_controller_id(c_); }

private:
    RigClient* c_ = nullptr;
};

/// A joint vector of a record (`state.q`, `state.qd`, `state.tau_applied`).
inline Vec6 vec6(const double (&a)[6]) { return {a[0], a[1], a[2], a[3], a[4], a[5]}; }

}  // namespace rig

#endif  // RIG_CLIENT_HPP
