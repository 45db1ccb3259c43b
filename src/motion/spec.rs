//! The TOML keyframe format.
//!
//! ```toml
//! name = "half-turn-2to1"        # optional; default: the file name without extension
//! class = "1R"                   # "1R", "1R1T" or "3R"
//! description = "..."            # optional free text (provenance, assumptions)
//! net_rotation = 360.0           # 1R/1R1T: degrees per period, a multiple of 360 (default 0)
//! angle_interpolation = "monotone"   # 1R/1R1T: "monotone" (default) or "spline"
//!
//! [[key]]                        # one table per keyframe, times increasing in [0, 1)
//! t = 0.0
//! angle = 0.0                    # 1R/1R1T: degrees about +z (unwrapped: 540 is 1.5 turns)
//! height = 0.0                   # 1R1T: position along z in model units
//! ```
//!
//! A key's orientation may be written in exactly one of these forms:
//! - `angle = θ` (1R/1R1T only): degrees about +z;
//! - `quaternion = [w, x, y, z]`: unit, scalar first (normalized with a warning within
//!   [`super::QUATERNION_NORM_TOLERANCE`], an error beyond);
//! - `axis = [x, y, z]` with `angle = θ`: θ degrees about the axis (any non-zero length);
//! - `euler_zyx = [z, y, x]`: intrinsic yaw–pitch–roll in degrees, R = Rz·Ry·Rx;
//! - `azimuth = a`, `elevation = e`, optional `roll = r` (3R): the direction of the
//!   end-effector axis (follower-local +z; rest is straight up, elevation 90°) and a roll
//!   about it — "a path on a sphere plus roll". R = T·Rz(r) where the swing
//!   T = Rz(a)·Ry(90° − e)·Rz(−a) tips the axis the shortest way from rest, so circling
//!   the rest direction does not spin the follower, and at rest (e = 90°) a is irrelevant.
//!
//! In 1R/1R1T every form must be a rotation about z; angles from non-`angle` forms are
//! unwrapped to the branch nearest the previous key. `translation = [x, y, z]` is accepted
//! for completeness and validated against the class (1R1T: along z only, same as `height`).
//!
//! **Timing-only keys (1R).** Instead of `[[key]]` tables a 1R motion may give the time
//! each stretch of rotation takes:
//!
//! ```toml
//! [timing]
//! start_angle = 0.0              # degrees at t = 0 (default 0)
//! segments = [ { angle = 180.0, duration = 2.0 }, { angle = 180.0, duration = 1.0 } ]
//! ```
//!
//! Durations are relative weights (normalized to one period); the angles must add up to a
//! whole number of turns, which becomes the net rotation. The example above is the paper's
//! "first half-turn takes twice as long as the second".

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;
use toml::Spanned;

use super::angle::AngleScheme;
use super::build::{angle_deg, finite, length, unit_quaternion, Assembly, NetRotation, RawKey};
use super::rotation::{from_axis_angle_deg, from_direction_roll_deg, from_euler_zyx_deg};
use super::{Location, Motion, MotionClass, MotionError, MotionWarning, MAX_SPEC_BYTES};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SpecFile {
    name: Option<Spanned<String>>,
    class: Spanned<String>,
    #[allow(dead_code)]
    description: Option<String>,
    net_rotation: Option<Spanned<f64>>,
    angle_interpolation: Option<Spanned<String>>,
    #[serde(default)]
    key: Vec<KeySpec>,
    timing: Option<Spanned<TimingSpec>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct KeySpec {
    t: Spanned<f64>,
    angle: Option<Spanned<f64>>,
    height: Option<Spanned<f64>>,
    translation: Option<Spanned<Vec<f64>>>,
    quaternion: Option<Spanned<Vec<f64>>>,
    axis: Option<Spanned<Vec<f64>>>,
    euler_zyx: Option<Spanned<Vec<f64>>>,
    azimuth: Option<Spanned<f64>>,
    elevation: Option<Spanned<f64>>,
    roll: Option<Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TimingSpec {
    start_angle: Option<Spanned<f64>>,
    segments: Spanned<Vec<Spanned<SegmentSpec>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentSpec {
    angle: Spanned<f64>,
    duration: Spanned<f64>,
}

/// Line numbers from byte offsets: the offsets of every line start, found once, so each
/// lookup is a binary search (counting newlines from the start for every key made parsing
/// quadratic: 40 000 keys took 22 s).
struct Lines {
    starts: Vec<usize>,
}

impl Lines {
    fn new(text: &str) -> Lines {
        let mut starts = vec![0];
        starts.extend(
            text.bytes()
                .enumerate()
                .filter(|&(_, b)| b == b'\n')
                .map(|(i, _)| i + 1),
        );
        Lines { starts }
    }

    /// 1-based line of a byte offset.
    fn line(&self, offset: usize) -> usize {
        self.starts.partition_point(|&s| s <= offset)
    }
}

/// Parse and validate a keyframe spec. `path` names the file in messages and supplies the
/// default name.
pub fn parse_spec(text: &str, path: Option<&Path>) -> Result<Motion, MotionError> {
    let file = path.map(Path::to_path_buf);
    if text.len() > MAX_SPEC_BYTES {
        return Err(MotionError::Invalid {
            at: Location::new(file, None, ""),
            message: format!(
                "{} bytes is more than a keyframe spec may hold ({MAX_SPEC_BYTES} bytes, over \
                 100 000 keys); write data this dense as a .csv dense file (data/README.md)",
                text.len()
            ),
        });
    }
    let lines = Lines::new(text);
    let at = |span: std::ops::Range<usize>, field: &str| {
        Location::new(file.clone(), Some(lines.line(span.start)), field)
    };
    let spec: SpecFile = toml::from_str(text).map_err(|e| MotionError::Syntax {
        at: Location::new(file.clone(), e.span().map(|s| lines.line(s.start)), ""),
        message: e.message().trim().to_string(),
    })?;

    let class: MotionClass =
        spec.class
            .get_ref()
            .parse()
            .map_err(|_| MotionError::UnknownClass {
                at: at(spec.class.span(), "class"),
                found: spec.class.get_ref().clone(),
            })?;
    let name = match &spec.name {
        Some(n) if n.get_ref().trim().is_empty() => {
            return Err(MotionError::Invalid {
                at: at(n.span(), "name"),
                message: "name is empty".into(),
            })
        }
        Some(n) => n.get_ref().trim().to_string(),
        None => path
            .and_then(Path::file_stem)
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "motion".to_string()),
    };
    let scheme = match &spec.angle_interpolation {
        None => AngleScheme::Monotone,
        Some(s) => {
            if !class.is_planar_rotation() {
                return Err(MotionError::Invalid {
                    at: at(s.span(), "angle_interpolation"),
                    message: format!(
                        "angle_interpolation applies to 1R and 1R1T only, not {class}"
                    ),
                });
            }
            match s.get_ref().as_str() {
                "monotone" => AngleScheme::Monotone,
                "spline" => AngleScheme::Spline,
                other => {
                    return Err(MotionError::Invalid {
                        at: at(s.span(), "angle_interpolation"),
                        message: format!(
                            "unknown scheme {other:?} (expected \"monotone\" or \"spline\")"
                        ),
                    })
                }
            }
        }
    };
    if let (Some(net), false) = (&spec.net_rotation, class.is_planar_rotation()) {
        return Err(MotionError::Invalid {
            at: at(net.span(), "net_rotation"),
            message: format!("net_rotation applies to 1R and 1R1T only, not {class}"),
        });
    }

    let mut warnings: Vec<MotionWarning> = Vec::new();
    let (keys, net) = match (&spec.timing, spec.key.is_empty()) {
        (Some(timing), true) => timing_keys(timing, &spec, class, &at)?,
        (Some(timing), false) => {
            return Err(MotionError::Invalid {
                at: at(timing.span(), "timing"),
                message: "give either [[key]] tables or a [timing] table, not both".into(),
            })
        }
        (None, _) => {
            let keys = spec
                .key
                .iter()
                .enumerate()
                .map(|(i, k)| key(k, i, class, &at, &mut warnings))
                .collect::<Result<Vec<_>, _>>()?;
            let net = match &spec.net_rotation {
                Some(n) => NetRotation::Given {
                    degrees: angle_deg(*n.get_ref(), || at(n.span(), "net_rotation"))?,
                    at: at(n.span(), "net_rotation"),
                },
                None => NetRotation::Given {
                    degrees: 0.0,
                    at: at(spec.class.span(), "net_rotation"),
                },
            };
            (keys, net)
        }
    };

    Assembly {
        class,
        name,
        file: file.clone(),
        keys,
        net,
        scheme,
        warnings,
        list_at: Location::new(file.clone(), None, "key"),
    }
    .finish()
}

type At<'a> = dyn Fn(std::ops::Range<usize>, &str) -> Location + 'a;

/// A bound on one number of a field: finite, or finite and physical (angles, lengths).
type Check = dyn Fn(f64, &dyn Fn() -> Location) -> Result<f64, MotionError>;

/// Keys from a `[timing]` table.
fn timing_keys(
    timing: &Spanned<TimingSpec>,
    spec: &SpecFile,
    class: MotionClass,
    at: &At<'_>,
) -> Result<(Vec<RawKey>, NetRotation), MotionError> {
    let tspan = timing.span();
    if class != MotionClass::R1 {
        return Err(MotionError::Invalid {
            at: at(tspan, "timing"),
            message: format!("timing-only keys are for 1R motions, not {class}"),
        });
    }
    let timing = timing.get_ref();
    let start = match &timing.start_angle {
        Some(s) => angle_deg(*s.get_ref(), || at(s.span(), "timing.start_angle"))?,
        None => 0.0,
    };
    let segs = timing.segments.get_ref();
    if segs.is_empty() {
        return Err(MotionError::TooFewKeyframes {
            at: at(timing.segments.span(), "timing.segments"),
            class,
            found: 0,
            needed: 1,
            why: "timing needs at least one segment",
        });
    }
    let mut total_duration = 0.0;
    let mut total_angle = 0.0;
    for (i, s) in segs.iter().enumerate() {
        let seg = s.get_ref();
        let d = finite(*seg.duration.get_ref(), || {
            at(
                seg.duration.span(),
                &format!("timing.segments[{i}].duration"),
            )
        })?;
        let a = angle_deg(*seg.angle.get_ref(), || {
            at(seg.angle.span(), &format!("timing.segments[{i}].angle"))
        })?;
        if d <= 0.0 {
            return Err(MotionError::Invalid {
                at: at(
                    seg.duration.span(),
                    &format!("timing.segments[{i}].duration"),
                ),
                message: format!("duration {d} must be positive (a relative share of the period)"),
            });
        }
        total_duration += d;
        total_angle += a;
    }
    let net_at = at(timing.segments.span(), "timing.segments");
    if let Some(n) = &spec.net_rotation {
        if (n.get_ref() - total_angle).abs() > 1e-9 * total_angle.abs().max(1.0) {
            return Err(MotionError::Invalid {
                at: at(n.span(), "net_rotation"),
                message: format!(
                    "net_rotation {} disagrees with the timing segments, which add up to {total_angle}°",
                    n.get_ref()
                ),
            });
        }
    }
    let mut keys = Vec::with_capacity(segs.len());
    let (mut t, mut angle) = (0.0, start);
    for (i, s) in segs.iter().enumerate() {
        let seg = s.get_ref();
        keys.push(RawKey {
            t,
            rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle.to_radians()),
            translation: Vector3::zeros(),
            angle: Some(angle.to_radians()),
            line: Some(at(s.span(), "").line.unwrap_or(0)),
            field: format!("timing.segments[{i}]"),
        });
        t += seg.duration.get_ref() / total_duration;
        angle += seg.angle.get_ref();
    }
    Ok((
        keys,
        NetRotation::Given {
            degrees: total_angle,
            at: net_at,
        },
    ))
}

/// One `[[key]]` table.
fn key(
    k: &KeySpec,
    index: usize,
    class: MotionClass,
    at: &At<'_>,
    warnings: &mut Vec<MotionWarning>,
) -> Result<RawKey, MotionError> {
    let prefix = format!("key[{index}]");
    let f = |name: &str| format!("{prefix}.{name}");
    let num = |v: &Spanned<f64>, name: &str| finite(*v.get_ref(), || at(v.span(), &f(name)));
    let angle = |v: &Spanned<f64>, name: &str| angle_deg(*v.get_ref(), || at(v.span(), &f(name)));
    // `check` bounds each component (finite, and physical for angles and lengths).
    let vec_n = |v: &Spanned<Vec<f64>>,
                 name: &str,
                 n: usize,
                 check: &Check|
     -> Result<Vec<f64>, MotionError> {
        if v.get_ref().len() != n {
            return Err(MotionError::Invalid {
                at: at(v.span(), &f(name)),
                message: format!("expected {n} numbers, found {}", v.get_ref().len()),
            });
        }
        for &x in v.get_ref() {
            check(x, &|| at(v.span(), &f(name)))?;
        }
        Ok(v.get_ref().clone())
    };
    let any = |x: f64, at: &dyn Fn() -> Location| finite(x, at);
    let angles = |x: f64, at: &dyn Fn() -> Location| angle_deg(x, at);
    let lengths = |x: f64, at: &dyn Fn() -> Location| length(x, at);
    let t = num(&k.t, "t")?;
    let line = Some(at(k.t.span(), "").line.unwrap_or(0));

    // Which orientation forms are present.
    let forms: Vec<&str> = [
        (k.quaternion.is_some(), "quaternion"),
        (k.axis.is_some(), "axis"),
        (k.euler_zyx.is_some(), "euler_zyx"),
        (
            k.azimuth.is_some() || k.elevation.is_some() || k.roll.is_some(),
            "azimuth/elevation",
        ),
    ]
    .iter()
    .filter(|(present, _)| *present)
    .map(|(_, n)| *n)
    .collect();
    let first_span = || k.t.span();
    if forms.len() > 1 {
        return Err(MotionError::Invalid {
            at: at(first_span(), &prefix),
            message: format!(
                "orientation given in several forms ({}); use exactly one",
                forms.join(", ")
            ),
        });
    }
    if let (Some(a), false) = (&k.angle, forms.is_empty() || forms == ["axis"]) {
        return Err(MotionError::Invalid {
            at: at(a.span(), &f("angle")),
            message: format!(
                "`angle` cannot be combined with `{}` (it is the angle about +z, or about `axis`)",
                forms[0]
            ),
        });
    }

    let mut explicit_angle = None;
    let rotation = match forms.first().copied() {
        None => match &k.angle {
            Some(a) if class.is_planar_rotation() => {
                let deg = angle(a, "angle")?;
                explicit_angle = Some(deg.to_radians());
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians())
            }
            Some(a) => {
                return Err(MotionError::Invalid {
                    at: at(a.span(), &f("angle")),
                    message: "a 3R keyframe's `angle` needs an `axis` (or use quaternion, \
                              euler_zyx or azimuth/elevation)"
                        .into(),
                })
            }
            None => {
                return Err(MotionError::Invalid {
                    at: at(first_span(), &prefix),
                    message: if class.is_planar_rotation() {
                        "missing `angle` (degrees about +z)".into()
                    } else {
                        "missing orientation: give `quaternion`, `axis` + `angle`, `euler_zyx` \
                         or `azimuth` + `elevation` (+ `roll`)"
                            .into()
                    },
                })
            }
        },
        Some("quaternion") => {
            let q = k.quaternion.as_ref().expect("present");
            let v = vec_n(q, "quaternion", 4, &any)?;
            unit_quaternion(
                [v[0], v[1], v[2], v[3]],
                &|| at(q.span(), &f("quaternion")),
                warnings,
            )?
        }
        Some("axis") => {
            let ax = k.axis.as_ref().expect("present");
            let v = vec_n(ax, "axis", 3, &any)?;
            let Some(a) = &k.angle else {
                return Err(MotionError::Invalid {
                    at: at(ax.span(), &f("axis")),
                    message: "`axis` needs an `angle` (degrees)".into(),
                });
            };
            let deg = angle(a, "angle")?;
            let q = from_axis_angle_deg([v[0], v[1], v[2]], deg).ok_or_else(|| {
                MotionError::Invalid {
                    at: at(ax.span(), &f("axis")),
                    message: "axis has zero length".into(),
                }
            })?;
            // An axis along ±z keeps the angle unwrapped.
            let n = Vector3::new(v[0], v[1], v[2]).normalize();
            if class.is_planar_rotation() && n.x.abs().max(n.y.abs()) < 1e-12 {
                explicit_angle = Some(deg.to_radians() * n.z.signum());
            }
            q
        }
        Some("euler_zyx") => {
            let e = k.euler_zyx.as_ref().expect("present");
            let v = vec_n(e, "euler_zyx", 3, &angles)?;
            from_euler_zyx_deg(v[0], v[1], v[2])
        }
        Some(_) => {
            let span = k
                .azimuth
                .as_ref()
                .or(k.elevation.as_ref())
                .or(k.roll.as_ref())
                .expect("present")
                .span();
            let (Some(az), Some(el)) = (&k.azimuth, &k.elevation) else {
                return Err(MotionError::Invalid {
                    at: at(span, &prefix),
                    message: "the direction form needs both `azimuth` and `elevation` \
                              (degrees; `roll` is optional)"
                        .into(),
                });
            };
            let roll = match &k.roll {
                Some(r) => angle(r, "roll")?,
                None => 0.0,
            };
            from_direction_roll_deg(angle(az, "azimuth")?, angle(el, "elevation")?, roll)
        }
    };

    let mut translation = Vector3::zeros();
    let mut translation_line = line;
    if let Some(tr) = &k.translation {
        let v = vec_n(tr, "translation", 3, &lengths)?;
        translation = Vector3::new(v[0], v[1], v[2]);
        translation_line = at(tr.span(), "").line;
    }
    if let Some(h) = &k.height {
        if class != MotionClass::R1T1 {
            return Err(MotionError::TranslationNotAllowed {
                at: at(h.span(), &f("height")),
                class,
                translation: [0.0, 0.0, *h.get_ref()],
                why: "`height` belongs to 1R1T motions; this class does not translate",
            });
        }
        if k.translation.is_some() {
            return Err(MotionError::Invalid {
                at: at(h.span(), &f("height")),
                message: "give `height` or `translation`, not both".into(),
            });
        }
        translation.z = length(*h.get_ref(), || at(h.span(), &f("height")))?;
    } else if class == MotionClass::R1T1 && k.translation.is_none() {
        return Err(MotionError::Invalid {
            at: at(first_span(), &prefix),
            message: "missing `height` (position along z) for a 1R1T keyframe".into(),
        });
    }
    // Translation errors are reported at the translation's own line.
    let line = if translation != Vector3::zeros() && k.height.is_none() {
        translation_line
    } else {
        line
    };
    Ok(RawKey {
        t,
        rotation,
        translation,
        angle: explicit_angle,
        line,
        field: prefix,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the line index: every byte offset (and one past the end) maps to the line
    /// that counting newlines before it gives.
    #[test]
    fn line_index_matches_counting_newlines() {
        let text = "a = 1\n\n[[key]]\nt = 0.5\nangle = 3\n";
        let lines = Lines::new(text);
        for offset in 0..=text.len() + 1 {
            let counted = 1 + text.as_bytes()[..offset.min(text.len())]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
            assert_eq!(lines.line(offset), counted, "offset {offset}");
        }
    }

    fn parse(text: &str) -> Result<Motion, MotionError> {
        parse_spec(text, Some(Path::new("test.toml")))
    }

    /// Guards the timing-only form: the paper's 2:1 half-turn becomes keys at t = 0 and 2/3
    /// with one net turn, and the follower is at 180° exactly at t = 2/3.
    #[test]
    fn timing_form_gives_two_to_one_half_turns() {
        let m = parse(
            "class = \"1R\"\n[timing]\nsegments = [ { angle = 180.0, duration = 2.0 }, \
             { angle = 180.0, duration = 1.0 } ]\n",
        )
        .unwrap();
        assert_eq!(m.net_turns(), 1);
        assert_eq!(m.keyframes().len(), 2);
        let a = m.angle_z(2.0 / 3.0).unwrap()[0];
        assert!((a - std::f64::consts::PI).abs() < 1e-12);
        assert_eq!(m.name(), "test");
    }

    /// Guards the 3R forms: the same orientation written as quaternion, axis-angle, ZYX
    /// Euler angles and direction + roll gives the same keyframe rotation.
    #[test]
    fn orientation_forms_agree() {
        let q = from_euler_zyx_deg(20.0, 30.0, 0.0);
        let (axis, angle) = q.axis_angle().unwrap();
        let a = from_direction_roll_deg(20.0, 90.0 - 30.0, -20.0);
        // The axis tilted 30° towards azimuth 20°, rolled −20° about itself.
        let forms = [
            format!("quaternion = [{}, {}, {}, {}]", a.w, a.i, a.j, a.k),
            format!(
                "axis = [{}, {}, {}]\nangle = {}",
                a.axis().unwrap().x,
                a.axis().unwrap().y,
                a.axis().unwrap().z,
                a.angle().to_degrees()
            ),
            "azimuth = 20.0\nelevation = 60.0\nroll = -20.0".to_string(),
        ];
        let _ = (axis, angle);
        for form in forms {
            let text = format!(
                "class = \"3R\"\n[[key]]\nt = 0.0\n{form}\n[[key]]\nt = 0.3\nquaternion = [1,0,0,0]\n\
                 [[key]]\nt = 0.6\neuler_zyx = [0, 10, 0]\n"
            );
            let m = parse(&text).unwrap();
            assert!(m.keyframes()[0].rotation.angle_to(&a) < 1e-9, "{form}");
        }
    }
}
