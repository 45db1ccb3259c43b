//! From parsed keys to a validated [`Motion`]: the checks every input format shares (times,
//! class constraints, key counts, whole turns) and the scan for warnings.
//!
//! Parsers ([`super::spec`], [`super::dense`], [`super::mechanism`]) turn their syntax
//! into [`RawKey`]s with locations; this module owns everything after that.

use std::path::PathBuf;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::angle::{AngleLaw, AngleScheme};
use super::rotation::{tilt_deg, RotationLaw, MAX_KEY_STEP_DEG};
use super::spline::PeriodicSpline;
use super::*;

/// One parsed pose with where it came from.
#[derive(Debug, Clone)]
pub(crate) struct RawKey {
    pub t: f64,
    pub rotation: UnitQuaternion<f64>,
    pub translation: Vector3<f64>,
    /// Explicit unwrapped angle about z in radians (1R/1R1T keys written as `angle`);
    /// otherwise the angle is unwrapped from the rotation.
    pub angle: Option<f64>,
    /// Line of the key (its `t` field) in the source.
    pub line: Option<usize>,
    /// Field prefix naming the key, e.g. `key[2]` or `row 14`.
    pub field: String,
}

/// How the net rotation of a 1R/1R1T period is known.
#[derive(Debug, Clone)]
pub(crate) enum NetRotation {
    /// Written in the spec (degrees), with where.
    Given { degrees: f64, at: Location },
    /// Implied by dense samples (unwrapping across the period boundary).
    FromSamples,
}

/// Everything a parser collected.
pub(crate) struct Assembly {
    pub class: MotionClass,
    pub name: String,
    pub file: Option<PathBuf>,
    pub keys: Vec<RawKey>,
    pub net: NetRotation,
    pub scheme: AngleScheme,
    pub warnings: Vec<MotionWarning>,
    /// Location used for whole-motion errors (too few keys...).
    pub list_at: Location,
}

/// Check a number is finite.
pub(crate) fn finite(value: f64, at: impl FnOnce() -> Location) -> Result<f64, MotionError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(MotionError::NonFinite { at: at(), value })
    }
}

/// Check an angle in degrees is finite and within [`MAX_ABS_ANGLE_DEG`].
pub(crate) fn angle_deg(value: f64, at: impl Fn() -> Location) -> Result<f64, MotionError> {
    within(
        finite(value, &at)?,
        MAX_ABS_ANGLE_DEG,
        "deg",
        "1000 turns",
        at,
    )
}

/// Check a translation component or height (model units) is finite and within
/// [`MAX_ABS_TRANSLATION`].
pub(crate) fn length(value: f64, at: impl Fn() -> Location) -> Result<f64, MotionError> {
    within(
        finite(value, &at)?,
        MAX_ABS_TRANSLATION,
        "model units",
        "10 m at the default scale for a follower about one unit in size",
        at,
    )
}

fn within(
    value: f64,
    limit: f64,
    unit: &'static str,
    why: &'static str,
    at: impl FnOnce() -> Location,
) -> Result<f64, MotionError> {
    if value.abs() <= limit {
        Ok(value)
    } else {
        Err(MotionError::NotPhysical {
            at: at(),
            value,
            limit,
            unit,
            why,
        })
    }
}

/// A unit quaternion from `[w, x, y, z]`: normalized silently within
/// [`QUATERNION_NORM_SILENT`], with a warning within [`QUATERNION_NORM_TOLERANCE`], an error
/// beyond.
pub(crate) fn unit_quaternion(
    wxyz: [f64; 4],
    at: &dyn Fn() -> Location,
    warnings: &mut Vec<MotionWarning>,
) -> Result<UnitQuaternion<f64>, MotionError> {
    for v in wxyz {
        finite(v, at)?;
    }
    let q = Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    let norm = q.norm();
    let dev = (norm - 1.0).abs();
    if dev > QUATERNION_NORM_TOLERANCE {
        return Err(MotionError::NonUnitQuaternion {
            at: at(),
            norm,
            tolerance: QUATERNION_NORM_TOLERANCE,
        });
    }
    if dev > QUATERNION_NORM_SILENT {
        warnings.push(MotionWarning {
            at: at(),
            kind: WarningKind::QuaternionNormalized { norm },
        });
    }
    Ok(UnitQuaternion::new_normalize(q))
}

/// Angle (radians, in (−π, π]) of a rotation assumed to be about z.
fn z_angle(q: &UnitQuaternion<f64>) -> f64 {
    let a = 2.0 * q.k.atan2(q.w);
    wrap_pi(a)
}

/// Map an angle to (−π, π].
fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

impl Assembly {
    fn at(&self, line: Option<usize>, field: impl Into<String>) -> Location {
        Location::new(self.file.clone(), line, field)
    }

    /// Validate and interpolate.
    pub(crate) fn finish(mut self) -> Result<Motion, MotionError> {
        let class = self.class;
        self.check_times()?;
        self.check_class()?;
        let keys = &self.keys;
        let knots: Vec<f64> = keys.iter().map(|k| k.t).collect();

        let (law, net_turns, angle_scheme, keyframes) = if class.is_planar_rotation() {
            // Unwrap the angles.
            let mut angles: Vec<f64> = Vec::with_capacity(keys.len());
            for (i, k) in keys.iter().enumerate() {
                let a = match (k.angle, angles.last()) {
                    (Some(a), _) => a,
                    (None, None) => z_angle(&k.rotation),
                    (None, Some(&prev)) => {
                        let step = wrap_pi(z_angle(&k.rotation) - prev);
                        if matches!(self.net, NetRotation::FromSamples)
                            && step.abs() > MAX_DENSE_STEP_DEG.to_radians()
                        {
                            return Err(MotionError::Invalid {
                                at: self.at(k.line, format!("{}.rotation", k.field)),
                                message: format!(
                                    "turns {:.2}° about z since the previous row (more than \
                                     {MAX_DENSE_STEP_DEG}°): the samples are too sparse to tell \
                                     which way the follower turns",
                                    step.to_degrees()
                                ),
                            });
                        }
                        prev + step
                    }
                };
                debug_assert!(i == angles.len());
                angles.push(a);
            }
            let turns = match &self.net {
                NetRotation::Given { degrees, at } => {
                    let r = degrees / 360.0;
                    if (r - r.round()).abs() > WHOLE_TURN_TOLERANCE {
                        return Err(MotionError::NotWholeTurns {
                            at: at.clone(),
                            degrees: *degrees,
                        });
                    }
                    r.round()
                }
                NetRotation::FromSamples => {
                    let last = *angles.last().expect("at least one key");
                    let first_raw = z_angle(&keys[0].rotation);
                    let step = wrap_pi(first_raw - last);
                    let k = keys.last().expect("at least one key");
                    if keys.len() > 1 && step.abs() > MAX_DENSE_STEP_DEG.to_radians() {
                        return Err(MotionError::Invalid {
                            at: self.at(k.line, format!("{}.rotation", k.field)),
                            message: format!(
                                "the period closes with a turn of {:.2}° about z back to the \
                                 first row (more than {MAX_DENSE_STEP_DEG}°): too sparse to \
                                 tell which way the follower turns",
                                step.to_degrees()
                            ),
                        });
                    }
                    ((last + step - angles[0]) / std::f64::consts::TAU).round()
                }
            };
            // Dense rows unwrap into angles no key wrote: bound those too.
            for (k, a) in keys.iter().zip(&angles) {
                angle_deg(a.to_degrees(), || {
                    self.at(k.line, format!("{}.rotation (unwrapped angle)", k.field))
                })?;
            }
            let offset = turns * std::f64::consts::TAU;
            if turns == 0.0 && keys.len() < 2 {
                return Err(MotionError::TooFewKeyframes {
                    at: self.list_at.clone(),
                    class,
                    found: keys.len(),
                    needed: 2,
                    why: "an oscillation (net rotation 0) needs two keyframes to move at all",
                });
            }
            let angle = AngleLaw::new(self.scheme, &knots, &angles, offset);
            let height = (class == MotionClass::R1T1).then(|| {
                let hv: Vec<[f64; 1]> = keys.iter().map(|k| [k.translation.z]).collect();
                PeriodicSpline::new(&knots, &hv, 1.0, [0.0])
            });
            let keyframes = keys
                .iter()
                .zip(&angles)
                .map(|(k, &a)| Keyframe {
                    t: k.t,
                    rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
                    translation: Vector3::new(0.0, 0.0, k.translation.z),
                    line: k.line,
                })
                .collect();
            (
                Law::Planar { angle, height },
                turns as i32,
                Some(self.scheme),
                keyframes,
            )
        } else {
            if keys.len() < 3 {
                return Err(MotionError::TooFewKeyframes {
                    at: self.list_at.clone(),
                    class,
                    found: keys.len(),
                    needed: 3,
                    why: "a periodic spline through fewer than three orientations only retraces \
                          one arc back and forth",
                });
            }
            for i in 0..keys.len() {
                let j = (i + 1) % keys.len();
                let step = keys[i].rotation.angle_to(&keys[j].rotation).to_degrees();
                if step > MAX_KEY_STEP_DEG {
                    let k = &keys[j];
                    return Err(MotionError::Invalid {
                        at: self.at(k.line, k.field.clone()),
                        message: format!(
                            "orientation is {step:.1}° away from the previous keyframe{} \
                             (at most {MAX_KEY_STEP_DEG}°: the way round is ambiguous; add a \
                             keyframe in between)",
                            if j == 0 {
                                " (across the period end)"
                            } else {
                                ""
                            }
                        ),
                    });
                }
            }
            let rotations: Vec<_> = keys.iter().map(|k| k.rotation).collect();
            let keyframes = keys
                .iter()
                .map(|k| Keyframe {
                    t: k.t,
                    rotation: k.rotation,
                    translation: Vector3::zeros(),
                    line: k.line,
                })
                .collect();
            (
                Law::Spherical(RotationLaw::new(&knots, &rotations)),
                0,
                None,
                keyframes,
            )
        };

        let mut motion = Motion {
            name: self.name,
            class,
            source: self.file.clone(),
            keyframes,
            warnings: std::mem::take(&mut self.warnings),
            net_turns,
            angle_scheme,
            law,
        };
        scan_for_warnings(&mut motion)?;
        Ok(motion)
    }

    fn check_times(&self) -> Result<(), MotionError> {
        let mut prev: Option<&RawKey> = None;
        for k in &self.keys {
            let at = || self.at(k.line, format!("{}.t", k.field));
            finite(k.t, at)?;
            if !(0.0..1.0).contains(&k.t) {
                return Err(MotionError::TimeOutOfRange { at: at(), t: k.t });
            }
            if let Some(p) = prev {
                if k.t == p.t {
                    return Err(MotionError::DuplicateTime {
                        at: at(),
                        t: k.t,
                        previous_line: p.line.unwrap_or(0),
                    });
                }
                if k.t < p.t {
                    return Err(MotionError::TimeNotIncreasing {
                        at: at(),
                        t: k.t,
                        previous: p.t,
                    });
                }
            }
            prev = Some(k);
        }
        if self.keys.is_empty() {
            let needed = if self.class == MotionClass::R3 { 3 } else { 1 };
            return Err(MotionError::TooFewKeyframes {
                at: self.list_at.clone(),
                class: self.class,
                found: 0,
                needed,
                why: "a motion is defined by its keyframes",
            });
        }
        Ok(())
    }

    fn check_class(&self) -> Result<(), MotionError> {
        let class = self.class;
        for k in &self.keys {
            let tr = k.translation;
            let arr = [tr.x, tr.y, tr.z];
            let at = || self.at(k.line, format!("{}.translation", k.field));
            for c in arr {
                length(c, at)?;
            }
            match class {
                MotionClass::R1 | MotionClass::R3 => {
                    if tr.amax() > TRANSLATION_TOLERANCE {
                        return Err(MotionError::TranslationNotAllowed {
                            at: at(),
                            class,
                            translation: arr,
                            why: "a pure-rotation class: the joint centre stays at the origin",
                        });
                    }
                }
                MotionClass::R1T1 => {
                    if tr.x.abs().max(tr.y.abs()) > TRANSLATION_TOLERANCE {
                        return Err(MotionError::TranslationNotAllowed {
                            at: at(),
                            class,
                            translation: arr,
                            why: "the follower only slides along the z axis",
                        });
                    }
                }
            }
            if class.is_planar_rotation() {
                let tilt = tilt_deg(&k.rotation);
                if tilt > OFF_AXIS_TOLERANCE_DEG {
                    return Err(MotionError::RotationOffAxis {
                        at: self.at(k.line, format!("{}.rotation", k.field)),
                        class,
                        tilt_deg: tilt,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Scan the law at [`WARNING_SCAN_SAMPLES`] points for motions unlikely to be
/// synthesizable; one warning per kind, at its worst sample. A law whose derivatives are
/// not finite (keys that jump a large angle within a tiny time) is an error at the nearest
/// key.
fn scan_for_warnings(motion: &mut Motion) -> Result<(), MotionError> {
    let n = WARNING_SCAN_SAMPLES;
    let mut worst_tilt = (0.0_f64, 0.0);
    let mut worst_acc = (0.0_f64, 0.0);
    let mut worst_lin = (0.0_f64, 0.0);
    let mut not_finite = None;
    for i in 0..n {
        let s = motion.sample(i as f64 / n as f64);
        let derivatives = [
            s.angular_velocity,
            s.angular_acceleration,
            s.velocity,
            s.acceleration,
        ];
        if not_finite.is_none() && derivatives.iter().any(|d| !d.iter().all(|x| x.is_finite())) {
            not_finite = Some(s.t);
        }
        if motion.class == MotionClass::R3 {
            let tilt = tilt_deg(&s.rotation);
            if tilt > worst_tilt.0 {
                worst_tilt = (tilt, s.t);
            }
        }
        let acc = s.angular_acceleration.norm();
        if acc > worst_acc.0 {
            worst_acc = (acc, s.t);
        }
        let lin = s.acceleration.norm();
        if lin > worst_lin.0 {
            worst_lin = (lin, s.t);
        }
    }
    let at = |t: f64| {
        // The keyframe nearest in time (cyclically) points the user at the right place.
        let nearest = motion.keyframes.iter().min_by(|a, b| {
            let d = |k: &Keyframe| {
                let d = (k.t - t).rem_euclid(1.0);
                d.min(1.0 - d)
            };
            d(a).total_cmp(&d(b))
        });
        Location::new(
            motion.source.clone(),
            nearest.and_then(|k| k.line),
            "motion (interpolated)",
        )
    };
    if let Some(t) = not_finite {
        return Err(MotionError::Invalid {
            at: at(t),
            message: format!(
                "the interpolated motion's velocity or acceleration is not finite near t = {t:.4}: \
                 keyframes too close in time for the motion between them"
            ),
        });
    }
    let mut found = Vec::new();
    if worst_tilt.0 > MAX_TILT_DEG {
        found.push(MotionWarning {
            at: at(worst_tilt.1),
            kind: WarningKind::LargeTilt {
                tilt_deg: worst_tilt.0,
                t: worst_tilt.1,
            },
        });
    }
    if worst_acc.0 > MAX_ANGULAR_ACCELERATION {
        found.push(MotionWarning {
            at: at(worst_acc.1),
            kind: WarningKind::LargeAngularAcceleration {
                value: worst_acc.0,
                t: worst_acc.1,
            },
        });
    }
    if worst_lin.0 > MAX_LINEAR_ACCELERATION {
        found.push(MotionWarning {
            at: at(worst_lin.1),
            kind: WarningKind::LargeAcceleration {
                value: worst_lin.0,
                t: worst_lin.1,
            },
        });
    }
    motion.warnings.extend(found);
    Ok(())
}
