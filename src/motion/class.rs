//! The three motion classes, named by the follower–support joint.

use std::fmt;
use std::str::FromStr;

/// The follower's motion space, fixed by its joint with the support (docs/conventions.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum MotionClass {
    /// Revolute joint: rotation about +z only.
    #[serde(rename = "1R")]
    R1,
    /// Cylindrical joint: rotation about and translation along z.
    #[serde(rename = "1R1T")]
    R1T1,
    /// Spherical joint: any rotation about the origin, no translation.
    #[serde(rename = "3R")]
    R3,
}

impl MotionClass {
    /// Degrees of freedom of the motion space: 1, 2 or 3.
    pub fn dof(self) -> usize {
        match self {
            Self::R1 => 1,
            Self::R1T1 => 2,
            Self::R3 => 3,
        }
    }

    /// The name used in files: "1R", "1R1T" or "3R".
    pub fn as_str(self) -> &'static str {
        match self {
            Self::R1 => "1R",
            Self::R1T1 => "1R1T",
            Self::R3 => "3R",
        }
    }

    /// Whether the follower only turns about z (1R, 1R1T).
    pub fn is_planar_rotation(self) -> bool {
        matches!(self, Self::R1 | Self::R1T1)
    }
}

impl fmt::Display for MotionClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The text was not "1R", "1R1T" or "3R".
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown motion class {0:?} (expected \"1R\", \"1R1T\" or \"3R\")")]
pub struct UnknownClass(pub String);

impl FromStr for MotionClass {
    type Err = UnknownClass;

    /// Exact names, ignoring ASCII case and surrounding blanks ("1r1t" is accepted).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_uppercase().as_str() {
            "1R" => Ok(Self::R1),
            "1R1T" => Ok(Self::R1T1),
            "3R" => Ok(Self::R3),
            _ => Err(UnknownClass(s.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the names used in files and mechanism.json: Display, FromStr and serde agree.
    #[test]
    fn names_round_trip() {
        for (class, name, dof) in [
            (MotionClass::R1, "1R", 1),
            (MotionClass::R1T1, "1R1T", 2),
            (MotionClass::R3, "3R", 3),
        ] {
            assert_eq!(class.to_string(), name);
            assert_eq!(name.parse::<MotionClass>().unwrap(), class);
            assert_eq!(
                serde_json::to_string(&class).unwrap(),
                format!("\"{name}\"")
            );
            assert_eq!(
                serde_json::from_str::<MotionClass>(&format!("\"{name}\"")).unwrap(),
                class
            );
            assert_eq!(class.dof(), dof);
        }
        assert!("2R".parse::<MotionClass>().is_err());
    }
}
