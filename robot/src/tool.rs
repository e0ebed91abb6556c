//! The applicator-wheel tool on the flange (DESIGN section 3).
//!
//! Tool frame = flange frame (DH frame 6) translated by `tcp_offset_flange_m`; the tool adds no
//! rotation. The wheel's axis is the flange y axis, so with the tool pointing straight down
//! (flange z = base -z) and joints 1, 4, 6 near zero the wheel axis lies along base y, across a
//! strip that runs along base x.

use nalgebra::{Matrix3, Vector3};

/// Rigid tool (bracket + applicator wheel) attached to the flange.
///
/// Defaults (documented in the README): 1 kg, modelled as a solid cylinder of radius 30 mm and
/// length 100 mm along the flange z axis, COM at 50 mm; the TCP is the wheel centre, 100 mm
/// along flange z (the scenario's `robot.tool_offset_m`); wheel radius 10 mm, so with the tool
/// pointing down the wheel's lowest point (the nominal contact with the strip) is 10 mm below
/// the TCP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tool {
    pub mass_kg: f64,
    /// Centre of mass in the flange frame (m).
    pub com_flange_m: Vector3<f64>,
    /// Inertia about the COM, flange axes (kg m^2).
    pub inertia_com: Matrix3<f64>,
    /// Tool centre point in the flange frame (m): the wheel centre.
    pub tcp_offset_flange_m: Vector3<f64>,
    pub wheel_radius_m: f64,
}

impl Tool {
    /// The applicator wheel on a straight bracket along flange z, as a scenario describes it:
    /// the [`Tool::default`] cylinder with mass and inertia scaled to `mass_kg`, the TCP (the
    /// wheel centre) `tcp_offset_m` along flange z, the COM half-way there. Plant and controller
    /// both build their tool with this one rule, so their models agree.
    pub fn wheel_on_bracket(mass_kg: f64, tcp_offset_m: f64, wheel_radius_m: f64) -> Tool {
        let d = Tool::default();
        Tool {
            mass_kg,
            com_flange_m: Vector3::new(0.0, 0.0, 0.5 * tcp_offset_m),
            inertia_com: d.inertia_com * (mass_kg / d.mass_kg),
            tcp_offset_flange_m: Vector3::new(0.0, 0.0, tcp_offset_m),
            wheel_radius_m,
        }
    }

    /// The wheel's point furthest along flange z, in the flange frame: its lowest point, where
    /// it touches the strip, when the tool points straight down.
    pub fn contact_point_flange_m(&self) -> Vector3<f64> {
        self.tcp_offset_flange_m + Vector3::new(0.0, 0.0, self.wheel_radius_m)
    }
}

impl Default for Tool {
    fn default() -> Self {
        let mass_kg = 1.0;
        let (radius, length) = (0.03, 0.1);
        let i_xx = mass_kg * (3.0 * radius * radius + length * length) / 12.0;
        let i_zz = mass_kg * radius * radius / 2.0;
        Tool {
            mass_kg,
            com_flange_m: Vector3::new(0.0, 0.0, 0.05),
            inertia_com: Matrix3::from_diagonal(&Vector3::new(i_xx, i_xx, i_zz)),
            tcp_offset_flange_m: Vector3::new(0.0, 0.0, 0.10),
            wheel_radius_m: 0.010,
        }
    }
}
