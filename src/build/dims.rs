//! Every dimension of the printed parts and their bench hardware, in millimetres, each with
//! the reason for its value. One owner: parts, support and checks read them from here.

/// Print clearance between driver and follower, split evenly between them, so the design
/// contacts touch in the middle of the play (default of `--clearance`). 0.2 mm: the usual
/// FDM clearance for parts that must slide (0.4 mm nozzle, 0.2 mm layers).
pub const DEFAULT_CLEARANCE_MM: f64 = 0.2;

/// Cell size of the mesher. 0.4 mm: the mesh error on curved surfaces (h²/8R plus the
/// field's own error) stays below 0.05 mm on the 0.85 mm apex radius of the rims, half of
/// the 0.1 mm budget, and the demo's parts mesh in under three minutes (driver 136 s,
/// follower 38 s, 2026-12-05; the 60 s for a whole build is not met). Not at
/// a corner of a rim's apex line, where c² turns sharply about a near-stationary contact:
/// there the mesh lay 0.10–0.20 mm inside the solid (docs/build.md, screw-bob's K = 7).
pub const DEFAULT_CELL_MM: f64 = 0.4;

/// How far the parts' meshes may be simplified from the mesher's (default of
/// `--simplify-mm`): every vertex left within this of the plane of each face it absorbed
/// (`geometry::simplify`). 0.01 mm: a tenth of the 0.1 mm mesh-error budget and a
/// twentieth of the clearance, and less than a desktop printer's motor step (0.0125 mm
/// at the common 80 steps per mm). The mesher's triangles are a third of a cell across
/// even where the surface is flat; at this bound half-turn-2to1's printable parts keep
/// 25–39 % of them (134 → 34 MB of STL for the driver).
pub const DEFAULT_SIMPLIFY_MM: f64 = 0.01;

/// Material thinner than this is not printed: the driver's mesh leaves out what the carve
/// leaves thinner (the ragged sheets where a rim's sweep cut a band nearly through),
/// farther than `geometry::mesher::trim_reach` from thicker material, and a band's pieces
/// are not joined through it (`segments::BRIDGE_MM`). 0.8 mm: two lines of a 0.4 mm
/// nozzle, the thinnest wall a slicer lays as a wall; thinner, it prints one loose strand
/// or nothing, and a strand that breaks off falls into the mechanism. On screw-bob's
/// demo design this left out 108 mm³ of such sheets, every contact figure unchanged
/// (0.4 mm left out 10 mm³: the sheets are mostly 0.4–0.8 mm thick).
pub const SLIVER_MM: f64 = 0.8;

/// The follower rim's section (depth along the contact normal, half width across it):
/// synthesis owns it, since which contacts a printed pair keeps depends on it.
pub use crate::synth::undercut::{RIM_DEPTH_MM, RIM_HALF_WIDTH_MM};
/// Follower plate (the web that closes each rim): half thickness. 1.2 mm: a 2.4 mm plate,
/// stiff enough in PLA over the 20–40 mm spans of the examples, thinner than the rim so
/// the web never reaches the contact side of the rim.
pub const WEB_HALF_THICKNESS_MM: f64 = 1.2;

/// The driver band's section (half width, depth behind the contact, lip past it):
/// synthesis owns it too, since whether a strut can leave a follower plate depends on the
/// band's sweep around it.
pub use crate::synth::undercut::{BAND_DEPTH_MM, BAND_HALF_WIDTH_MM, BAND_LIP_MM};
/// Driver band: corner radius of the rectangular section (no sharp edge for the mesher to
/// chamfer). 0.6 mm.
pub const BAND_ROUND_MM: f64 = 0.6;

/// Radius of the struts that join plates to hubs and bands to the driver hub. 2.2 mm: a
/// 4.4 mm round strut, eleven perimeters, stiff over the 30–80 mm spans the planner finds.
pub const STRUT_RADIUS_MM: f64 = 2.2;
/// Free space kept around a strut beyond its radius from anything of the other part over
/// the whole period (and from the support). 1.2 mm: several times the print clearance, and
/// more than the 1 mm voxels the planner searches on.
pub const STRUT_MARGIN_MM: f64 = 1.2;
/// Margin by which a plate's web is kept off the other part's swept volume. 0.8 mm.
pub const WEB_MARGIN_MM: f64 = 0.8;
/// Voxel edge of the planning grids (swept volumes, free space, strut paths). 1 mm.
pub const PLAN_VOXEL_MM: f64 = 1.0;

/// Vertical gap between the lowest moving material and the hubs, and between a hub and
/// the base plate. 3 mm.
pub const HUB_GAP_MM: f64 = 3.0;
/// Height of the driver and follower hubs. 14 mm: a bore length of almost three shaft
/// diameters keeps a 5 mm shaft from rocking.
pub const HUB_HEIGHT_MM: f64 = 14.0;
/// Driver hub radius. 9 mm.
pub const DRIVER_HUB_RADIUS_MM: f64 = 9.0;
/// Follower hub radius. 7 mm.
pub const FOLLOWER_HUB_RADIUS_MM: f64 = 7.0;

/// NEMA 17 stepper: shaft diameter. 5 mm.
pub const NEMA17_SHAFT_MM: f64 = 5.0;
/// NEMA 17 stepper: the D-flat leaves 4.5 mm across (shaft minus 0.5 mm flat).
pub const NEMA17_FLAT_MM: f64 = 4.5;
/// NEMA 17 stepper: mounting screw square (M3 on 31 mm).
pub const NEMA17_SCREW_SQUARE_MM: f64 = 31.0;
/// NEMA 17 stepper: pilot boss diameter (22 mm) plus clearance for the hole in the base.
pub const NEMA17_PILOT_HOLE_MM: f64 = 22.6;
/// NEMA 17 stepper: body width. 42.3 mm.
pub const NEMA17_BODY_MM: f64 = 42.3;
/// M3 clearance hole. 3.4 mm (normal fit).
pub const M3_CLEARANCE_MM: f64 = 3.4;
/// M2 clearance hole. 2.4 mm (normal fit).
pub const M2_CLEARANCE_MM: f64 = 2.4;

/// Dynamixel X430 horn (HN11-I101 on the XL430-W250): screw circle diameter of its eight
/// M2 holes. 16 mm, from ROBOTIS's horn drawing; check it against your horn before
/// printing (it is the one figure here not measured by us).
pub const XL430_HORN_PCD_MM: f64 = 16.0;
/// Dynamixel X430 horn: number of screw holes. 8.
pub const XL430_HORN_HOLES: usize = 8;
/// Dynamixel X430 horn: diameter of the raised horn the hub sits over (with clearance).
pub const XL430_HORN_RECESS_MM: f64 = 20.0;
/// Dynamixel X430 body: 28.5 × 34 mm footprint (W × D), 46.5 mm tall (ROBOTIS e-Manual).
pub const XL430_BODY_MM: [f64; 3] = [28.5, 34.0, 46.5];

/// Shaft the follower turns (1R) or slides (1R1T) on: a 5 mm steel rod.
pub const FOLLOWER_SHAFT_MM: f64 = 5.0;

/// Diametric magnet for the AS5600: 6 × 2.5 mm, the common one. The seat adds 0.2 mm to
/// the diameter and 0.2 mm to the depth for glue.
pub const MAGNET_DIAMETER_MM: f64 = 6.0;
/// Magnet thickness.
pub const MAGNET_THICKNESS_MM: f64 = 2.5;
/// Air gap between magnet and AS5600 chip. 1.5 mm: the middle of the 0.5–3 mm the
/// datasheet allows for a 6 mm magnet.
pub const AS5600_AIR_GAP_MM: f64 = 1.5;
/// AS5600 breakout board: square side and M3 hole spacing of the common 23 mm boards
/// (holes 16 mm apart on the diagonal side), board 1.6 mm thick with the chip on top.
pub const AS5600_BOARD_MM: f64 = 23.0;
/// AS5600 breakout board: spacing of its two mounting holes.
pub const AS5600_HOLE_SPACING_MM: f64 = 16.0;

/// BNO055 breakout board pad (Adafruit-style 27 × 20 mm board, M2.5 holes 22 mm apart).
pub const IMU_PAD_MM: [f64; 2] = [27.0, 20.0];
/// BNO055 board mounting hole spacing.
pub const IMU_HOLE_SPACING_MM: f64 = 22.0;

/// 3R joint: radius of the follower's ball. 6 mm (a 12 mm ball).
pub const BALL_RADIUS_MM: f64 = 6.0;
/// 3R joint: wall of the support's cup around the ball.
pub const CUP_WALL_MM: f64 = 2.5;

/// Base plate thickness. 5 mm.
pub const BASE_THICKNESS_MM: f64 = 5.0;
/// Radius of the support's pillars and posts. 5 mm.
pub const PILLAR_RADIUS_MM: f64 = 5.0;
/// Margin between the support and anything moving. 3 mm.
pub const SUPPORT_MARGIN_MM: f64 = 3.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the one fact synthesis and the build must share about a strut: the free space
    /// the island and plate tests ask of a ray starts from the planner's strut, its radius
    /// and margin (`synth::undercut::ESCAPE_STRUT_MM`, to which they add how much the
    /// planner's field understates). Were they to differ, synthesis would accept designs
    /// whose pieces the build cannot join, or refuse ones it can.
    #[test]
    fn the_island_test_frees_a_point_where_a_strut_fits() {
        let fits = STRUT_RADIUS_MM + STRUT_MARGIN_MM;
        assert!((fits - crate::synth::undercut::ESCAPE_STRUT_MM).abs() < 1e-9);
    }
}
