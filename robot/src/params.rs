//! The one place the IRB 2400 data lives: DH parameters (thesis Table 7.1), link inertias
//! (thesis Table E.1) and joint limits.
//!
//! Conventions (DESIGN section 3):
//! - standard (distal) DH, `A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`;
//! - the mass, centre of mass and inertia of link `i` are expressed in DH frame `i` (the distal
//!   frame of link `i`), inertia about the centre of mass, Table E.1's off-diagonal entries taken
//!   as tensor entries (not products of inertia with a minus sign);
//! - `q = 0` is not ABB's zero pose: ABB's zero is `q = (0, -pi/2, 0, 0, 0, 0)` here.

/// One row of Table 7.1 (lengths in m, angle in rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhRow {
    pub d_m: f64,
    pub a_m: f64,
    pub alpha_rad: f64,
}

/// One block of Table E.1: mass, COM in DH frame `i`, inertia about the COM in DH frame `i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkRow {
    pub mass_kg: f64,
    pub com_m: [f64; 3],
    pub inertia_kgm2: [[f64; 3]; 3],
}

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

/// Table 7.1: DH parameters of the ABB IRB 2400.
pub const IRB2400_DH: [DhRow; 6] = [
    DhRow { d_m: 0.615, a_m: 0.100, alpha_rad: -HALF_PI },
    DhRow { d_m: 0.0, a_m: 0.705, alpha_rad: 0.0 },
    DhRow { d_m: 0.0, a_m: 0.135, alpha_rad: -HALF_PI },
    DhRow { d_m: 0.755, a_m: 0.0, alpha_rad: HALF_PI },
    DhRow { d_m: 0.0, a_m: 0.0, alpha_rad: -HALF_PI },
    DhRow { d_m: 0.085, a_m: 0.0, alpha_rad: 0.0 },
];

/// Table E.1: link masses, COMs and inertias of the ABB IRB 2400 (from ABB's CAD data).
pub const IRB2400_LINKS: [LinkRow; 6] = [
    LinkRow { mass_kg: 150.0, com_m: [-0.070, 0.17, 0.019], inertia_kgm2: [[7.6, 1.0, 0.30], [1.0, 5.8, -0.10], [0.30, -0.10, 5.0]] },
    LinkRow {
        mass_kg: 47.0,
        com_m: [-0.38, 0.037, -0.0027],
        inertia_kgm2: [[0.38, 0.094, 0.0027], [0.094, 2.0, -0.025], [0.0027, -0.025, 2.1]],
    },
    LinkRow {
        mass_kg: 40.0,
        com_m: [-0.019, 0.010, -0.0011],
        inertia_kgm2: [[0.93, -0.010, -0.053], [-0.010, 0.91, 0.011], [-0.053, 0.011, 0.32]],
    },
    LinkRow {
        mass_kg: 18.0,
        com_m: [0.00030, -0.20, 0.0010],
        inertia_kgm2: [[0.52, -0.00038, -4.3e-5], [-0.00038, 0.044, -0.0036], [-4.3e-5, -0.0036, 0.51]],
    },
    LinkRow {
        mass_kg: 0.97,
        com_m: [0.00096, 4e-7, -0.00019],
        inertia_kgm2: [[0.00085, 0.0, 6.9e-6], [0.0, 0.0014, -2.8e-8], [6.9e-6, -2.8e-8, 0.00091]],
    },
    LinkRow {
        mass_kg: 0.57,
        com_m: [-9.1e-5, -9e-7, -0.047],
        inertia_kgm2: [[0.00047, 0.0, 1.0e-6], [0.0, 0.00047, 0.0], [1.0e-6, 0.0, 6.2e-5]],
    },
];

/// Gravitational acceleration, along -z of the base frame (m/s^2).
pub const GRAVITY_MPS2: f64 = 9.81;

/// Joint position limits in this DH convention (rad), `[lower, upper]` per joint.
///
/// From ABB's product specification of the IRB 2400 (3HAC 8857-1, "Working range" and "Axis
/// speeds"; IRB 2400/10 and /16) (axis 1 +-180 deg, axis 2 +110/-100 deg,
/// axis 3 +65/-60 deg, axis 4 +-200 deg, axis 5 +-120 deg, axis 6 +-400 deg), shifted to this
/// convention: DH `q2 = ABB axis 2 - pi/2`; the other axes share ABB's zero and sign.
pub const POSITION_LIMIT_RAD: [[f64; 2]; 6] = [
    [-std::f64::consts::PI, std::f64::consts::PI],
    [-100.0 * DEG - HALF_PI, 110.0 * DEG - HALF_PI],
    [-60.0 * DEG, 65.0 * DEG],
    [-200.0 * DEG, 200.0 * DEG],
    [-120.0 * DEG, 120.0 * DEG],
    [-400.0 * DEG, 400.0 * DEG],
];

/// Joint speed limits (rad/s), IRB 2400/16 product specification: 150, 150, 150, 360, 360,
/// 450 deg/s.
pub const VELOCITY_LIMIT_RADPS: [f64; 6] = [150.0 * DEG, 150.0 * DEG, 150.0 * DEG, 360.0 * DEG, 360.0 * DEG, 450.0 * DEG];

/// Mechanical end stops (DESIGN section 10): beyond a range limit the stop acts as a stiff spring
/// `τ = −k δ` on the penetration δ, stiff enough that the joint's own torque limit presses it in by
/// only `END_STOP_PENETRATION_AT_TORQUE_LIMIT_RAD` (0.25 degree): `k_i = TORQUE_LIMIT_NM[i] / 0.25 deg`,
/// so that a joint arriving at its axis speed stops within 2 degrees past its range.
/// The plant adds critical damping for the joint's inertia (see `plant_sim::limits`).
pub const END_STOP_PENETRATION_AT_TORQUE_LIMIT_RAD: f64 = 0.25 * DEG;

/// Drive torque–speed limit: a drive delivers its full torque up to the knee
/// `DRIVE_KNEE_SPEED_RATIO × VELOCITY_LIMIT_RADPS` and, while it drives the joint faster still
/// (motoring), linearly less, down to zero at `DRIVE_ZERO_TORQUE_SPEED_RATIO ×` the axis speed;
/// beyond that it brakes (the drive's speed limiter), with its full torque from
/// `DRIVE_FULL_BRAKE_SPEED_RATIO ×` the axis speed on, so coupling or gravity cannot carry a joint
/// much past it either. Braking torque is never limited. ABB publishes no drive curves; the knee
/// at the axis speed and the zero 5 % above it make the axis speed the practical maximum.
pub const DRIVE_KNEE_SPEED_RATIO: f64 = 1.0;
pub const DRIVE_ZERO_TORQUE_SPEED_RATIO: f64 = 1.05;
pub const DRIVE_FULL_BRAKE_SPEED_RATIO: f64 = 1.1;

/// Joint torque limits (N m). ABB does not publish them and the thesis gives none; these are
/// assumed values, a few times the static gravity load of each axis at full reach (axes 1-3)
/// and of the rated wrist moments (axes 4-6). Use them as saturation and sanity bounds only.
pub const TORQUE_LIMIT_NM: [f64; 6] = [1500.0, 1500.0, 800.0, 100.0, 100.0, 50.0];

const DEG: f64 = std::f64::consts::PI / 180.0;
