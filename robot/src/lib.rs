//! ABB IRB 2400 kinematics and rigid-body dynamics for the weatherstrip rig (issue 3, DESIGN
//! section 3): forward kinematics, geometric Jacobians, J-dot q-dot, RNEA, CRBA, gravity,
//! Coriolis, forward dynamics (CRBA + Cholesky) and inverse kinematics, on fixed-size nalgebra
//! types without allocation. Data: [`params`] (thesis Tables 7.1 and E.1).

pub mod cli;
pub mod dynamics;
pub mod ik;
pub mod kinematics;
pub mod model;
mod newton_euler;
pub mod params;
pub mod pose;
mod spatial;
pub mod tool;
pub mod urdf;

pub use ik::IkError;
pub use kinematics::Frames;
pub use model::{LinkInertia, Robot};
pub use newton_euler::{sin_cos, SinCos};
pub use pose::{ik_seed_tool_down, tool_down_pose};
pub use tool::Tool;

/// Joint-space vector (rad, rad/s, rad/s^2 or N m).
pub type Vec6 = nalgebra::SVector<f64, 6>;
/// 6x6 matrix (mass matrix, Jacobian).
pub type Mat6 = nalgebra::SMatrix<f64, 6, 6>;
