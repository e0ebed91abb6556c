//! Shared test helpers: deterministic pseudo-random states and example robots.
#![allow(dead_code)]

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

/// The models every identity is checked on: bare arm, arm with the default tool, and the tool
/// plus armature and viscous friction.
pub fn robots() -> Vec<(&'static str, Robot)> {
    vec![
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
