//! The functional shapes: what the conjugate curve pairs become.
//!
//! Owns, for each curve pair k (paper §5.3):
//! - the follower's **rim**: a half ellipse swept along c²ₖ (follower frame) with its apex
//!   on the curve and its major axis along the outward normal n²ₖ, so the rim's surface
//!   normal at the contact is the design normal;
//! - the follower's **web**: the surface spanning the rim (a fan from the rim's centroid
//!   to the ellipse centres behind the apex), thickened, which closes the rim into a
//!   plate; the caller keeps it clear of the driver's swept volume;
//! - the driver's **band**: a rounded rectangle swept along c¹ₖ (driver frame), standing
//!   [`BAND_LIP_MM`] past the contact towards the follower, so the follower's sweep carves
//!   a groove into it;
//! - ball covers of each (conservative: every point of the shape lies in a ball) for the
//!   coarse swept volumes that plan struts.
//!
//! It does not place hubs or supports, and does not carve.

use crate::geometry::sdf::{ThickTriangles, Vec3};
use crate::geometry::sweep::{Frame as PathFrame, Section, Sweep, SweepError};
use crate::synth::mechanism::CurvePair;

use super::dims::*;
use super::kinematics::Frame;
use super::swept::Balls;

/// The rims' section.
pub const RIM: Section = Section::HalfEllipse {
    a: RIM_DEPTH_MM,
    b: RIM_HALF_WIDTH_MM,
};

/// The bands' section (u along the driver's outward normal: material from −depth to +lip).
pub const BAND: Section = Section::RoundedRect {
    u_min: -BAND_DEPTH_MM,
    u_max: BAND_LIP_MM,
    half_width: BAND_HALF_WIDTH_MM,
    round: BAND_ROUND_MM,
};

/// Length of the strips a web's fan is cut into along each sliver, mm ([`web`]). 2 mm: a
/// few strips' boxes hold any point of the 2.4 mm plate.
pub const WEB_STRIP_MM: f64 = 2.0;
/// Spacing of the sample points a web is covered by, mm.
const WEB_COVER_SPACING_MM: f64 = 1.4;

fn scaled(p: [f64; 3], s: f64) -> Vec3 {
    Vec3::new(p[0] * s, p[1] * s, p[2] * s)
}
fn unit(p: [f64; 3]) -> Vec3 {
    Vec3::new(p[0], p[1], p[2]).normalize()
}

/// The rim of pair `cp` in the follower frame, mm (frame i is sample i of c², n²).
pub fn rim(cp: &CurvePair, scale_mm: f64) -> Result<Sweep, SweepError> {
    let frames = cp
        .samples
        .c2
        .iter()
        .zip(&cp.samples.n2)
        .map(|(c, n)| PathFrame {
            o: scaled(*c, scale_mm),
            u: unit(*n),
        })
        .collect();
    Sweep::new(frames, RIM)
}

/// The band of pair `cp` in the driver frame, mm (frame i is sample i of c¹, n¹).
pub fn band(cp: &CurvePair, scale_mm: f64) -> Result<Sweep, SweepError> {
    let frames = cp
        .samples
        .c1
        .iter()
        .zip(&cp.samples.n1)
        .map(|(c, n)| PathFrame {
            o: scaled(*c, scale_mm),
            u: unit(*n),
        })
        .collect();
    Sweep::new(frames, BAND)
}

/// The ellipse centres behind the rim's apex: where the web joins the rim.
pub fn rim_core(rim: &Sweep) -> Vec<Vec3> {
    rim.frames()
        .iter()
        .map(|f| f.o - f.u * RIM_DEPTH_MM)
        .collect()
}

/// The web closing `rim` into a plate: a fan from the core loop's centroid, thickened;
/// and the fan's triangles (centre, core point, next core point).
///
/// The plate is built from the same fan cut into strips [`WEB_STRIP_MM`] long along each
/// sliver: the same surface, but boxes small enough that a point inside the plate lies in
/// a few of them, where a whole sliver's box (from the centre to the rim) holds about a
/// quarter of the plate and the exact value inside (`ThickTriangles`) visited that many.
pub fn web(rim: &Sweep) -> (ThickTriangles, Vec<[Vec3; 3]>) {
    let core = rim_core(rim);
    let c = core.iter().sum::<Vec3>() / core.len() as f64;
    let n = core.len();
    let tris: Vec<[Vec3; 3]> = (0..n).map(|i| [c, core[i], core[(i + 1) % n]]).collect();
    let mut strips = Vec::new();
    for &[c, a, b] in &tris {
        let reach = (a - c).norm().max((b - c).norm());
        let m = (reach / WEB_STRIP_MM).ceil().max(1.0) as usize;
        let at = |q: Vec3, k: usize| c + (q - c) * (k as f64 / m as f64);
        strips.push([c, at(a, 1), at(b, 1)]);
        for k in 1..m {
            let (a0, b0, a1, b1) = (at(a, k), at(b, k), at(a, k + 1), at(b, k + 1));
            strips.push([a0, a1, b1]);
            strips.push([a0, b1, b0]);
        }
    }
    (ThickTriangles::new(strips, WEB_HALF_THICKNESS_MM), tris)
}

/// Balls covering a sweep: per frame, a small grid of balls over the section (two along
/// the half ellipse's axis; two by two over the rectangle), each radius the half diagonal
/// of its cell, plus half the largest frame spacing so the cover has no gaps between frames.
pub fn sweep_cover(s: &Sweep, frame: Frame) -> Balls {
    // Section cells as (u centre, v centre) with the cell half extents.
    let (cells, half): (Vec<(f64, f64)>, (f64, f64)) = match s.section() {
        Section::HalfEllipse { a, b } => (vec![(-0.25 * a, 0.0), (-0.75 * a, 0.0)], (0.25 * a, b)),
        Section::RoundedRect {
            u_min,
            u_max,
            half_width,
            ..
        } => {
            let (hu, hv) = (0.25 * (u_max - u_min), 0.5 * half_width);
            let (u0, u1) = (u_min + hu, u_max - hu);
            (vec![(u0, -hv), (u0, hv), (u1, -hv), (u1, hv)], (hu, hv))
        }
    };
    let fr = s.frames();
    let n = fr.len();
    let gap = (0..n)
        .map(|i| (fr[(i + 1) % n].o - fr[i].o).norm())
        .fold(0.0, f64::max);
    let mut centers = Vec::with_capacity(n * cells.len());
    for i in 0..n {
        let t = (fr[(i + 1) % n].o - fr[(i + n - 1) % n].o).normalize();
        let u = (fr[i].u - t * fr[i].u.dot(&t)).normalize();
        let v = t.cross(&u);
        for &(cu, cv) in &cells {
            centers.push(fr[i].o + u * cu + v * cv);
        }
    }
    Balls {
        frame,
        centers,
        radius: half.0.hypot(half.1) + 0.5 * gap,
    }
}

/// Sample points covering a web's fan (centre `tris[i][0]`, rim core `tris[i][1]`), about
/// `WEB_COVER_SPACING_MM` (1.4 mm) apart: rings of points at fractions of the way from the
/// centre to the core, each ring thinned to that spacing; with the radius that covers the
/// thickened web. `keep` filters the points (what survives of a web).
pub fn web_cover(tris: &[[Vec3; 3]], keep: impl Fn(Vec3) -> bool) -> Balls {
    let mut centers = Vec::new();
    if let Some(first) = tris.first() {
        let c = first[0];
        let core: Vec<Vec3> = tris.iter().map(|t| t[1]).collect();
        let n = core.len();
        let reach = core.iter().map(|q| (q - c).norm()).fold(0.0, f64::max);
        let spacing = (0..n)
            .map(|i| (core[(i + 1) % n] - core[i]).norm())
            .sum::<f64>()
            / n as f64;
        let rings = (reach / WEB_COVER_SPACING_MM).ceil().max(1.0) as usize;
        for j in 0..=rings {
            let s = j as f64 / rings as f64;
            let stride = if s * spacing > 0.0 {
                ((WEB_COVER_SPACING_MM / (s * spacing)).floor() as usize).clamp(1, n)
            } else {
                n
            };
            for i in (0..n).step_by(stride) {
                let p = c + (core[i] - c) * s;
                if keep(p) {
                    centers.push(p);
                }
            }
        }
    }
    Balls {
        frame: Frame::Follower,
        centers,
        // Within a ring samples are at most the spacing apart, rings are the spacing apart
        // along the rays: any fan point is within spacing·√2/2·2 of a sample.
        radius: WEB_HALF_THICKNESS_MM + WEB_COVER_SPACING_MM * std::f64::consts::SQRT_2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::sdf::Sdf;

    /// The rim of a circular curve pair touches the design point with the design normal:
    /// the apex is on the surface and the rim's distance grows along +n² at rate 1.
    #[test]
    fn rim_apex_is_on_the_curve_with_the_design_normal() {
        let n = 360;
        let frames: Vec<PathFrame> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                PathFrame {
                    o: Vec3::new(20.0 * a.cos(), 20.0 * a.sin(), 0.0),
                    // The normal leans 30° upwards from radial.
                    u: Vec3::new(a.cos() * 0.866, a.sin() * 0.866, 0.5),
                }
            })
            .collect();
        let r = Sweep::new(frames.clone(), RIM).unwrap();
        for f in frames.iter().step_by(37) {
            assert!(r.dist(f.o).abs() < 1e-3, "apex at {:?}", f.o);
            assert!((r.dist(f.o + f.u * 0.5) - 0.5).abs() < 1e-3);
        }
        let cover = sweep_cover(&r, Frame::Follower);
        // Every point inside the rim is inside some ball of the cover.
        for k in 0..500 {
            let f = &frames[(k * 7) % n];
            let v = f.u.cross(&Vec3::z()).normalize();
            let p = f.o - f.u * (0.01 + (k % 29) as f64 * 0.1) + v * ((k % 7) as f64 * 0.2 - 0.6);
            if r.dist(p) < 0.0 {
                let inside = cover.centers.iter().any(|c| (p - c).norm() <= cover.radius);
                assert!(inside, "{p:?} not covered");
            }
        }
    }
}
