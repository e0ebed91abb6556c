#!/usr/bin/env python3
"""Joint-space computed-torque hold controller for `plant-sim`, in Python: a template.

    python3 hold_controller.py --rig NAME --scenario FILE.toml

Speaks the wire contract of messages/README.md over iceoryx2 shared memory (PyPI `iceoryx2`
0.10.0) and holds the joint position of the first state it sees with

    tau = M(q) (Kp e - Kd qd) + C(q, qd) qd + g(q) + armature * qdd_ref + viscous * qd

(Pinocchio RNEA), so every joint behaves as a critically damped 10 Hz unit mass, exactly like
tests/src/bin/hold_controller.rs. Exits 0 when the plant says it is shutting down, 1 on a
contract-version mismatch or when the plant falls silent. Needs `pip install iceoryx2==0.10.0
pin numpy`.
"""
import argparse, ctypes, os, sys, time, tomllib
import iceoryx2 as iox2
import numpy as np
import pinocchio as pin

CONTRACT_VERSION = 2
SHUTTING_DOWN = 4                        # PlantStatus::ShuttingDown
OMEGA, ZETA = 2 * np.pi * 10.0, 1.0      # closed-loop natural frequency (rad/s) and damping ratio
DEAD_PLANT_S = 0.1                       # silence after the first state that means "plant is dead"
D6 = ctypes.c_double * 6
D3 = ctypes.c_double * 3
u32, u64, f64 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double


# --- Payloads: byte for byte the #[repr(C)] records of messages/src/lib.rs (sizes asserted below).
# `type_name()` is what iceoryx2 compares with the Rust `#[type_name(...)]` when opening a service.
class JointState(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("plant_status", u32), ("tick", u64), ("sim_time_s", f64),
                ("q", D6), ("qd", D6), ("tau_applied", D6), ("period_s", f64), ("flags", u32),
                ("consecutive_misses", u32), ("total_misses", u64)]
    @staticmethod
    def type_name(): return "rig::JointState"

class Wrench(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("frame", u32), ("tick", u64), ("force", D3), ("torque", D3)]
    @staticmethod
    def type_name(): return "rig::Wrench"

class JointTorque(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("controller_status", u32), ("tick", u64),
                ("controller_id", u64), ("tau", D6)]
    @staticmethod
    def type_name(): return "rig::JointTorque"

class ControllerDiagnostics(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("force_control_active", u32), ("tick", u64),
                ("force_ref_n", f64), ("force_meas_n", f64), ("pos_ref_task_m", D3),
                ("pos_err_task_m", D3), ("rot_err_task_rad", D3), ("force_integral_ns", f64),
                ("compute_time_ns", u64),
                # Stage stamps, CLOCK_MONOTONIC ns (time.monotonic_ns() on Linux): woke, computed,
                # handed over. The plant turns them into /timing's offsets and attributes misses.
                ("woke_mono_ns", u64), ("computed_mono_ns", u64), ("published_mono_ns", u64)]
    @staticmethod
    def type_name(): return "rig::ControllerDiagnostics"

for t, size in ((JointState, 192), (Wrench, 64), (JointTorque, 72), (ControllerDiagnostics, 144)):
    assert ctypes.sizeof(t) == size and ctypes.alignment(t) == 8, t


# --- Model: IRB 2400 of thesis Tables 7.1/E.1 (as robot/tools/pinocchio_check.py) plus the tool.
DH = [(0.615, 0.1, -np.pi/2), (0, 0.705, 0), (0, 0.135, -np.pi/2), (0.755, 0, np.pi/2), (0, 0, -np.pi/2), (0.085, 0, 0)]
LINKS = [  # mass kg, COM and inertia about the COM in DH frame i
    (150, [-0.070, 0.17, 0.019], [[7.6, 1.0, 0.30], [1.0, 5.8, -0.10], [0.30, -0.10, 5.0]]),
    (47, [-0.38, 0.037, -0.0027], [[0.38, 0.094, 0.0027], [0.094, 2.0, -0.025], [0.0027, -0.025, 2.1]]),
    (40, [-0.019, 0.010, -0.0011], [[0.93, -0.010, -0.053], [-0.010, 0.91, 0.011], [-0.053, 0.011, 0.32]]),
    (18, [0.00030, -0.20, 0.0010], [[0.52, -0.00038, -4.3e-5], [-0.00038, 0.044, -0.0036], [-4.3e-5, -0.0036, 0.51]]),
    (0.97, [0.00096, 4e-7, -0.00019], [[0.00085, 0, 6.9e-6], [0, 0.0014, -2.8e-8], [6.9e-6, -2.8e-8, 0.00091]]),
    (0.57, [-9.1e-5, -9e-7, -0.047], [[0.00047, 0, 1.0e-6], [0, 0.00047, 0], [1.0e-6, 0, 6.2e-5]]),
]

def tool_inertia(robot_cfg):
    """`robot::Tool::wheel_on_bracket`, the rule plant and controllers share: the default tool
    cylinder (1 kg, r = 30 mm, l = 100 mm) scaled to `tool_mass_kg`, COM half-way to the TCP on
    flange z. Defaults as scenarios/src/lib.rs `RobotConfig`."""
    m, off = robot_cfg.get("tool_mass_kg", 1.0), robot_cfg.get("tool_offset_m", 0.1)
    ixx, izz = (3 * 0.03**2 + 0.1**2) / 12.0, 0.03**2 / 2.0
    return pin.Inertia(m, np.array([0.0, 0.0, 0.5 * off]), m * np.diag([ixx, ixx, izz]))

def build_model(robot_cfg):
    """Pinocchio model: revolute z joints, DH frame i placed by Tz(d) Tx(a) Rx(alpha) after joint i;
    the tool is rigidly attached to the flange (DH frame 6)."""
    model, parent, placement = pin.Model(), 0, pin.SE3.Identity()
    for i, (d, a, alpha) in enumerate(DH):
        jid = model.addJoint(parent, pin.JointModelRZ(), placement, f"j{i+1}")
        X = pin.SE3(pin.utils.rotate('x', alpha), np.array([a, 0.0, d]))
        m, c, I = LINKS[i]
        model.appendBodyToJoint(jid, X.act(pin.Inertia(m, np.array(c), np.array(I))), pin.SE3.Identity())
        parent, placement = jid, X
    model.appendBodyToJoint(parent, placement.act(tool_inertia(robot_cfg)), pin.SE3.Identity())
    model.gravity.linear = np.array([0.0, 0.0, -9.81])
    return model


# --- The rig's iceoryx2 configuration (messages/README.md, "iceoryx2 configuration"): every peer
# loads the file the rig's daemons write into the user's owner-only state directory.
def rig_config_path():
    d = os.environ.get("RIG_ICEORYX2_DIR")
    if not d:
        uid = os.geteuid()
        run_user = f"/run/user/{uid}"
        if uid == 0:
            d = "/run/rig-iceoryx2"
        elif os.path.isdir(run_user) and os.stat(run_user).st_uid == uid:
            d = f"{run_user}/rig-iceoryx2"
        else:
            d = f"/tmp/rig-iceoryx2-{uid}"
    return os.path.join(d, "iceoryx2.toml")

def rig_config(wait_s=30.0):
    """The plant writes the file on its first start; a controller started with it waits for it."""
    path = rig_config_path()
    until = time.monotonic() + wait_s
    while not os.path.exists(path):
        if time.monotonic() > until:
            sys.exit(f"hold_controller.py: error: no rig iceoryx2 configuration at {path} after {wait_s:.0f} s: "
                     "start plant-sim (it writes the file), or set RIG_ICEORYX2_DIR as for the plant")
        time.sleep(0.05)
    return iox2.config.from_file(iox2.FilePath.new(path))


# --- Ports: the contract's services and QoS (messages/src/qos.rs); any difference and opening fails.
def open_ports(rig):
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = (iox2.NodeBuilder.new().name(iox2.NodeName.new(f"python-hold-controller/{rig}")).config(rig_config())
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled).create(iox2.ServiceType.Ipc))
    node.try_cleanup_dead_nodes()  # a killed peer leaves its shared memory behind
    name = lambda svc: iox2.ServiceName.new(f"rig/{rig}/{svc}")
    def pubsub(svc, t):
        return (node.service_builder(name(svc)).publish_subscribe(t)
                .max_publishers(4).max_subscribers(4).max_nodes(8).subscriber_max_buffer_size(4)
                .subscriber_max_borrowed_samples(2).history_size(0).enable_safe_overflow(True)
                .open_or_create())
    def event(svc):
        return (node.service_builder(name(svc)).event()
                .max_notifiers(4).max_listeners(4).max_nodes(8).event_id_max_value(0).open_or_create())
    p = dict(node=node)
    p["state"] = pubsub("joint_state", JointState).subscriber_builder().buffer_size(4).create()
    p["wrench"] = pubsub("wrench", Wrench).subscriber_builder().buffer_size(4).create()
    p["torque"] = pubsub("joint_torque", JointTorque).publisher_builder().create()
    p["diag"] = pubsub("controller_diagnostics_v2", ControllerDiagnostics).publisher_builder().create()
    p["state_ready"] = event("state_ready").listener_builder().create()
    p["torque_ready"] = event("torque_ready").notifier_builder().create()
    return p

def newest(sub, t):
    """Drain `sub`, returning a copy of the newest sample (older ones are stale) or None. Samples
    are released at once: the contract allows only 2 borrowed at a time."""
    out = None
    while (s := sub.receive()) is not None:
        out = t()
        ctypes.memmove(ctypes.byref(out), s.payload_ptr, ctypes.sizeof(t))
        s.delete()
    return out

def check_version(rec, what):
    if rec.contract_version != CONTRACT_VERSION:
        sys.exit(f"hold_controller.py: error: contract version mismatch on {what}: peer speaks version "
                 f"{rec.contract_version}, this process speaks version {CONTRACT_VERSION}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", required=True)
    ap.add_argument("--scenario", required=True)
    a = ap.parse_args()
    with open(a.scenario, "rb") as f:
        robot_cfg = tomllib.load(f).get("robot", {})
    model = build_model(robot_cfg)
    data = model.createData()
    armature = np.array(robot_cfg.get("armature_kgm2", [0.0] * 6), dtype=float)
    viscous = np.array(robot_cfg.get("viscous_nms", [0.0] * 6), dtype=float)
    ports = open_ports(a.rig)
    controller_id = (os.getpid() << 32) | (time.time_ns() % 1_000_000_000)
    q_hold, last_state = None, time.monotonic()
    while True:
        # Sleep on the plant's `state_ready` event; the timeout only serves the dead-plant check.
        ports["state_ready"].timed_wait(iox2.Duration.from_millis(20))
        st = newest(ports["state"], JointState)
        if st is None:
            if q_hold is not None and time.monotonic() - last_state > DEAD_PLANT_S:
                sys.exit(f"hold_controller.py: error: plant on rig {a.rig!r} is silent for "
                         f"{DEAD_PLANT_S * 1e3:.0f} ms: assuming it is dead")
            continue
        t0, woke = time.perf_counter_ns(), time.monotonic_ns()
        last_state = time.monotonic()
        check_version(st, "joint state")
        if st.plant_status == SHUTTING_DOWN:
            return 0
        wrench = newest(ports["wrench"], Wrench)  # unused by a hold; a force law would read it here
        if wrench is not None:
            check_version(wrench, "wrench")
        q, qd = np.array(st.q), np.array(st.qd)
        if q_hold is None:
            q_hold = q.copy()
        qdd_ref = OMEGA**2 * (q_hold - q) - 2 * ZETA * OMEGA * qd
        tau = pin.rnea(model, data, q, qd, qdd_ref) + armature * qdd_ref + viscous * qd
        torque = JointTorque(CONTRACT_VERSION, 0, st.tick, controller_id, D6(*tau))  # status 0 = active
        computed = time.monotonic_ns()
        diag = ControllerDiagnostics(contract_version=CONTRACT_VERSION, tick=st.tick,
                                     compute_time_ns=time.perf_counter_ns() - t0, woke_mono_ns=woke,
                                     computed_mono_ns=computed, published_mono_ns=time.monotonic_ns())
        # Diagnostics first: a plant that polls for the torque then finds them too.
        ports["diag"].send_copy(diag)
        ports["torque"].send_copy(torque)
        ports["torque_ready"].notify()


if __name__ == "__main__":
    sys.exit(main())
