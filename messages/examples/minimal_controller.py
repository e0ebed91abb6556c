#!/usr/bin/env python3
"""Minimal controller for plant-sim, written from messages/README.md alone: holds the robot still.

    minimal_controller.py --rig NAME --scenario FILE.toml    (or: rig run --controller THIS_FILE)

Law, per joint, no robot model: tau = u + KP (q0 - q) - KD qd, with q0 the first state's q and u
a feed-forward that starts at that state's tau_applied and then takes up every difference between
what the plant applied and what this controller sent (u += tau_applied - tau_sent). While the
plant blends the controller in from its hold (gravity compensation + joint damping, 50 ms), u
thereby follows what the hold applies, gravity torque included, and the hold keeps the arm still;
once the blend is over the plant applies what was sent, u stays constant and the PD holds.
Exit 0 on the plant's goodbye (plant_status 4); exit 1 with one sentence when the plant is gone
or silent. Needs Python >= 3.11 and `pip install iceoryx2==0.10.0`.
"""
import argparse, ctypes, math, os, sys, time, tomllib
import iceoryx2 as iox2

CONTRACT_VERSION, SHUTTING_DOWN = 2, 4
# Critically damped 10 Hz per joint on M_ii of the rig's start pose (kg m^2, 1 kg tool, rounded).
OMEGA, INERTIA = 2 * math.pi * 10.0, [25.0, 47.0, 9.5, 0.057, 0.022, 0.0005]
KP = [m * OMEGA**2 for m in INERTIA]  # N m/rad
KD = [2 * m * OMEGA for m in INERTIA]  # N m s/rad
WAKE = iox2.Duration.from_millis(10)  # listener timeout: only paces the liveness checks
SILENCE_S = 0.02  # no new state for this long: look at the plant's node
STARTUP_S = 120.0  # longest wait for the first state (the plant may build a strip model first)
u32, u64, f64, D3, D6 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double, ctypes.c_double * 3, ctypes.c_double * 6


class JointState(ctypes.Structure):  # the records of messages/README.md, field for field
    _fields_ = [("contract_version", u32), ("plant_status", u32), ("tick", u64), ("sim_time_s", f64),
                ("q", D6), ("qd", D6), ("tau_applied", D6), ("period_s", f64), ("flags", u32),
                ("consecutive_misses", u32), ("total_misses", u64)]
    type_name = staticmethod(lambda: "rig::JointState")  # iceoryx2 matches it against the Rust type


class Wrench(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("frame", u32), ("tick", u64), ("force", D3), ("torque", D3)]
    type_name = staticmethod(lambda: "rig::Wrench")


class JointTorque(ctypes.Structure):
    _fields_ = [("contract_version", u32), ("controller_status", u32), ("tick", u64),
                ("controller_id", u64), ("tau", D6)]
    type_name = staticmethod(lambda: "rig::JointTorque")


def rig_config():
    """The rig's iceoryx2 configuration (messages/README.md, "iceoryx2 configuration"): the file
    the plant writes into the user's owner-only state directory; started with it, wait for it."""
    d = os.environ.get("RIG_ICEORYX2_DIR")
    if not d:
        uid, run_user = os.geteuid(), f"/run/user/{os.geteuid()}"
        if uid == 0:
            d = "/run/rig-iceoryx2"
        elif os.path.isdir(run_user) and os.stat(run_user).st_uid == uid:
            d = f"{run_user}/rig-iceoryx2"
        else:
            d = f"/tmp/rig-iceoryx2-{uid}"
    path, until = os.path.join(d, "iceoryx2.toml"), time.monotonic() + STARTUP_S
    while not os.path.exists(path):
        if time.monotonic() > until:
            sys.exit(f"minimal_controller.py: error: no rig iceoryx2 configuration at {path}: start plant-sim first")
        time.sleep(0.05)
    return iox2.config.from_file(iox2.FilePath.new(path))


def open_ports(rig):
    """A node and the rig's services with the contract's QoS (any other value and opening fails)."""
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = (iox2.NodeBuilder.new().name(iox2.NodeName.new(f"minimal-controller/{rig}")).config(rig_config())
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled).create(iox2.ServiceType.Ipc))
    node.try_cleanup_dead_nodes()  # a killed peer leaves its shared memory behind
    name = lambda svc: iox2.ServiceName.new(f"rig/{rig}/{svc}")
    pubsub = lambda svc, t: (node.service_builder(name(svc)).publish_subscribe(t)
                             .max_publishers(4).max_subscribers(4).max_nodes(8).subscriber_max_buffer_size(4)
                             .history_size(0).enable_safe_overflow(True).subscriber_max_borrowed_samples(2)
                             .open_or_create())
    event = lambda svc: (node.service_builder(name(svc)).event()
                         .max_notifiers(4).max_listeners(4).max_nodes(8).event_id_max_value(0).open_or_create())
    return (node, pubsub("joint_state", JointState).subscriber_builder().buffer_size(4).create(),
            pubsub("wrench", Wrench).subscriber_builder().buffer_size(4).create(),
            pubsub("joint_torque", JointTorque).publisher_builder().create(),
            event("state_ready").listener_builder().create(), event("torque_ready").notifier_builder().create())


def newest(sub, t):
    """Copy of the newest sample (older ones are stale) or None; every sample is released at once
    (at most 2 may be borrowed)."""
    out = None
    while (s := sub.receive()) is not None:
        out = t.from_buffer_copy(s.payload().contents)
        s.delete()
    return out


def plant_alive(node, rig):
    """True while the plant's iceoryx2 node `plant-sim/<RIG>` is alive (a killed one shows as dead)."""
    for s in iox2.Node.list(iox2.ServiceType.Ipc, node.config):
        match s:
            case iox2.NodeState.Alive(view) if view.details and view.details.name.as_str() == f"plant-sim/{rig}":
                return True
    return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", required=True)
    ap.add_argument("--scenario", required=True)
    a = ap.parse_args()
    with open(a.scenario, "rb") as f:
        stall_s = tomllib.load(f).get("loop", {}).get("peer_stall_timeout_s", 5.0)
    node, state_sub, wrench_sub, torque_pub, state_ready, torque_ready = open_ports(a.rig)
    cid = (os.getpid() << 32) | (time.time_ns() & 0xFFFFFFFF)  # unique to this process
    q0 = u = sent = last_tick = last_seen = None
    plant_known, started = False, time.monotonic()  # plant_known: its node was seen (else: stall timeout only)
    fail = lambda why: sys.exit(f"minimal_controller.py: error: rig {a.rig!r}: {why}")
    while True:
        state_ready.timed_wait(WAKE)  # sleep until the plant notifies (or the timeout)
        st, now = newest(state_sub, JointState), time.monotonic()
        if st is None or (last_tick is not None and st.tick <= last_tick):  # nothing new
            if last_seen is None:
                if now - started > STARTUP_S:
                    fail(f"no joint state within {STARTUP_S:.0f} s: is plant-sim running on this rig?")
            elif now - last_seen > SILENCE_S:
                if plant_known and not plant_alive(node, a.rig):
                    fail(f"the plant is gone (its node is dead; no state for {(now - last_seen) * 1e3:.0f} ms "
                         f"after tick {last_tick}); exiting")
                if now - last_seen > stall_s:
                    fail(f"the plant is alive but silent for {stall_s:g} s (no state after tick {last_tick}); exiting")
            continue
        if st.contract_version != CONTRACT_VERSION:
            fail(f"contract version mismatch on joint state: peer speaks version {st.contract_version}, "
                 f"this process speaks version {CONTRACT_VERSION}")
        if st.plant_status == SHUTTING_DOWN:
            return 0
        newest(wrench_sub, Wrench)  # received and released; a force law would use it
        if q0 is None:
            q0, u, plant_known = list(st.q), list(st.tau_applied), plant_alive(node, a.rig)
        else:
            u = [ui + applied - s for ui, applied, s in zip(u, st.tau_applied, sent)]
        sent = [u[i] + KP[i] * (q0[i] - st.q[i]) - KD[i] * st.qd[i] for i in range(6)]
        torque_pub.send_copy(JointTorque(CONTRACT_VERSION, 0, st.tick, cid, D6(*sent)))  # status 0 = active
        torque_ready.notify()
        last_tick, last_seen = st.tick, now


if __name__ == "__main__":
    sys.exit(main())
