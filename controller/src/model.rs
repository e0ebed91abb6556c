//! The controller's robot model built from the scenario (without the plant's inertia scale).
//! The rig's geometry (task frame, tool, start pose) is `scenario::geometry`'s.

use robot::{Robot, Vec6};
use scenario::geometry;
use scenario::Scenario;

/// The controller's robot model: the scenario's arm and tool ([`geometry::tool`]) with armature
/// and viscous friction, deliberately WITHOUT `robot.plant_inertia_scale` (that is the plant's
/// mismatch).
pub fn controller_robot(s: &Scenario) -> Robot {
    Robot::irb2400_with_tool(geometry::tool(s))
        .with_armature(Vec6::from(s.robot.armature_kgm2))
        .with_viscous(Vec6::from(s.robot.viscous_nms))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controller_robot_ignores_plant_inertia_scale() {
        let mut s = Scenario::default();
        let a = controller_robot(&s).total_mass_kg();
        s.robot.plant_inertia_scale = 1.1;
        assert_eq!(controller_robot(&s).total_mass_kg(), a);
    }
}
