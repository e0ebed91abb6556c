#!/usr/bin/env python3
"""A third-party EGM sensor for the rig's tests: ABB's EGM as `abb-robot-client` speaks it.

    egm_client.py PORT OUT.json MODE [CYCLES]

Binds PORT with `abb_robot_client.egm.EGM`, answers every `EgmRobot` and writes what it received
(`header.tm` in ms, feedback and planned joints in degrees, TCP position in mm, measured force,
MCI state) to OUT.json when the robot goes quiet (2 s without a message) or after CYCLES cycles.
MODE:
  step        echo the planned joints (hold) for 50 cycles, then command axis 6 +1 degree from
              there and hold that
  silent      hold for 50 cycles, then stop answering (the robot's comm_timeout ends the session)
  repeat_seq  hold for 50 cycles, then send one message with the previous sequence number again
  out_of_limit  hold for 50 cycles, then command axis 3 to 70 degrees (its range ends at 65)
  too_fast    hold for 50 cycles, then command axis 6 3 degrees on within one cycle (750 deg/s at
              the 4 ms cycle; the axis makes 450 deg/s), then hold again
"""
import json
import sys

import numpy as np
from abb_robot_client.egm import EGM

port, out, mode = int(sys.argv[1]), sys.argv[2], sys.argv[3]
max_cycles = int(sys.argv[4]) if len(sys.argv) > 4 else 10**9
egm = EGM(port=port)
log = []
hold = None
n = 0
quiet = 0.0
while n < max_cycles:
    ok, st = egm.receive_from_robot(timeout=0.1)
    if not ok:
        quiet += 0.1
        if quiet >= 2.0 and log:
            break
        if quiet >= 60.0:
            break
        continue
    quiet = 0.0
    m = st.robot_message
    log.append({
        "tm": m.header.tm,
        "seqno": m.header.seqno,
        "joints": list(st.joint_angles),
        "planned": list(st.joint_angles_planned),
        "pos_mm": list(st.cartesian[0]),
        "quat": list(st.cartesian[1]),
        "force": None if st.measured_force is None else list(st.measured_force),
        "mci": m.mciState.state,
        "motors_on": st.motors_on,
        "rapid_running": st.rapid_running,
        "sent": None,
    })
    if hold is None:
        hold = np.array(st.joint_angles_planned)
    cmd = hold
    if n >= 50:
        if mode == "step":
            cmd = hold + np.array([0, 0, 0, 0, 0, 1.0])
        elif mode == "silent":
            cmd = None
        elif mode == "out_of_limit" and n == 50:
            cmd = hold.copy()
            cmd[2] = 70.0
        elif mode == "too_fast" and n == 50:
            cmd = hold + np.array([0, 0, 0, 0, 0, 3.0])
        elif mode == "repeat_seq" and n == 50:
            # abb-robot-client steps its sequence number by 2 per message; go back one message
            egm.send_sequence_number -= 2
    if cmd is not None:
        egm.send_to_robot(cmd)
        log[-1]["sent"] = list(cmd)
    n += 1

with open(out, "w") as f:
    json.dump(log, f)
