//! The robot description: DH geometry plus per-body inertia, tool, armature and friction.

use nalgebra::{Matrix3, Vector3};

use crate::params::{self, DhRow, LinkRow};
use crate::spatial::{BodyInertia, OriginInertia};
use crate::tool::Tool;
use crate::Vec6;

/// Inertial data of one body in its own DH frame: mass, COM, inertia about the COM.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkInertia {
    pub mass_kg: f64,
    pub com_m: Vector3<f64>,
    pub inertia_com: Matrix3<f64>,
}

impl LinkInertia {
    fn from_row(row: &LinkRow) -> Self {
        LinkInertia { mass_kg: row.mass_kg, com_m: Vector3::from(row.com_m), inertia_com: Matrix3::from_fn(|r, c| row.inertia_kgm2[r][c]) }
    }

    /// The rigid union of two bodies given in the same frame (parallel-axis theorem).
    pub fn combined(&self, other: &LinkInertia) -> LinkInertia {
        let mass_kg = self.mass_kg + other.mass_kg;
        let com_m = (self.com_m * self.mass_kg + other.com_m * other.mass_kg) / mass_kg;
        let shifted = |b: &LinkInertia| {
            let r = b.com_m - com_m;
            b.inertia_com + (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * b.mass_kg
        };
        LinkInertia { mass_kg, com_m, inertia_com: shifted(self) + shifted(other) }
    }

    fn scaled(&self, factor: f64) -> LinkInertia {
        LinkInertia { mass_kg: self.mass_kg * factor, com_m: self.com_m, inertia_com: self.inertia_com * factor }
    }
}

impl BodyInertia {
    /// The algorithms' form of a link's inertia (same frame, same numbers); written here so that
    /// `spatial` needs nothing from the description.
    fn local(link: &LinkInertia) -> Self {
        BodyInertia { mass: link.mass_kg, com: link.com_m, inertia_com: link.inertia_com }
    }
}

/// Precomputed constants of one DH row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DhConst {
    pub d: f64,
    pub a: f64,
    pub cos_alpha: f64,
    pub sin_alpha: f64,
}

impl DhConst {
    fn from_row(row: &DhRow) -> Self {
        let (s, c) = row.alpha_rad.sin_cos();
        // Snap the exact right angles of Table 7.1 so cos(pi/2) is 0, not 6e-17.
        let snap = |x: f64| if x.abs() < 1e-15 { 0.0 } else { x };
        DhConst { d: row.d_m, a: row.a_m, cos_alpha: snap(c), sin_alpha: snap(s) }
    }
}

/// ABB IRB 2400 rigid-body model (6 revolute joints), optionally with a tool on the flange.
///
/// All algorithms take `q`, `qd`, `qdd` in rad, rad/s, rad/s^2 and return N m; poses and Jacobians
/// are in the base frame. They use fixed-size types and do not allocate.
#[derive(Clone, Debug, PartialEq)]
pub struct Robot {
    pub(crate) dh: [DhConst; 6],
    /// Bare links from Table E.1 (each in its DH frame).
    links: [LinkInertia; 6],
    tool: Option<Tool>,
    /// Reflected motor inertia per joint (kg m^2), added to the mass-matrix diagonal.
    pub armature: Vec6,
    /// Viscous friction per joint (N m s/rad): torque `viscous_i * qd_i` opposes motion.
    pub viscous: Vec6,
    /// Bodies as the dynamics sees them: link 6 includes the tool.
    pub(crate) bodies: [BodyInertia; 6],
    /// The same bodies about their frame origins, for the CRBA.
    pub(crate) origin_inertias: [OriginInertia; 6],
    /// TCP in the flange frame (zero without a tool).
    pub(crate) tcp_flange_m: Vector3<f64>,
}

impl Robot {
    /// Joint position limits `[lower, upper]` (rad), this DH convention.
    pub const POSITION_LIMIT_RAD: [[f64; 2]; 6] = params::POSITION_LIMIT_RAD;
    /// Joint speed limits (rad/s).
    pub const VELOCITY_LIMIT_RADPS: [f64; 6] = params::VELOCITY_LIMIT_RADPS;
    /// Assumed joint torque limits (N m), see [`params::TORQUE_LIMIT_NM`].
    pub const TORQUE_LIMIT_NM: [f64; 6] = params::TORQUE_LIMIT_NM;
    /// Gravity along base -z (m/s^2).
    pub const GRAVITY_MPS2: f64 = params::GRAVITY_MPS2;
    /// ABB's zero pose in this DH convention.
    pub const ABB_ZERO_Q: [f64; 6] = [0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0];

    /// The bare arm (Tables 7.1 and E.1): no tool, no armature, no friction.
    pub fn irb2400() -> Robot {
        Robot::from_tables(&params::IRB2400_DH, &params::IRB2400_LINKS, None)
    }

    /// The arm carrying `tool` on its flange.
    pub fn irb2400_with_tool(tool: Tool) -> Robot {
        Robot::from_tables(&params::IRB2400_DH, &params::IRB2400_LINKS, Some(tool))
    }

    /// A 6R arm from any DH table and link data in the conventions of [`params`].
    pub fn from_tables(dh: &[DhRow; 6], links: &[LinkRow; 6], tool: Option<Tool>) -> Robot {
        let mut robot = Robot {
            dh: std::array::from_fn(|i| DhConst::from_row(&dh[i])),
            links: std::array::from_fn(|i| LinkInertia::from_row(&links[i])),
            tool,
            armature: Vec6::zeros(),
            viscous: Vec6::zeros(),
            bodies: [BodyInertia::default(); 6],
            origin_inertias: [OriginInertia::default(); 6],
            tcp_flange_m: Vector3::zeros(),
        };
        robot.rebuild();
        robot
    }

    fn rebuild(&mut self) {
        for i in 0..6 {
            let mut body = self.links[i];
            if i == 5 {
                if let Some(tool) = &self.tool {
                    body = body.combined(&LinkInertia { mass_kg: tool.mass_kg, com_m: tool.com_flange_m, inertia_com: tool.inertia_com });
                }
            }
            self.bodies[i] = BodyInertia::local(&body);
            self.origin_inertias[i] = OriginInertia::from_body(&self.bodies[i]);
        }
        self.tcp_flange_m = self.tool.map_or(Vector3::zeros(), |t| t.tcp_offset_flange_m);
    }

    /// Same robot with per-joint armature (reflected motor inertia, kg m^2).
    pub fn with_armature(mut self, armature: Vec6) -> Robot {
        self.armature = armature;
        self
    }

    /// Same robot with per-joint viscous friction (N m s/rad).
    pub fn with_viscous(mut self, viscous: Vec6) -> Robot {
        self.viscous = viscous;
        self
    }

    /// All link and tool masses and inertias (and the armature) scaled by `factor`; geometry
    /// and COMs unchanged. For plant/controller mismatch studies.
    pub fn scaled_inertia(&self, factor: f64) -> Robot {
        let mut robot = self.clone();
        for link in robot.links.iter_mut() {
            *link = link.scaled(factor);
        }
        if let Some(tool) = robot.tool.as_mut() {
            tool.mass_kg *= factor;
            tool.inertia_com *= factor;
        }
        robot.armature *= factor;
        robot.rebuild();
        robot
    }

    /// Link `i`'s mass and inertia scaled by `scale[i]` (the tool and the armature unchanged):
    /// a plant whose links the controller's model gets wrong by stated factors.
    pub fn scaled_links(&self, scale: &[f64; 6]) -> Robot {
        let mut robot = self.clone();
        for (link, f) in robot.links.iter_mut().zip(scale) {
            *link = link.scaled(*f);
        }
        robot.rebuild();
        robot
    }

    /// The same robot carrying `tool` instead.
    pub fn with_tool(&self, tool: Tool) -> Robot {
        let mut robot = self.clone();
        robot.tool = Some(tool);
        robot.rebuild();
        robot
    }

    /// The tool, if any.
    pub fn tool(&self) -> Option<&Tool> {
        self.tool.as_ref()
    }

    /// Bare link `i` (0-based) as in Table E.1.
    pub fn link(&self, i: usize) -> &LinkInertia {
        &self.links[i]
    }

    /// Total moving mass including the tool (kg).
    pub fn total_mass_kg(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass).sum()
    }
}
