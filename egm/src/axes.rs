//! ABB's axis angles against the DH joints of DESIGN section 3 (thesis Table 7.1).
//!
//! ABB reports and takes axis angles in degrees, each axis positive by the right-hand rule about
//! its axis at ABB's zero pose (lower arm vertical, upper arm horizontal along base +x): axis 1
//! about base +z, axes 2, 3 and 5 about +y, axes 4 and 6 about +x (ABB's product specification;
//! the ROS-Industrial IRB 2400 description, whose joint values are the controller's own, has the
//! same axes). The DH joints turn about the z axes of their frames; at ABB's zero pose (DH
//! `q = (0, −π/2, 0, 0, 0, 0)`) those are +z, +y, +y, +x, +y, +x for joints 1..6, so every sign is
//! +1 and only joint 2 has an offset:
//!
//! `q_i = θ_i π/180 + OFFSET_RAD[i]`, `OFFSET_RAD = (0, −π/2, 0, 0, 0, 0)`, `SIGN = +1` for all six.
//!
//! `tests/axes.rs` checks it against the robot model: the DH joint axes at ABB's zero are ABB's,
//! the wrist centre there is the product specification's (855 mm, 0, 1455 mm) and the flange
//! 85 mm further along +x, and the DH position limits are ABB's axis ranges.

/// Sign of each ABB axis against its DH joint.
pub const SIGN: [f64; 6] = [1.0; 6];
/// DH joint value at ABB axis angle zero (rad).
pub const OFFSET_RAD: [f64; 6] = [0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0];

const DEG: f64 = std::f64::consts::PI / 180.0;

/// DH joint positions (rad) of ABB axis angles (degrees).
pub fn dh_from_abb_deg(abb_deg: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| SIGN[i] * abb_deg[i] * DEG + OFFSET_RAD[i])
}

/// ABB axis angles (degrees) of DH joint positions (rad).
pub fn abb_deg_from_dh(q_rad: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| SIGN[i] * (q_rad[i] - OFFSET_RAD[i]) / DEG)
}

/// DH joint velocities (rad/s) of ABB axis speeds (degrees/s): the offsets drop out.
pub fn dh_rate_from_abb_deg(abb_deg_s: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| SIGN[i] * abb_deg_s[i] * DEG)
}

/// ABB axis speeds (degrees/s) of DH joint velocities (rad/s).
pub fn abb_rate_deg_from_dh(qd_rad_s: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| SIGN[i] * qd_rad_s[i] / DEG)
}
