//! A small mechanism-like scene for the geometry export and render tests: a static grey base
//! plate, an orange driver (a torus with a box lug) turning once about the z axis through
//! (30, 0, 0), and a blue follower (a sphere on an arm) swinging ±40° about z while sliding
//! 5 mm up and down, over a period of 2 s in `keys` steps (the last key equals the first).
//! Used by the geometry export tests (`geometry_glb`, `geometry_trimesh`).

use mpc_rig::geometry::primitive_meshes::{cuboid, torus, uv_sphere};
use mpc_rig::geometry::{Mesh, Pose, Scene, ScenePart};

/// Driver axis offset, mm.
pub const DX: f64 = 30.0;
/// Period, s.
pub const PERIOD_S: f64 = 2.0;

fn rz(angle: f64) -> [f64; 4] {
    let h = 0.5 * angle;
    [h.cos(), 0.0, 0.0, h.sin()]
}

/// The driver's pose at fraction `t` of the period.
pub fn driver_pose(t: f64) -> Pose {
    Pose {
        rotation: rz(std::f64::consts::TAU * t),
        translation: [DX, 0.0, 0.0],
    }
}

/// The follower's pose at fraction `t` of the period.
pub fn follower_pose(t: f64) -> Pose {
    let s = (std::f64::consts::TAU * t).sin();
    Pose {
        rotation: rz(40f64.to_radians() * s),
        translation: [0.0, 0.0, 5.0 * s],
    }
}

/// The scene with `keys` + 1 key times (0 ..= period).
pub fn mechanism_scene(keys: usize) -> Scene {
    let ts: Vec<f64> = (0..=keys).map(|k| k as f64 / keys as f64).collect();
    let mut driver = torus([0.0; 3], 14.0, 4.0, 96, 32);
    driver.append(&cuboid([13.0, -4.0, -3.0], [22.0, 4.0, 3.0]));
    let mut follower: Mesh = uv_sphere([-6.0, 0.0, 0.0], 7.0, 64, 32);
    follower.append(&cuboid([-4.0, -2.5, -2.5], [6.0, 2.5, 2.5]));
    Scene {
        parts: vec![
            ScenePart {
                name: "support".into(),
                mesh: cuboid([-25.0, -25.0, -18.0], [55.0, 25.0, -14.0]),
                color: [0.55, 0.56, 0.58, 1.0],
                poses: vec![Pose::IDENTITY],
            },
            ScenePart {
                name: "driver".into(),
                mesh: driver,
                color: [0.90, 0.35, 0.08, 1.0],
                poses: ts.iter().map(|&t| driver_pose(t)).collect(),
            },
            ScenePart {
                name: "follower".into(),
                mesh: follower,
                color: [0.10, 0.35, 0.80, 1.0],
                poses: ts.iter().map(|&t| follower_pose(t)).collect(),
            },
        ],
        times_s: ts.iter().map(|t| t * PERIOD_S).collect(),
    }
}
