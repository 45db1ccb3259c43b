//! The synthesis report: PNG/SVG plots of a mechanism, drawn through the shared `plot`
//! module.
//!
//! Owns the choice of plots: dist(t) against −ε (paper Fig. 8 middle), the curve pairs in
//! the follower's and the driver's local frames (top and side views), and the projected
//! normals ñ with their hull at the worst instant (paper Fig. 8 right). It reads only the
//! mechanism file's content; it does not synthesize or check.

use std::path::{Path, PathBuf};

use crate::plot::{Chart, Series};

use super::closure::{self, Class, EPSILON, NO_INTERIOR_DIST};
use super::error::ReportError;
use super::mechanism::Mechanism;

/// dist values above this are drawn clipped (no-interior samples carry
/// [`NO_INTERIOR_DIST`]). Default 1.2: every real distance of unit vectors is within ±1.
pub const DIST_PLOT_CLIP: f64 = 1.2;

/// Write every report plot into `dir`; returns the files written.
pub fn write_report(m: &Mechanism, dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut out = Vec::new();
    let charts = std::iter::once(("dist".to_string(), dist_chart(m)))
        .chain(torque_arm_chart(m))
        .chain(curve_charts(m))
        .chain(normals_charts(m));
    for (stem, chart) in charts {
        out.extend(chart.write(&dir.join(stem))?);
    }
    Ok(out)
}

/// dist(t) against the zones of closure with margin and closure lost (paper Fig. 8 middle).
fn dist_chart(m: &Mechanism) -> Chart {
    let n = m.samples as f64;
    let clip = |d: f64| d.min(DIST_PLOT_CLIP);
    let mut dist = Chart::new(
        format!(
            "dist(t), {} K = {}, d_x = {} ({} mm): E_valiTime {:.3}, E_maxDist {}",
            m.class.label(),
            m.curve_pairs.len(),
            m.driver_offset,
            crate::motion::units::trim(m.driver_offset * m.scale_mm, 2),
            m.closure.vali_time,
            super::closure::dist_text(m.closure.max_dist)
        ),
        "t (fraction of the period)",
        "signed distance (clipped at 1.2 = no interior)",
    )
    .with(Series::line(
        "dist(t) (paper)",
        m.closure
            .dist
            .iter()
            .enumerate()
            .map(|(i, d)| (i as f64 / n, clip(*d)))
            .collect(),
        0,
    ));
    if m.closure.robust_dist.len() == m.samples {
        dist.series.push(Series::dashed(
            "robust dist(t)",
            m.closure
                .robust_dist
                .iter()
                .enumerate()
                .map(|(i, d)| (i as f64 / n, clip(*d)))
                .collect(),
            1,
        ));
    }
    // Issue 20: the −ε and 0 lines were two identical red dashes; the zones say which
    // side is which.
    dist.zones.push((
        -1.1,
        -EPSILON,
        2,
        format!("closure with margin (≤ −ε = −{EPSILON})"),
    ));
    dist.zones
        .push((0.0, DIST_PLOT_CLIP + 0.05, 1, "closure lost (> 0)".into()));
    dist.y_range = Some((-1.1, DIST_PLOT_CLIP + 0.05));
    dist
}

/// 1R/1R1T: each contact's torque arm over t, what the robust closure looks at.
fn torque_arm_chart(m: &Mechanism) -> Option<(String, Chart)> {
    let n = m.samples as f64;
    let mut out = None;
    if matches!(m.class, Class::R1 | Class::R1T1) {
        // Torque arm per contact: what the robust closure looks at.
        let sg = closure::GAMMA0_DEG.to_radians().sin();
        let mut c = Chart::new(
            "torque arm per contact, (p × n)·z / |p_xy| (robust when |arm| ≥ sin 10°)",
            "t (fraction of the period)",
            "torque arm per unit radius",
        );
        for (k, cp) in m.curve_pairs.iter().enumerate() {
            let pts = cp
                .samples
                .p
                .iter()
                .zip(&cp.samples.n)
                .enumerate()
                .map(|(i, (&p, &nn))| (i as f64 / n, closure::torque_arm(p, nn)))
                .collect();
            c.series.push(Series::line(format!("pair {k}"), pts, k));
        }
        c.h_lines.push((sg, "+sin 10°".into()));
        c.h_lines.push((-sg, "−sin 10°".into()));
        c.y_range = Some((-1.05, 1.05));
        out = Some(("torque-arm".to_string(), c));
    }

    out
}

/// The curve pairs in the follower's and the driver's frames, top and side views, in mm.
fn curve_charts(m: &Mechanism) -> Vec<(String, Chart)> {
    let mut out = Vec::new();
    for (frame, name) in [("follower", "c2"), ("driver", "c1")] {
        for (view, a, b) in [("top", 0usize, 1usize), ("side", 0, 2)] {
            // In millimetres, the size the parts are built at (issue 20).
            let mm = |axis: &str| {
                format!(
                    "{axis} [mm = model units × {}]",
                    crate::motion::units::trim(m.scale_mm, 3)
                )
            };
            let mut c = Chart::new(
                format!("curves in the {frame} frame ({view} view)"),
                mm("x"),
                mm(if b == 1 { "y" } else { "z" }),
            );
            c.equal_aspect = true;
            for (k, cp) in m.curve_pairs.iter().enumerate() {
                let pts = if frame == "follower" {
                    &cp.samples.c2
                } else {
                    &cp.samples.c1
                };
                let mut v: Vec<(f64, f64)> = pts
                    .iter()
                    .map(|p| (p[a] * m.scale_mm, p[b] * m.scale_mm))
                    .collect();
                v.push(v[0]);
                c.series
                    .push(Series::line(format!("{name} pair {k}"), v, k));
            }
            c.series
                .push(Series::points("axis", vec![(0.0, 0.0)], 4, 7));
            // Room above the curves for the legend, which hid the top band's curve where
            // it reached the right edge.
            let (lo, hi) = c
                .series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                    (lo.min(y), hi.max(y))
                });
            if lo < hi {
                c.y_range = Some(crate::plot::legend_room_y_range(lo, hi - lo));
            }
            out.push((format!("curves-{frame}-{view}"), c));
        }
    }

    out
}

/// The projected normals ñ and their hull at the worst instant (paper Fig. 8 right); for
/// 1R each contact's torque arm as a bar.
fn normals_charts(m: &Mechanism) -> Vec<(String, Chart)> {
    let n = m.samples as f64;
    let mut out = Vec::new();
    // Projected normals at the worst time.
    let worst = m
        .closure
        .dist
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
        .unwrap_or(0);
    let pts: Vec<[f64; 3]> = m
        .curve_pairs
        .iter()
        .filter_map(|cp| closure::project(m.class, cp.samples.p[worst], cp.samples.n[worst]))
        .collect();
    let d = m.closure.dist[worst];
    let title = format!(
        "projected normals at the worst time t = {:.3} (dist {})",
        worst as f64 / n,
        if d >= NO_INTERIOR_DIST {
            "no interior".to_string()
        } else {
            format!("{d:.3}")
        }
    );
    if m.class == Class::R1 {
        // A 1R normal projects to one number, the sense it can turn the follower (issue
        // 20: drawn on a plane with an "(unused)" axis): each contact's torque arm as a
        // bar, closure needing both senses.
        let sg = closure::GAMMA0_DEG.to_radians().sin();
        let mut c = Chart::new(
            format!("{title}: torque arm per contact"),
            "curve pair",
            "torque arm per unit radius",
        );
        let arms: Vec<(f64, f64)> = m
            .curve_pairs
            .iter()
            .enumerate()
            .map(|(k, cp)| {
                let arm = closure::torque_arm(cp.samples.p[worst], cp.samples.n[worst]);
                (k as f64, arm)
            })
            .collect();
        c.series.push(Series::bars("", arms, 0));
        c.h_lines.push((sg, "±sin 10° (robust)".into()));
        c.h_lines.push((-sg, String::new()));
        c.y_range = Some((-1.05, 1.05 * crate::plot::LEGEND_HEADROOM));
        c.x_range = Some((-0.5, m.curve_pairs.len() as f64 - 0.5));
        c.whole_x = true;
        out.push(("normals-worst".to_string(), c));
        return out;
    }
    let views: Vec<(usize, usize, &str)> = match m.class {
        Class::R1 | Class::R1T1 => vec![(0, 1, "")],
        Class::R3 => vec![(0, 1, "-xy"), (0, 2, "-xz")],
    };
    for (a, b, suffix) in views {
        let mut c = Chart::new(
            format!("{title}{}", suffix.replace('-', " ")),
            match m.class {
                Class::R1 => "ñ (sign of torque)",
                Class::R1T1 => "ñ₁ (n·z, normalized)",
                Class::R3 => "ñ component",
            },
            match m.class {
                Class::R1 => "",
                Class::R1T1 => "ñ₂ ((p×n)·z, normalized)",
                Class::R3 => "ñ component",
            },
        );
        c.equal_aspect = true;
        c.x_range = Some((-1.2, 1.2));
        c.y_range = Some((-1.2, 1.2));
        let proj: Vec<(f64, f64)> = pts.iter().map(|p| (p[a], p[b])).collect();
        // Hull outline in this view (2-D hull of the projected points).
        let h = closure::hull_2d(&proj.iter().map(|p| [p.0, p.1]).collect::<Vec<_>>());
        if h.len() >= 2 {
            let mut v: Vec<(f64, f64)> = h.iter().map(|p| (p[0], p[1])).collect();
            v.push(v[0]);
            c.series.push(Series::line("hull (projected)", v, 3));
        }
        c.series.push(Series::points("ñ_k", proj, 6, 0));
        c.series
            .push(Series::points("origin", vec![(0.0, 0.0)], 5, 2));
        out.push((format!("normals-worst{suffix}"), c));
    }
    out
}
