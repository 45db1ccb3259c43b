//! The pictures of a motion (`mpc-rig motion show`), drawn through [`crate::plot`].
//!
//! - every class: angular velocity and acceleration over t;
//! - 1R/1R1T: the unwrapped angle θ(t) with the keyframes marked; 1R1T also the height;
//! - 3R: ZYX Euler angles over t (for reading only: the law itself is interpolated on
//!   SO(3)), tilt of the end-effector axis and roll about it over t, and the path of the end-effector axis (follower-local +z) in an azimuthal
//!   equidistant projection around its rest direction, with keyframes, the start and the
//!   [`super::MAX_TILT_DEG`] circle.
//!
//! This module decides what to plot; [`crate::plot`] owns how charts look.

use std::path::{Path, PathBuf};

use crate::plot::{Chart, PlotError, Series};

use super::rotation::{end_effector_axis, roll_deg, tilt_deg};
use super::{BenchScale, Motion, MotionClass};

/// Unwrap a sequence of angles in degrees (remove ±360° jumps).
fn unwrap_deg(values: &mut [f64]) {
    for i in 1..values.len() {
        let d = values[i] - values[i - 1];
        values[i] -= 360.0 * (d / 360.0).round();
    }
}

/// Build the charts for `motion` sampled at `n` points (plus the closing point t = 1).
/// Heights are drawn in millimetres and rates per second, read at `scale` (issue 20: a
/// person at the bench reads mm and seconds); t stays the fraction of the period that the
/// keyframes are written in, its axis saying how long a period is at that speed.
pub fn charts(motion: &Motion, n: usize, scale: &BenchScale) -> Vec<(String, Chart)> {
    let n = n.max(8);
    let ts: Vec<f64> = (0..=n).map(|i| i as f64 / n as f64).collect();
    let s = Sampled {
        motion,
        scale,
        n,
        samples: ts.iter().map(|&t| motion.sample(t)).collect(),
        ts,
        name: motion.name(),
        t_label: format!(
            "t [fraction of the period; 1 = {} s at {}]",
            super::units::trim(scale.period_s(), 3),
            scale.speed_text()
        ),
        mm_label: format!(
            "mm = model units × {}",
            super::units::trim(scale.scale_mm, 3)
        ),
        speed: scale.speed_text(),
    };
    let mut out = match motion.class() {
        MotionClass::R1 | MotionClass::R1T1 => about_z_charts(&s),
        MotionClass::R3 => orientation_charts(&s),
    };
    out.extend(rate_charts(&s));
    out
}

/// A motion sampled for its charts, with the labels every chart shares.
struct Sampled<'a> {
    motion: &'a Motion,
    scale: &'a BenchScale,
    n: usize,
    ts: Vec<f64>,
    samples: Vec<super::PoseSample>,
    name: &'a str,
    t_label: String,
    mm_label: String,
    speed: String,
}

/// 1R and 1R1T: the angle about z with its keyframes; 1R1T also the height and its rates.
fn about_z_charts(s: &Sampled) -> Vec<(String, Chart)> {
    let Sampled {
        motion,
        scale,
        ref ts,
        ref samples,
        name,
        ref t_label,
        ref mm_label,
        ref speed,
        ..
    } = *s;
    let t_label = t_label.as_str();
    let xr = Some((0.0, 1.0));
    let mut out = Vec::new();
    let angle = |t: f64| motion.angle_z(t).map_or(0.0, |a| a[0]).to_degrees();
    let mut c = Chart::new(
        format!(
            "{name}: rotation about z ({} turn(s) per period)",
            motion.net_turns()
        ),
        t_label,
        "θ [deg]",
    )
    .with(Series::line(
        "θ(t)",
        ts.iter().map(|&t| (t, angle(t))).collect(),
        0,
    ))
    .with(Series::points(
        "keyframes",
        motion
            .key_poses()
            .iter()
            .map(|k| (k.t, angle(k.t)))
            .collect(),
        5,
        1,
    ));
    c.x_range = xr;
    out.push(("angle".to_string(), c));
    if motion.class() == MotionClass::R1T1 {
        let h = |t: f64| scale.mm(motion.height(t).map_or(0.0, |h| h[0]));
        let mut c = Chart::new(
            format!("{name}: height along z"),
            t_label,
            format!("h [{mm_label}]"),
        )
        .with(Series::line(
            "h(t)",
            ts.iter().map(|&t| (t, h(t))).collect(),
            2,
        ))
        .with(Series::points(
            "keyframes",
            motion.key_poses().iter().map(|k| (k.t, h(k.t))).collect(),
            5,
            1,
        ));
        c.x_range = xr;
        out.push(("height".to_string(), c));
        // One chart per unit (issue 20: velocity and acceleration shared an axis,
        // so the acceleration's larger numbers flattened the velocity).
        let mut c = Chart::new(
            format!("{name}: vertical velocity"),
            t_label,
            format!("dh/dt [mm/s at {speed}]"),
        )
        .with(Series::line(
            "dh/dt",
            samples
                .iter()
                .map(|s| (s.t, scale.per_s(scale.mm(s.velocity.z))))
                .collect(),
            0,
        ));
        c.x_range = xr;
        out.push(("height-velocity".to_string(), c));
        let mut c = Chart::new(
            format!("{name}: vertical acceleration"),
            t_label,
            format!("d²h/dt² [mm/s² at {speed}]"),
        )
        .with(Series::line(
            "d²h/dt²",
            samples
                .iter()
                .map(|s| (s.t, scale.per_s2(scale.mm(s.acceleration.z))))
                .collect(),
            1,
        ));
        c.x_range = xr;
        out.push(("height-acceleration".to_string(), c));
    }
    out
}

/// 3R: Euler angles, the end-effector axis's tilt and roll, and its path seen from above.
fn orientation_charts(s: &Sampled) -> Vec<(String, Chart)> {
    let Sampled {
        motion,
        n,
        ref ts,
        ref samples,
        name,
        ref t_label,
        ..
    } = *s;
    let t_label = t_label.as_str();
    let xr = Some((0.0, 1.0));
    let mut out = Vec::new();
    // Euler angles for reading.
    let mut e: [Vec<f64>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for s in samples {
        let (roll, pitch, yaw) = s.rotation.euler_angles();
        e[0].push(yaw.to_degrees());
        e[1].push(pitch.to_degrees());
        e[2].push(roll.to_degrees());
    }
    for v in &mut e {
        unwrap_deg(v);
    }
    let mut c = Chart::new(
        format!("{name}: orientation as ZYX Euler angles (interpolated on SO(3))"),
        t_label,
        "angle [deg]",
    );
    for (k, label) in ["yaw (z)", "pitch (y)", "roll (x)"].iter().enumerate() {
        c.series.push(Series::line(
            *label,
            ts.iter().zip(&e[k]).map(|(&t, &v)| (t, v)).collect(),
            k,
        ));
    }
    // Keyframes: mark on each curve at its sample nearest in value continuity.
    let key_points = |k: usize| -> Vec<(f64, f64)> {
        motion
            .key_poses()
            .iter()
            .map(|kf| {
                let i = ((kf.t * n as f64).round() as usize).min(n);
                let (roll, pitch, yaw) = kf.rotation.euler_angles();
                let raw = [yaw, pitch, roll][k].to_degrees();
                // Same branch as the unwrapped curve near that time.
                let v = raw - 360.0 * ((raw - e[k][i]) / 360.0).round();
                (kf.t, v)
            })
            .collect()
    };
    for k in 0..3 {
        c.series.push(Series::points(
            if k == 0 { "keyframes" } else { "" },
            key_points(k),
            5,
            6,
        ));
    }
    c.x_range = xr;
    out.push(("euler".to_string(), c));

    // The direction form's own terms: tilt of the axis and roll about it.
    let mut roll: Vec<f64> = samples.iter().map(|s| roll_deg(&s.rotation)).collect();
    unwrap_deg(&mut roll);
    let mut c = Chart::new(
        format!("{name}: end-effector axis tilt and roll about it"),
        t_label,
        "angle [deg]",
    )
    .with(Series::line(
        "tilt from rest",
        samples
            .iter()
            .map(|s| (s.t, tilt_deg(&s.rotation)))
            .collect(),
        0,
    ))
    .with(Series::line(
        "roll",
        ts.iter().zip(&roll).map(|(&t, &r)| (t, r)).collect(),
        1,
    ))
    .with(Series::points(
        "keyframes",
        motion
            .key_poses()
            .iter()
            .flat_map(|k| {
                let i = ((k.t * n as f64).round() as usize).min(n);
                let r = roll_deg(&k.rotation);
                [
                    (k.t, tilt_deg(&k.rotation)),
                    (k.t, r - 360.0 * ((r - roll[i]) / 360.0).round()),
                ]
            })
            .collect(),
        5,
        6,
    ));
    c.h_lines.push((super::MAX_TILT_DEG, "tilt warning".into()));
    c.x_range = xr;
    out.push(("tilt-roll".to_string(), c));

    // End-effector axis path.
    let project = |q: &nalgebra::UnitQuaternion<f64>| {
        let a = q * end_effector_axis();
        let tilt = a.z.clamp(-1.0, 1.0).acos().to_degrees();
        let az = a.y.atan2(a.x);
        (tilt * az.cos(), tilt * az.sin())
    };
    let circle: Vec<(f64, f64)> = (0..=180)
        .map(|i| {
            let a = f64::from(i) / 180.0 * std::f64::consts::TAU;
            (super::MAX_TILT_DEG * a.cos(), super::MAX_TILT_DEG * a.sin())
        })
        .collect();
    let mut c = Chart::new(
        format!("{name}: end-effector axis (follower +z), seen from above"),
        "tilt towards +x [deg]",
        "tilt towards +y [deg]",
    )
    .with(Series::dashed(
        format!("{}° tilt", super::MAX_TILT_DEG),
        circle,
        6,
    ))
    .with(Series::line(
        "axis path",
        samples.iter().map(|s| project(&s.rotation)).collect(),
        0,
    ))
    .with(Series::points(
        "keyframes",
        motion
            .key_poses()
            .iter()
            .map(|k| project(&k.rotation))
            .collect(),
        5,
        1,
    ))
    .with(Series::points(
        "t = 0",
        vec![project(&samples[0].rotation)],
        8,
        2,
    ));
    c.equal_aspect = true;
    c.size = (900, 900);
    out.push(("axis-path".to_string(), c));
    out
}

/// Angular velocity and acceleration, every class, per second at the bench speed.
fn rate_charts(s: &Sampled) -> Vec<(String, Chart)> {
    let Sampled {
        motion,
        scale,
        ref samples,
        name,
        ref t_label,
        ref speed,
        ..
    } = *s;
    let t_label = t_label.as_str();
    let xr = Some((0.0, 1.0));
    let mut out = Vec::new();
    // Rates, all classes, in degrees per second at the bench speed.
    let comps = |f: &dyn Fn(&super::PoseSample) -> nalgebra::Vector3<f64>| -> [Vec<(f64, f64)>; 3] {
        let mut r: [Vec<(f64, f64)>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        for s in samples {
            let v = f(s);
            for k in 0..3 {
                r[k].push((s.t, v[k].to_degrees()));
            }
        }
        r
    };
    for (stem, title, unit, f) in [
        (
            "angular-velocity",
            "angular velocity ω (frame R)",
            format!("ω [°/s at {speed}]"),
            (&|s: &super::PoseSample| scale.per_s(1.0) * s.angular_velocity)
                as &dyn Fn(&super::PoseSample) -> _,
        ),
        (
            "angular-acceleration",
            "angular acceleration dω/dt (frame R)",
            format!("dω/dt [°/s² at {speed}]"),
            &|s: &super::PoseSample| scale.per_s2(1.0) * s.angular_acceleration,
        ),
    ] {
        let [x, y, z] = comps(f);
        let mut c = Chart::new(format!("{name}: {title}"), t_label, unit);
        if motion.class() == MotionClass::R3 {
            c.series.push(Series::line("x", x, 0));
            c.series.push(Series::line("y", y, 1));
        }
        c.series.push(Series::line("z", z, 2));
        c.x_range = xr;
        out.push((stem.to_string(), c));
    }
    out
}

/// Write every chart of `motion`, read at `scale`, as `<dir>/<name>-<chart>.png` and
/// `.svg`; returns the files written.
pub fn write_all(
    motion: &Motion,
    dir: &Path,
    n: usize,
    scale: &BenchScale,
) -> Result<Vec<PathBuf>, FigureError> {
    std::fs::create_dir_all(dir).map_err(|source| FigureError::Dir {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    for (stem, chart) in charts(motion, n, scale) {
        let [png, svg] = chart.write(&dir.join(format!("{}-{stem}", motion.name())))?;
        written.push(png);
        written.push(svg);
    }
    Ok(written)
}

/// Why the figures could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// The output directory could not be created.
    #[error("cannot create output directory {path}")]
    Dir {
        /// The directory.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::spec::parse_spec;

    /// Guards `motion show`'s output: each class gets its charts (3R: Euler angles, tilt and
    /// roll, axis path, rates), all written as PNG and SVG.
    #[test]
    fn writes_the_charts_of_each_class() {
        let dir = tempfile::tempdir().unwrap();
        let cases = [
            (
                "class = \"1R\"\nnet_rotation = 360\n[[key]]\nt = 0.0\nangle = 0.0\n",
                3,
            ),
            (
                "class = \"1R1T\"\n[[key]]\nt = 0.0\nangle = 0.0\nheight = 0.0\n\
                 [[key]]\nt = 0.5\nangle = 30.0\nheight = 1.0\n",
                // angle, its two rates, height, its velocity and its acceleration.
                6,
            ),
            (
                "class = \"3R\"\n[[key]]\nt = 0.0\nazimuth = 0\nelevation = 80\n\
                 [[key]]\nt = 0.3\nazimuth = 120\nelevation = 80\nroll = 20\n\
                 [[key]]\nt = 0.6\nazimuth = 240\nelevation = 80\n",
                5,
            ),
        ];
        for (i, (text, charts)) in cases.iter().enumerate() {
            let m = parse_spec(text, Some(Path::new(&format!("case{i}.toml")))).unwrap();
            let files = write_all(&m, dir.path(), 200, &BenchScale::default()).unwrap();
            assert_eq!(files.len(), 2 * charts, "case {i}");
            for f in files {
                assert!(
                    std::fs::metadata(&f).unwrap().len() > 1000,
                    "{}",
                    f.display()
                );
            }
        }
    }
}
