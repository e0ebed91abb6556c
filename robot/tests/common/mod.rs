//! Shared test helpers: deterministic pseudo-random states and example robots.
#![allow(dead_code)]

use robot::params::{DhRow, LinkRow};
use robot::{Robot, Tool, Vec6};

/// Small deterministic generator (splitmix64) so failures reproduce.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * (z >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn vec6(&mut self, amplitude: f64) -> Vec6 {
        Vec6::from_fn(|_, _| self.uniform(-amplitude, amplitude))
    }
}

/// A 6R arm with random DH rows (general twist angles, not only 0 and +-pi/2) and random but
/// physical link inertias, so no identity can pass by the symmetry of Table 7.1.
pub fn random_arm(seed: u64) -> Robot {
    let mut rng = Rng::new(seed);
    let dh: [DhRow; 6] =
        std::array::from_fn(|_| DhRow { d_m: rng.uniform(-0.5, 0.5), a_m: rng.uniform(-0.5, 0.5), alpha_rad: rng.uniform(-3.0, 3.0) });
    let links: [LinkRow; 6] = std::array::from_fn(|_| {
        // Inertia about the COM: principal moments obeying the triangle inequality, rotated.
        let (p1, p2) = (rng.uniform(0.01, 1.0), rng.uniform(0.01, 1.0));
        let p3 = rng.uniform((p1 - p2).abs() + 1e-3, p1 + p2);
        let rot = nalgebra::Rotation3::from_euler_angles(rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0));
        let inertia = rot.matrix() * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(p1, p2, p3)) * rot.matrix().transpose();
        LinkRow {
            mass_kg: rng.uniform(0.5, 20.0),
            com_m: [rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)],
            inertia_kgm2: std::array::from_fn(|r| std::array::from_fn(|c| inertia[(r, c)])),
        }
    });
    Robot::from_tables(&dh, &links, Some(Tool::default()))
}

/// The models every identity is checked on: bare arm, arm with the default tool, the tool plus
/// armature and viscous friction, and a random arm with general geometry.
pub fn robots() -> Vec<(&'static str, Robot)> {
    vec![
        ("random geometry", random_arm(99)),
        ("bare", Robot::irb2400()),
        ("tool", Robot::irb2400_with_tool(Tool::default())),
        (
            "tool+armature+viscous",
            Robot::irb2400_with_tool(Tool::default())
                .with_armature(Vec6::new(0.5, 0.5, 0.3, 0.02, 0.02, 0.01))
                .with_viscous(Vec6::new(5.0, 5.0, 3.0, 0.5, 0.5, 0.2)),
        ),
    ]
}

/// Relative difference `|a - b| / max(|a|, |b|, floor)`.
pub fn rel_err(a: &Vec6, b: &Vec6, floor: f64) -> f64 {
    (a - b).norm() / a.norm().max(b.norm()).max(floor)
}
