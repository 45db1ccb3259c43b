//! An assembly of parts with their poses over one period: what the animated glTF file and the
//! shaded renders show.
//!
//! Owns [`Scene`], [`ScenePart`] and [`Pose`]. A part's mesh is in its own frame (mm); a
//! pose maps it into the world: x_world = R·x_part + T. It does not know what the parts are
//! (the mechanism's driver, follower and support are placed by `build`).

use super::mesh::Mesh;

/// A rigid placement: unit quaternion (scalar first) and translation in mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Unit quaternion [w, x, y, z].
    pub rotation: [f64; 4],
    /// Translation, mm.
    pub translation: [f64; 3],
}

impl Pose {
    /// No rotation, no translation.
    pub const IDENTITY: Pose = Pose {
        rotation: [1.0, 0.0, 0.0, 0.0],
        translation: [0.0; 3],
    };

    /// Apply to a point of the part's frame.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = self.rotate(p);
        [
            r[0] + self.translation[0],
            r[1] + self.translation[1],
            r[2] + self.translation[2],
        ]
    }

    /// Rotate a vector (no translation).
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let [w, x, y, z] = self.rotation;
        // v' = v + 2w(q×v) + 2 q×(q×v), q = (x, y, z).
        let q = [x, y, z];
        let c1 = cross(q, v);
        let c2 = cross(q, c1);
        [
            v[0] + 2.0 * (w * c1[0] + c2[0]),
            v[1] + 2.0 * (w * c1[1] + c2[1]),
            v[2] + 2.0 * (w * c1[2] + c2[2]),
        ]
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// One part of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenePart {
    /// Name shown in viewers ("driver", "follower", "support").
    pub name: String,
    /// The part in its own frame, mm.
    pub mesh: Mesh,
    /// Base colour, linear RGBA in [0, 1].
    pub color: [f32; 4],
    /// One pose per entry of [`Scene::times_s`] for a moving part, or exactly one pose for a
    /// part that does not move.
    pub poses: Vec<Pose>,
}

impl ScenePart {
    /// The pose at key `i` (the only pose of a static part).
    pub fn pose(&self, i: usize) -> Pose {
        if self.poses.len() == 1 {
            self.poses[0]
        } else {
            self.poses[i]
        }
    }
}

/// Parts and the key times of one period of their motion.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// The parts.
    pub parts: Vec<ScenePart>,
    /// Key times, seconds from 0 (strictly increasing); the period ends at the last key,
    /// whose poses equal the first key's so that a looping animation is seamless.
    pub times_s: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quarter turn about z maps x to y, and translation is added after the rotation.
    #[test]
    fn pose_rotates_then_translates() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let p = Pose {
            rotation: [h, 0.0, 0.0, h],
            translation: [1.0, 2.0, 3.0],
        };
        let r = p.apply([1.0, 0.0, 0.0]);
        for (a, b) in r.iter().zip([1.0, 3.0, 3.0]) {
            assert!((a - b).abs() < 1e-12, "{r:?}");
        }
    }
}
