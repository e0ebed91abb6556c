//! The EGM session rules of the robot controller: which `EgmSensor` messages it takes.
//!
//! - The sensor's sequence number (`header.seqno`) must increase from one accepted message to the
//!   next; gaps are fine (`abb-robot-client` steps by 2). A repeated or older number, or none, is
//!   refused: the message is stale or from a second sender.
//! - Joint references (`planned.joints`) must have six values, each within the axis range, and
//!   reach no joint speed beyond its axis speed from the previous accepted reference within one
//!   EGM cycle; speed references (`speedRef.joints`), if sent, must be within the axis speeds.
//! - A refused message changes nothing: the previous reference stays.
//!
//! Everything here works on fixed-size values; decoding reuses the message's buffers (see
//! [`SensorBuffer`]), so taking a reference allocates nothing once the buffers have grown.

use egm::pb;
use robot::Vec6;

/// Why a sensor message was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// Not an `EgmSensor` protobuf.
    Malformed,
    NoSequenceNumber,
    /// `seqno` not greater than the last accepted one.
    Sequence {
        seqno: u32,
        last: u32,
    },
    /// No joint references (pose references are not emulated).
    NoJoints,
    JointCount(usize),
    /// Axis `axis` (1-based) reference beyond its range (degrees, ABB convention).
    Range {
        axis: usize,
        deg: f64,
        lo: f64,
        hi: f64,
    },
    /// Reaching the reference within one cycle needs this axis speed (degrees/s) over the limit.
    Speed {
        axis: usize,
        deg_s: f64,
        limit: f64,
    },
    /// A speed reference over the axis speed (degrees/s).
    SpeedRef {
        axis: usize,
        deg_s: f64,
        limit: f64,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Refusal::Malformed => write!(f, "not an EgmSensor message"),
            Refusal::NoSequenceNumber => write!(f, "no header sequence number"),
            Refusal::Sequence { seqno, last } => write!(f, "wrong sequence: seqno {seqno} after {last} (must increase)"),
            Refusal::NoJoints => write!(f, "no joint references (planned.joints)"),
            Refusal::JointCount(n) => write!(f, "{n} joint references, the robot has 6"),
            Refusal::Range { axis, deg, lo, hi } => write!(f, "axis {axis} reference {deg:.3} deg beyond its range {lo:.0} .. {hi:.0} deg"),
            Refusal::Speed { axis, deg_s, limit } => {
                write!(f, "axis {axis} reference needs {deg_s:.1} deg/s within one cycle, the axis speed is {limit:.0} deg/s")
            }
            Refusal::SpeedRef { axis, deg_s, limit } => {
                write!(f, "axis {axis} speed reference {deg_s:.1} deg/s beyond the axis speed {limit:.0} deg/s")
            }
        }
    }
}

/// A reference the rules accepted, DH convention.
#[derive(Debug, Clone, Copy)]
pub struct Accepted {
    pub seqno: u32,
    pub q_ref: Vec6,
    pub qd_ref: Vec6,
    /// As received, degrees and degrees/s (ABB convention; zero speeds when none were sent).
    pub joints_deg: [f64; 6],
    pub speed_deg_s: [f64; 6],
}

/// Decodes `EgmSensor` into one message kept for the whole run: its vectors keep their capacity,
/// so after the first messages no decode allocates.
pub struct SensorBuffer {
    msg: pb::EgmSensor,
}

impl Default for SensorBuffer {
    fn default() -> Self {
        let joints = || Some(pb::EgmJoints { joints: Vec::with_capacity(16) });
        SensorBuffer {
            msg: pb::EgmSensor {
                header: Some(pb::EgmHeader::default()),
                planned: Some(pb::EgmPlanned { joints: joints(), external_joints: joints(), ..Default::default() }),
                speed_ref: Some(pb::EgmSpeedRef { joints: joints(), external_joints: joints(), ..Default::default() }),
            },
        }
    }
}

impl SensorBuffer {
    /// Decode `bytes`; afterwards an empty joint vector means "not sent".
    pub fn decode(&mut self, bytes: &[u8]) -> Result<&pb::EgmSensor, Refusal> {
        let m = &mut self.msg;
        if let Some(h) = m.header.as_mut() {
            *h = pb::EgmHeader::default();
        }
        let clear = |j: &mut Option<pb::EgmJoints>| {
            if let Some(j) = j.as_mut() {
                j.joints.clear();
            }
        };
        if let Some(p) = m.planned.as_mut() {
            clear(&mut p.joints);
            clear(&mut p.external_joints);
            p.cartesian = None;
            p.time = None;
        }
        if let Some(s) = m.speed_ref.as_mut() {
            clear(&mut s.joints);
            clear(&mut s.external_joints);
            s.cartesians = None;
        }
        prost::Message::merge(m, bytes).map_err(|_| Refusal::Malformed)?;
        Ok(&self.msg)
    }
}

/// The rules' state: the last accepted sequence number and reference.
pub struct Rules {
    cycle_s: f64,
    last_seqno: Option<u32>,
    /// The last accepted reference, DH rad (the start pose before any).
    last_ref: Vec6,
    /// The axis ranges in ABB's convention, degrees (`robot::params::POSITION_LIMIT_RAD`).
    range_deg: [[f64; 2]; 6],
}

impl Rules {
    pub fn new(cycle_s: f64, q0: Vec6) -> Rules {
        let lo = egm::axes::abb_deg_from_dh(&std::array::from_fn(|i| robot::Robot::POSITION_LIMIT_RAD[i][0]));
        let hi = egm::axes::abb_deg_from_dh(&std::array::from_fn(|i| robot::Robot::POSITION_LIMIT_RAD[i][1]));
        Rules { cycle_s, last_seqno: None, last_ref: q0, range_deg: std::array::from_fn(|i| [lo[i].min(hi[i]), lo[i].max(hi[i])]) }
    }

    /// Check one decoded message; on success it becomes the last accepted one.
    pub fn check(&mut self, m: &pb::EgmSensor) -> Result<Accepted, Refusal> {
        let seqno = m.header.as_ref().and_then(|h| h.seqno).ok_or(Refusal::NoSequenceNumber)?;
        if let Some(last) = self.last_seqno {
            if seqno <= last {
                return Err(Refusal::Sequence { seqno, last });
            }
        }
        let joints = m.planned.as_ref().and_then(|p| p.joints.as_ref()).map_or(&[][..], |j| j.joints.as_slice());
        if joints.is_empty() {
            return Err(Refusal::NoJoints);
        }
        if joints.len() != 6 {
            return Err(Refusal::JointCount(joints.len()));
        }
        let deg: [f64; 6] = std::array::from_fn(|i| joints[i]);
        let speeds = m.speed_ref.as_ref().and_then(|s| s.joints.as_ref()).map_or(&[][..], |j| j.joints.as_slice());
        if !speeds.is_empty() && speeds.len() != 6 {
            return Err(Refusal::JointCount(speeds.len()));
        }
        let speed_deg_s: [f64; 6] = std::array::from_fn(|i| speeds.get(i).copied().unwrap_or(0.0));
        let speed_limit_deg = egm::axes::abb_rate_deg_from_dh(&robot::Robot::VELOCITY_LIMIT_RADPS);
        for i in 0..6 {
            let [lo, hi] = self.range_deg[i];
            // NaN fails both comparisons: refused as out of range.
            if !(deg[i] >= lo && deg[i] <= hi) {
                return Err(Refusal::Range { axis: i + 1, deg: deg[i], lo, hi });
            }
            // NaN is refused too (it is not within the limit).
            if speed_deg_s[i].abs().partial_cmp(&speed_limit_deg[i].abs()).is_none_or(|o| o.is_gt()) {
                return Err(Refusal::SpeedRef { axis: i + 1, deg_s: speed_deg_s[i], limit: speed_limit_deg[i].abs() });
            }
        }
        let q_ref = Vec6::from(egm::axes::dh_from_abb_deg(&deg));
        let last_deg = egm::axes::abb_deg_from_dh(&self.last_ref.into());
        for i in 0..6 {
            let need = (deg[i] - last_deg[i]).abs() / self.cycle_s;
            if need > speed_limit_deg[i].abs() {
                return Err(Refusal::Speed { axis: i + 1, deg_s: need, limit: speed_limit_deg[i].abs() });
            }
        }
        self.last_seqno = Some(seqno);
        self.last_ref = q_ref;
        Ok(Accepted { seqno, q_ref, qd_ref: Vec6::from(egm::axes::dh_rate_from_abb_deg(&speed_deg_s)), joints_deg: deg, speed_deg_s })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;

    fn msg(seqno: Option<u32>, joints: &[f64], speeds: &[f64]) -> Vec<u8> {
        pb::EgmSensor {
            header: Some(pb::EgmHeader { seqno, tm: None, mtype: Some(pb::egm_header::MessageType::MsgtypeCorrection as i32) }),
            planned: Some(pb::EgmPlanned { joints: Some(pb::EgmJoints { joints: joints.to_vec() }), ..Default::default() }),
            speed_ref: (!speeds.is_empty())
                .then(|| pb::EgmSpeedRef { joints: Some(pb::EgmJoints { joints: speeds.to_vec() }), ..Default::default() }),
        }
        .encode_to_vec()
    }

    #[test]
    fn rules_take_increasing_sequence_numbers_and_refuse_the_rest() {
        let q0 = Vec6::from(robot::Robot::ABB_ZERO_Q);
        let mut rules = Rules::new(0.004, q0);
        let mut buf = SensorBuffer::default();
        let zero = [0.0; 6];
        assert!(rules.check(buf.decode(&msg(Some(1), &zero, &[])).unwrap()).is_ok());
        assert!(rules.check(buf.decode(&msg(Some(3), &zero, &[])).unwrap()).is_ok());
        assert_eq!(rules.check(buf.decode(&msg(Some(3), &zero, &[])).unwrap()).unwrap_err(), Refusal::Sequence { seqno: 3, last: 3 });
        assert_eq!(rules.check(buf.decode(&msg(None, &zero, &[])).unwrap()).unwrap_err(), Refusal::NoSequenceNumber);
        // axis 3's range is -60 .. 65 deg
        assert!(matches!(
            rules.check(buf.decode(&msg(Some(4), &[0.0, 0.0, 66.0, 0.0, 0.0, 0.0], &[])).unwrap()),
            Err(Refusal::Range { axis: 3, .. })
        ));
        // 1 deg within 4 ms on axis 1 is 250 deg/s, over its 150 deg/s
        assert!(matches!(
            rules.check(buf.decode(&msg(Some(5), &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], &[])).unwrap()),
            Err(Refusal::Speed { axis: 1, .. })
        ));
        assert!(matches!(
            rules.check(buf.decode(&msg(Some(6), &zero, &[0.0, 0.0, 0.0, 0.0, 0.0, 500.0])).unwrap()),
            Err(Refusal::SpeedRef { axis: 6, .. })
        ));
        let ok =
            rules.check(buf.decode(&msg(Some(7), &[0.5, 0.0, 0.0, 0.0, 0.0, 0.0], &[10.0, 0.0, 0.0, 0.0, 0.0, 0.0])).unwrap()).unwrap();
        assert_eq!(ok.seqno, 7);
        assert!((ok.qd_ref[0] - 10f64.to_radians()).abs() < 1e-15);
        // a later message without speed references has none (the buffer forgets the old ones)
        let ok = rules.check(buf.decode(&msg(Some(8), &[0.5, 0.0, 0.0, 0.0, 0.0, 0.0], &[])).unwrap()).unwrap();
        assert_eq!(ok.speed_deg_s, [0.0; 6]);
        assert_eq!(buf.decode(&[0xff, 0xff, 0xff]).unwrap_err(), Refusal::Malformed);
    }
}
