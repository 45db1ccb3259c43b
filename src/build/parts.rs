//! The three printed parts as solids: the design step that joins shapes, layout and plans.
//!
//! Owns [`Design`] and its construction, in this order (each step plans against what the
//! earlier ones fixed):
//! 1. rims and webs (follower) and bands (driver) from the curve pairs (`shapes`);
//! 2. hubs, joint, couplings, sensor features and support by rule (`layout`);
//! 3. for 3R, the support's post to the ball's cup, planned around both parts' sweeps;
//! 4. the webs kept [`WEB_MARGIN_MM`] clear of the driver's swept bands (exactly, near
//!    their edge, by cuts through their whole thickness: [`WEB_THROUGH_CUT_MM`]) and the
//!    follower's struts, cap and pad joined through the space the driver and support never
//!    enter;
//! 5. the driver's struts joined through the space the whole follower never enters, one
//!    per piece the carve leaves of each band (`segments`).
//!
//! Then the solids: the follower shrunk by half the clearance; the driver as bands, struts
//! and hub minus the exact swept volume of the rims grown by half the clearance (the
//! groove); the support. It does not mesh or check (`build`).

use std::sync::Arc;

use rayon::prelude::*;

use crate::geometry::mesh::Aabb;
use crate::geometry::sdf::{
    Cylinder, Difference, Offset, Sdf, ThickPolyline, ThickTriangles, Union, Vec3,
};
use crate::geometry::sweep::{Sweep, SWEEP_EXACT_WITHIN_MM};
use crate::geometry::voxel::DistanceField;
use crate::synth::closure::Class;
use crate::synth::mechanism::Mechanism;

use super::bench::{Bench, Reading};
use super::connect::{self, Joined};
use super::dims::*;
use super::kinematics::{Frame, Kinematics};
use super::layout::{cover_cylinder, Layout, Pieces};
use super::segments::{self, Segment};
use super::shapes;
use super::swept::{nearest_first, Balls, Certificates, ExactSweep, SweptEach};
use super::{BuildError, BuildOptions};

/// A strut's root lies this far inside the piece it leaves from (behind the rim's flat
/// side, in front of the band's back face), mm.
const ROOT_DEPTH_MM: f64 = 1.0;
/// Exact clearance the strut's first segment keeps from the other part's functional
/// surfaces beyond its radius, mm (the coarse field takes over at the start point).
const ROOT_MARGIN_MM: f64 = 0.3;
/// How far behind a rim or band a strut may have to reach for free space, mm: synthesis
/// owns it, since its island test must anchor only the pieces these rays can leave.
use crate::synth::undercut::ESCAPE_REACH_MM as RAY_REACH_MM;
/// The exact carve of the driver is computed only where its value matters: within this many
/// cells of the surface (values beyond are capped). A capped value keeps its sign, and the
/// mesher reads magnitudes only on the edges of its tetrahedra that change sign, which are
/// at most a cell diagonal (√3 cells) long: where the value changes by at most 1 per mm, a
/// point farther than that from the surface has no such edge. 2 leaves 15 % over √3. A
/// twisted rim's value may change faster (its `Sdf::lipschitz`, up to 2.84 on
/// half-turn-2to1), and there a capped value could move a vertex along its edge, never a
/// sign. Measured on half-turn-2to1 at 0.4 mm: the driver's STL is byte for byte the one
/// the earlier 3 cells gave, and the carve took 269 s against 288–363 s.
const CARVE_CAP_CELLS: f64 = 2.0;
/// How far above the bridge the search for the carve's pieces of band looks, mm
/// ([`carved_pieces`]): any value above the bridge would do, a tenth of a millimetre
/// keeps the searches short.
const PIECES_CAP_ABOVE_BRIDGE_MM: f64 = 0.1;

/// The largest cap of the carve's searches, mm: the driver's
/// ([`Design::carve_cap`]) and that of the pieces it leaves of each band
/// ([`carved_pieces`]). Each rim's coarse field (`Design::carve_fields`) is made this far
/// around the rim's sweep and no farther.
fn carve_reach(cell_mm: f64, clearance: f64) -> f64 {
    (CARVE_CAP_CELLS * cell_mm).max(segments::BRIDGE_MM + PIECES_CAP_ABOVE_BRIDGE_MM)
        + 0.5 * clearance
}

/// The slope at or below which a rim's pieces count as mild for the carve
/// ([`Sweep::split_by_twist`]): 1.2 keeps all but the sharpest stretches of the examples'
/// rims in the mild part (half-turn-2to1: 1.00–1.14 for four rims, 1.52 and 2.84 at their
/// sharpest for the other two, whose mild parts are then searched at 1.2 at most).
const CARVE_MILD_SLOPE: f64 = 1.2;
/// Lattice of the certificates (`swept::Certificates`) of every swept search that many
/// nearby points ask, mm: the carve's rims through the driver's frame and the bands
/// through the follower's ([`SharedClearance`]). Every point in a 1 mm cube starts from
/// the search made at its centre. Lattices of 0.8, 1.25, 1.6 and 2 mm were measured
/// against it for the carve (docs/build.md): none was faster.
const CERTIFICATE_CELL_MM: f64 = 1.0;

/// Everything the parts are made of, placed and planned.
pub struct Design {
    /// The kinematics.
    pub kin: Arc<Kinematics>,
    /// Placement by rule.
    pub layout: Layout,
    /// Follower rims (follower frame), nominal.
    pub rims: Vec<Sweep>,
    /// Driver bands (driver frame), nominal.
    pub bands: Vec<Sweep>,
    /// Follower webs before keeping them clear.
    pub webs: Vec<Arc<ThickTriangles>>,
    /// Follower struts.
    pub follower_struts: Vec<ThickPolyline>,
    /// Follower struts whose root the driver's swept bands hem in: only their core was
    /// planned clear there, and their flanks are trimmed as the webs are.
    pub follower_rooted: Vec<ThickPolyline>,
    /// Driver struts.
    pub driver_struts: Vec<ThickPolyline>,
    /// Follower features by rule plus planned ones (pad, end-effector).
    pub follower_pieces: Pieces,
    /// Driver hub and coupling.
    pub driver_pieces: Pieces,
    /// Support by rule plus planned ones (post, cup).
    pub support_pieces: Pieces,
    /// Clearance from the driver's bands (exact where it matters), hub, column, struts and
    /// the support, follower frame: what the webs keep clear of.
    pub band_clearance: Arc<BandClearance>,
    /// The rims as the carve sweeps them: each cut by how sharply it twists
    /// ([`Sweep::split_by_twist`] at a slope of 1.2, `CARVE_MILD_SLOPE`), so that a short
    /// sharp twist slows the search near it alone.
    pub carve_rims: Vec<Sweep>,
    /// Per carve rim, a lower bound of its swept distance (driver frame) up to the carve's
    /// largest cap (`carve_reach`): its own rim's coarse sweep, which lets the carve skip
    /// every rim but the one whose groove a point is near (a field of the whole follower
    /// bounds them all by the nearest).
    pub carve_fields: Vec<Arc<DistanceField>>,
    /// Cells per mm of the mesher (for the carve's cap).
    pub cell_mm: f64,
    /// Print clearance.
    pub clearance: f64,
    /// Pair left out (`--without-pair`), if any.
    pub without_pair: Option<usize>,
}

fn boxed<S: Sdf + 'static>(s: S) -> Box<dyn Sdf> {
    Box::new(s)
}

/// Design the parts of `mech`.
pub fn design(
    mech: &Mechanism,
    kin: Arc<Kinematics>,
    bench: &Bench,
    opts: &BuildOptions,
    progress: &dyn Fn(&str),
) -> Result<Design, BuildError> {
    let s = kin.scale_mm();
    let pairs: Vec<(usize, &crate::synth::mechanism::CurvePair)> = mech
        .curve_pairs
        .iter()
        .enumerate()
        .filter(|(k, _)| Some(*k) != opts.without_pair)
        .collect();
    let sweep_err = |what: &'static str, k: usize| {
        move |source| BuildError::Sweep {
            what,
            pair: k + 1,
            source,
        }
    };
    // Side by side (each sweep makes its cells' lists on one thread); the first failure in
    // the pairs' order is the one reported.
    let (rims, bands): (Vec<_>, Vec<_>) = pairs
        .par_iter()
        .map(|(k, cp)| {
            (
                shapes::rim(cp, s).map_err(sweep_err("rim", *k)),
                shapes::band(cp, s).map_err(sweep_err("band", *k)),
            )
        })
        .unzip();
    let rims: Vec<Sweep> = rims.into_iter().collect::<Result<_, _>>()?;
    let bands: Vec<Sweep> = bands.into_iter().collect::<Result<_, _>>()?;
    let webs_tris: Vec<(ThickTriangles, Vec<[Vec3; 3]>)> = rims.iter().map(shapes::web).collect();
    let rim_covers: Vec<Balls> = rims
        .iter()
        .map(|r| shapes::sweep_cover(r, Frame::Follower))
        .collect();
    let band_covers: Vec<Balls> = bands
        .iter()
        .map(|b| shapes::sweep_cover(b, Frame::Driver))
        .collect();
    let web_full_covers: Vec<Balls> = webs_tris
        .iter()
        .map(|(_, t)| shapes::web_cover(t, |_| true))
        .collect();

    // 2. By rule.
    let mut f_cover: Vec<Balls> = rim_covers.clone();
    f_cover.extend(web_full_covers.iter().cloned());
    let layout = Layout::new(&kin, bench, opts.clearance_mm, &f_cover, &band_covers);
    let mut follower_pieces = layout.follower_pieces();
    let driver_pieces = layout.driver_pieces();
    let mut support_pieces = layout.support_pieces();

    // 3. 3R: the post from the base to the ball's cup.
    if kin.class() == Class::R3 {
        progress("planning the post to the ball joint");
        plan_post(
            &kin,
            &layout,
            &f_cover,
            &band_covers,
            &driver_pieces,
            &mut support_pieces,
        )?;
    }

    // 4. Each part's column up its axis from the hub, as far as the other part's functional
    //    surfaces leave it room (all the way when the curves keep off the other axis).
    progress("sweeping the rims through the driver's frame and the bands through the follower's");
    let mut d_bodies: Vec<&Balls> = band_covers.iter().collect();
    d_bodies.extend(driver_pieces.cover.iter());
    let dgrid = connect::grid_around(&kin, &d_bodies, Frame::Driver);
    let mut f_bodies: Vec<&Balls> = f_cover.iter().collect();
    f_bodies.extend(follower_pieces.cover.iter());
    let fgrid = connect::grid_around(&kin, &f_bodies, Frame::Follower);
    let mut d_others_rule: Vec<Balls> = follower_pieces.cover.clone();
    d_others_rule.extend(support_pieces.cover.iter().cloned());
    let mut f_others_rule: Vec<Balls> = driver_pieces.cover.clone();
    f_others_rule.extend(support_pieces.cover.iter().cloned());
    // The swept fields below are independent: made side by side, the serial parts of one
    // (marking the traces, the transform's gathers) overlap the others.
    let reach = carve_reach(opts.cell_mm, opts.clearance_mm);
    let ((d_rims, d_others), ((rim_fields, band_fields), follower_other_field)) = rayon::join(
        || {
            rayon::join(
                || connect::clearance(&kin, &rim_covers, Frame::Driver, dgrid),
                || connect::clearance(&kin, &d_others_rule, Frame::Driver, dgrid),
            )
        },
        || {
            rayon::join(
                || {
                    rayon::join(
                        // Each rim's own sweep, so that near one groove the carve searches
                        // that rim alone.
                        || {
                            rim_covers
                                .par_iter()
                                .map(|c| {
                                    Arc::new(connect::clearance_within(
                                        &kin,
                                        c,
                                        Frame::Driver,
                                        reach,
                                    ))
                                })
                                .collect::<Vec<Arc<DistanceField>>>()
                        },
                        // One field per band, so that the exact sweep is run only for the
                        // bands near a point.
                        || {
                            band_covers
                                .par_iter()
                                .map(|b| {
                                    connect::clearance(
                                        &kin,
                                        std::slice::from_ref(b),
                                        Frame::Follower,
                                        fgrid,
                                    )
                                })
                                .collect::<Vec<DistanceField>>()
                        },
                    )
                },
                || connect::clearance(&kin, &f_others_rule, Frame::Follower, fgrid),
            )
        },
    );
    let mut driver_field = d_rims.min(&d_others);
    let (carve_rims, carve_of): (Vec<Sweep>, Vec<usize>) = rims
        .iter()
        .enumerate()
        .flat_map(|(k, r)| {
            r.split_by_twist(CARVE_MILD_SLOPE)
                .into_iter()
                .map(move |part| (part, k))
        })
        .unzip();
    let carve_fields: Vec<Arc<DistanceField>> =
        carve_of.iter().map(|&k| rim_fields[k].clone()).collect();
    let f_bands = band_fields
        .iter()
        .skip(1)
        .fold(band_fields[0].clone(), |acc, f| acc.min(f));
    let mut follower_other_field = follower_other_field;
    let driver_top = band_covers
        .iter()
        .flat_map(|b| b.centers.iter().map(move |c| c.z + b.radius))
        .fold(f64::NEG_INFINITY, f64::max);
    // The columns are checked against the other part's functional surfaces exactly: a
    // column on the axis is where the coarse fields are most pessimistic.
    let exact_cap = COLUMN_RADIUS_MM + STRUT_MARGIN_MM + 1.0;
    let (driver_column, follower_column) = rayon::join(
        || {
            column(
                &|p| {
                    let rims = SweptEach::new(&kin, &rims, Frame::Follower, Frame::Driver)
                        .value(p, exact_cap);
                    rims.min(d_others.sample(p))
                },
                layout.driver_hub.1,
                driver_top,
            )
        },
        || {
            layout.follower_hub.and_then(|(_, top)| {
                let up_to = layout.cap.map_or(layout.z_hi, |c| c.0 + 1.0);
                column(
                    &|p| {
                        let bands = SweptEach::new(&kin, &bands, Frame::Driver, Frame::Follower)
                            .value(p, exact_cap);
                        bands.min(follower_other_field.sample(p))
                    },
                    top,
                    up_to,
                )
            })
        },
    );
    // A column that stops just short of the magnet cap leaves the cap loose (half-turn-2to1:
    // 0.5 mm short, the cap dropped and the follower without its magnet). The cap itself
    // sits there, so the last stretch up into it is taken; the check measures the result.
    let follower_column = follower_column.map(|c| reach_cap(c, layout.cap.map(|(cap0, _)| cap0)));
    let describe = |c: &Option<Cylinder>| {
        c.as_ref().map_or("none".to_string(), |c| {
            format!("{:.0}–{:.0} mm", c.base.z, c.base.z + c.length)
        })
    };
    progress(&format!(
        "columns: driver {}, follower {}",
        describe(&driver_column),
        describe(&follower_column)
    ));
    let mut driver_pieces = driver_pieces;
    if let Some(c) = &driver_column {
        driver_pieces
            .cover
            .insert(1, cover_cylinder(c, Frame::Driver));
        driver_pieces.add.insert(1, Arc::new(c.clone()));
        let swept = connect::clearance(&kin, &driver_pieces.cover[1..2], Frame::Follower, fgrid);
        follower_other_field = follower_other_field.min(&swept);
    }
    if let Some(c) = &follower_column {
        follower_pieces
            .cover
            .insert(1, cover_cylinder(c, Frame::Follower));
        follower_pieces.add.insert(1, Arc::new(c.clone()));
        let swept = connect::clearance(&kin, &follower_pieces.cover[1..2], Frame::Driver, dgrid);
        driver_field = driver_field.min(&swept);
    }

    // 5. The driver's struts first, to its hub or column, through space that the rims,
    //    the follower's rule-placed features and the support never enter (the webs and
    //    the follower's struts then make way for them: they are the part that can give).
    progress("planning the driver's struts");
    let driver_field = Arc::new(driver_field);
    let band_pieces = carved_pieces(
        &kin,
        &bands,
        &carve_rims,
        &carve_fields,
        opts.clearance_mm,
        &pairs,
        progress,
    );
    let plan_driver = |every_piece: bool| {
        plan_driver_struts(
            &kin,
            &layout,
            &bands,
            &rims,
            &driver_field,
            &driver_pieces,
            &pairs,
            &band_pieces,
            opts.clearance_mm,
            every_piece,
            progress,
        )
    };
    let driver_struts = plan_driver(true)?;

    // 6. The follower: webs and struts through space that the driver (bands, hub, column,
    //    struts) and the support never enter. When the struts to every piece of band leave
    //    it no room, the follower is planned again around one strut per band (the other
    //    pieces are then left out of the driver, and the check counts their contacts as
    //    lost): a driver missing some groove beats no parts at all.
    let webs: Vec<Arc<ThickTriangles>> = webs_tris.into_iter().map(|(w, _)| Arc::new(w)).collect();
    let plan_follower = |struts: &[ThickPolyline]| -> Result<FollowerPlan, BuildError> {
        progress("sweeping the driver's struts through the follower's frame");
        let strut_covers: Vec<Balls> = struts
            .iter()
            .map(|s| connect::strut_cover(s, Frame::Driver))
            .collect();
        let mut others = follower_other_field.clone();
        if !strut_covers.is_empty() {
            let swept = connect::clearance(&kin, &strut_covers, Frame::Follower, fgrid);
            others = others.min(&swept);
        }
        let field = Arc::new(f_bands.min(&others));
        let others = Arc::new(others);
        let web_clear = Arc::new(BandClearance {
            kin: kin.clone(),
            bands: bands.clone(),
            band_fields: band_fields.clone(),
            others,
        });
        let mut pieces = follower_pieces.clone();
        // 3R: the IMU pad and end-effector on the follower, where nothing passes.
        if kin.class() == Class::R3 && bench.reading == Reading::Imu {
            place_imu_pad(&field, &mut pieces)?;
        }
        progress("planning the follower's struts");
        let (struts, rooted) = plan_follower_struts(
            &layout,
            &rims,
            &web_clear,
            &field,
            &pieces,
            &pairs,
            opts.clearance_mm,
            progress,
        )?;
        Ok(FollowerPlan {
            web_clear,
            pieces,
            struts,
            rooted,
        })
    };
    let (driver_struts, plan) = match plan_follower(&driver_struts) {
        Ok(plan) => (driver_struts, plan),
        Err(e) => {
            // Planned again, not filtered: a band's strut may have ended on a piece that
            // only another piece's strut joined.
            let main = plan_driver(false)?;
            if main.len() == driver_struts.len() {
                return Err(e);
            }
            let why = match &e {
                BuildError::NoRoom { what, detail } => format!("{what}: {detail}"),
                other => other.to_string(),
            };
            progress(&format!(
                "the follower cannot be joined around a strut to every piece of band ({why}); \
                 planning both again with one strut per band (the {} other pieces are left \
                 out of the driver)",
                driver_struts.len() - main.len()
            ));
            let plan = plan_follower(&main)?;
            (main, plan)
        }
    };
    let FollowerPlan {
        web_clear,
        pieces: follower_pieces,
        struts: follower_struts,
        rooted: follower_rooted,
    } = plan;

    Ok(Design {
        kin,
        layout,
        rims,
        bands,
        webs,
        follower_struts,
        follower_rooted,
        driver_struts,
        follower_pieces,
        driver_pieces,
        support_pieces,
        band_clearance: web_clear,
        carve_rims,
        carve_fields,
        cell_mm: opts.cell_mm,
        clearance: opts.clearance_mm,
        without_pair: opts.without_pair,
    })
}

/// The follower's plan around a given set of driver struts.
struct FollowerPlan {
    web_clear: Arc<BandClearance>,
    pieces: Pieces,
    struts: Vec<ThickPolyline>,
    rooted: Vec<ThickPolyline>,
}

/// How far a follower column that stops below the magnet cap is still carried up into
/// it, mm: the strut margin its stopping test keeps and the cap (6 mm radius, placed by
/// rule above the contact stack) does not, plus the 2.4 mm by which the coarse field it
/// reads understates the distance (`undercut::PLANNER_UNDERSTATEMENT_MM`, measured). A
/// column ending that close to the cap ends beside material that is there anyway, and the
/// check measures the result. 2 mm was too short for screw-bob's K = 7 design: its
/// column ended 1.1 mm below the cap (2.1 mm short of 1 mm into it), stopped by the coarse
/// field of what lies on the axis above the cap, and the cap came out loose.
const COLUMN_REACH_TO_CAP_MM: f64 =
    STRUT_MARGIN_MM + crate::synth::undercut::PLANNER_UNDERSTATEMENT_MM;

/// The follower's column `c`, carried up 1 mm into the magnet cap starting at height `cap0`
/// when it stops at most [`COLUMN_REACH_TO_CAP_MM`] short of that; otherwise as it is.
fn reach_cap(mut c: Cylinder, cap0: Option<f64>) -> Cylinder {
    if let Some(cap0) = cap0 {
        let top = c.base.z + c.length;
        let into_cap = cap0 + 1.0;
        if top < into_cap && into_cap - top <= COLUMN_REACH_TO_CAP_MM {
            c.length = into_cap - c.base.z;
        }
    }
    c
}

/// Radius of each part's column up its axis. 3.5 mm: a 7 mm round post.
const COLUMN_RADIUS_MM: f64 = 3.5;

/// The column from `z0` up its part's axis towards `z1`, as far as `clearance` allows a
/// [`COLUMN_RADIUS_MM`] post with the strut margin; `None` when not even 5 mm fit.
fn column(clearance: &(dyn Fn(Vec3) -> f64 + Sync), z0: f64, z1: f64) -> Option<Cylinder> {
    let need = COLUMN_RADIUS_MM + STRUT_MARGIN_MM;
    // The heights in 0.5 mm steps from z0 to z1 (and the first beyond); the column rises
    // to the first whose next half millimetre is not clear. The exact sweeps are asked at
    // every height side by side: each value is a search of its own on one thread.
    let mut steps = Vec::new();
    let mut z = z0;
    while z < z1 {
        steps.push(z);
        z += 0.5;
    }
    let blocked = steps
        .par_iter()
        .position_first(|&z| clearance(Vec3::new(0.0, 0.0, z + 0.5)) < need);
    let z = blocked.map_or(z, |k| steps[k]);
    (z - z0 >= 5.0).then(|| Cylinder::z(0.0, 0.0, z0 - 1.0, z, COLUMN_RADIUS_MM))
}

/// Join each plate (nearest the hub first), then the rule-placed features, to the hub:
/// the struts, and those of them rooted by their core alone (see below).
///
/// A plate's strut leaves from behind its rim, along −n², with its whole section clear of
/// the driver's swept bands; failing that, also across the rim (±v, towards the gap
/// between slabs, and the diagonals), as the driver's struts do; failing that, with only
/// its core clear from its root on ([`STRUT_CORE_MM`] plus the webs' margin and half the
/// clearance): such a strut is trimmed by the bands' sweep as the webs are
/// ([`Design::follower_solid`]). Screw-bob's printable design has a plate that every ray
/// from behind leaves within 2.5 mm of the bands' sweep.
#[allow(clippy::too_many_arguments)]
fn plan_follower_struts(
    layout: &Layout,
    rims: &[Sweep],
    web_clear: &BandClearance,
    field: &DistanceField,
    pieces: &Pieces,
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    clearance: f64,
    progress: &dyn Fn(&str),
) -> Result<(Vec<ThickPolyline>, Vec<ThickPolyline>), BuildError> {
    let fgrid = field.grid;
    let mut joined = Joined::new(fgrid);
    let hub_center = match layout.follower_hub {
        Some((z0, z1)) => Vec3::new(0.0, 0.0, 0.5 * (z0 + z1)),
        None => Vec3::zeros(),
    };
    // The hub (or ball) is where joining starts.
    joined_mark_first(&mut joined, pieces);
    let core_of = |k: usize| shapes::rim_core(&rims[k]);
    let mut order: Vec<usize> = (0..rims.len()).collect();
    let nearest = |k: usize| {
        core_of(k)
            .iter()
            .map(|p| (p - hub_center).norm())
            .fold(f64::INFINITY, f64::min)
    };
    order.sort_by(|&a, &b| nearest(a).total_cmp(&nearest(b)));
    let mut struts = Vec::new();
    let mut rooted = Vec::new();
    let whole = STRUT_RADIUS_MM + ROOT_MARGIN_MM;
    // A strut rooted by its core is trimmed as the webs are: nothing is left within
    // WEB_MARGIN_MM of the bands' sweep, and the shrink takes half the clearance more. Its
    // core survives where the clearance is that much beyond the core's radius, and from
    // its root on: screw-bob's K = 7 design had plate 6's strut pass at 1.1 mm from 1 mm
    // out, its root 0.6 mm from band 6's sweep, and the rim came out loose.
    let core = STRUT_CORE_MM + WEB_MARGIN_MM + 0.5 * clearance;
    let band_clearance = |p: Vec3| web_clear.below(p, whole, f64::NEG_INFINITY);
    for &k in &order {
        let what = format!("plate {} (curve pair {})", k + 1, pairs[k].0 + 1);
        // Struts leave a rim from behind it, along −n², where the driver's band is not.
        let depth = RIM_DEPTH_MM + ROOT_DEPTH_MM;
        let behind = strut_from_behind(
            &rims[k],
            depth,
            field,
            &band_clearance,
            &mut joined,
            hub_center,
            &what,
        );
        let st = match behind {
            Ok(st) => st,
            Err(BuildError::NoRoom { .. }) => {
                let rays = rim_rays(&rims[k], depth);
                let across = strut_from_rays(
                    &rays,
                    whole,
                    false,
                    field,
                    &band_clearance,
                    &mut joined,
                    hub_center,
                    &what,
                    None,
                );
                match across {
                    Ok(st) => st,
                    Err(BuildError::NoRoom { .. }) => {
                        let blame = |points: &[Vec3]| {
                            sweeps_that_block(
                                &web_clear.kin,
                                &web_clear.bands,
                                (Frame::Driver, Frame::Follower),
                                pairs,
                                "band",
                                "no single band's sweep stops them: the driver's hub, \
                                 column, struts or the support do",
                                core,
                                points,
                            )
                        };
                        let st = strut_from_rays(
                            &rays,
                            core,
                            true,
                            field,
                            &band_clearance,
                            &mut joined,
                            hub_center,
                            &what,
                            Some(&blame),
                        )?;
                        progress(&format!(
                            "{what}: no strut's whole section leaves it clear of the driver's \
                             swept bands; one leaves with its {:.1} mm core clear, its flanks \
                             trimmed like the webs",
                            2.0 * STRUT_CORE_MM
                        ));
                        joined.mark_balls(&core_of(k), 1.5);
                        rooted.push(st);
                        continue;
                    }
                    Err(e) => return Err(e),
                }
            }
            Err(e) => return Err(e),
        };
        joined.mark_balls(&core_of(k), 1.5);
        struts.push(st);
    }
    // Rule-placed features other than the hub/ball (cap, flange, pad) joined too.
    for (i, cover) in pieces.cover.iter().enumerate().skip(1) {
        let pts = &cover.centers;
        // A feature touching what is joined already needs no strut.
        if pts
            .iter()
            .any(|p| fgrid.voxel_of(*p).is_some_and(|v| joined.contains(v)))
        {
            joined.mark_balls(pts, 1.0);
            continue;
        }
        // Rays in the six axis directions from the feature's cover centres.
        let rays: Vec<(Vec3, Vec3)> = pts
            .iter()
            .flat_map(|&p| {
                [
                    Vec3::x(),
                    -Vec3::x(),
                    Vec3::y(),
                    -Vec3::y(),
                    Vec3::z(),
                    -Vec3::z(),
                ]
                .map(|d| (p, d))
            })
            .collect();
        let starts =
            connect::ray_starts(&rays, field, &|_| f64::INFINITY, 0.0, RAY_REACH_MM, false);
        let st = strut_from_starts(
            field,
            &joined,
            &starts,
            hub_center,
            &format!("follower feature {}", i + 1),
            None,
        )?;
        joined.mark_balls(&connect::polyline_points(&st, 0.5), st.radius);
        joined.mark_balls(pts, 1.0);
        struts.push(st);
    }
    Ok((struts, rooted))
}

/// Rays leaving a rim from `depth` mm behind its curve at every second frame: behind it
/// (−u), across it (±v) and the diagonals between, u and v the section's axes.
fn rim_rays(rim: &Sweep, depth: f64) -> Vec<(Vec3, Vec3)> {
    let frames = rim.frames();
    (0..frames.len())
        .step_by(2)
        .flat_map(|i| {
            let (u, v) = segments::section_axes(frames, i);
            let root = frames[i].o - frames[i].u * depth;
            [-u, v, -v, (v - u).normalize(), (-v - u).normalize()].map(|d| (root, d))
        })
        .collect()
}

/// The pieces the carve leaves of each band ([`segments::band_segments`]), largest first,
/// saying which bands come out in several.
fn carved_pieces(
    kin: &Kinematics,
    bands: &[Sweep],
    rims: &[Sweep],
    fields: &[Arc<DistanceField>],
    clearance: f64,
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    progress: &dyn Fn(&str),
) -> Vec<Vec<Segment>> {
    // What the carve leaves of each band: its swept distance less half the clearance.
    // Material survives at a sample where the swept distance is at least `bridge`; a
    // floor just below that gives the same verdicts and ends each search at the first
    // instant that removes the sample.
    let bridge = 0.5 * clearance + segments::BRIDGE_MM;
    let swept = SweptEach::new(kin, rims, Frame::Follower, Frame::Driver)
        .with_coarse_each(fields)
        .with_floor(bridge - 1e-9);
    let cap = bridge + PIECES_CAP_ABOVE_BRIDGE_MM;
    let carve = |p: Vec3| swept.value(p, cap) - 0.5 * clearance;
    bands
        .iter()
        .enumerate()
        .map(|(k, band)| {
            let segs = segments::band_segments(band, &carve);
            if segs.len() > 1 {
                progress(&format!(
                    "band {} (curve pair {}) comes out of the carve in {} pieces: one strut each",
                    k + 1,
                    pairs[k].0 + 1,
                    segs.len()
                ));
            }
            segs
        })
        .collect()
}

/// Join every piece of every band (`band_pieces`, from [`carved_pieces`]; nearest the hub
/// first) to the driver's hub: a band the rims' sweep cuts crosswise needs a strut per
/// piece. With `every_piece` false, only each band's largest piece (the others are left
/// out). A piece no strut can start from is left out and said so, even a band's largest:
/// the check judges what the pieces left give. A band none of whose pieces can be joined
/// is an error.
#[allow(clippy::too_many_arguments)]
fn plan_driver_struts(
    kin: &Kinematics,
    layout: &Layout,
    bands: &[Sweep],
    rims: &[Sweep],
    field: &DistanceField,
    pieces: &Pieces,
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    band_pieces: &[Vec<Segment>],
    clearance: f64,
    every_piece: bool,
    progress: &dyn Fn(&str),
) -> Result<Vec<ThickPolyline>, BuildError> {
    let mut joined = Joined::new(field.grid);
    joined_mark_first(&mut joined, pieces);
    let hub = Vec3::new(0.0, 0.0, 0.5 * (layout.driver_hub.0 + layout.driver_hub.1));
    let rims_swept = SweptEach::new(kin, rims, Frame::Follower, Frame::Driver);
    let rim_clearance = |p: Vec3| rims_swept.value(p, STRUT_RADIUS_MM + STRUT_MARGIN_MM + 1.0);
    // (band, piece number, piece), nearest the hub first.
    let mut items: Vec<(usize, usize, &Segment)> = Vec::new();
    for (k, segs) in band_pieces.iter().enumerate() {
        for (j, seg) in segs.iter().enumerate() {
            if seg.samples.len() >= MIN_PIECE_SAMPLES && (every_piece || j == 0) {
                items.push((k, j, seg));
            }
        }
    }
    let nearest = |s: &Segment| {
        s.roots
            .iter()
            .map(|p| (p - hub).norm())
            .fold(f64::INFINITY, f64::min)
    };
    items.sort_by(|a, b| nearest(a.2).total_cmp(&nearest(b.2)));
    let mut struts = Vec::new();
    let mut band_joined = vec![false; band_pieces.len()];
    // Why each band's largest piece could not be joined, when it could not.
    let mut band_why: Vec<Option<String>> = vec![None; band_pieces.len()];
    for (k, j, seg) in &items {
        let what = if *j == 0 {
            format!("band {} (curve pair {})", k + 1, pairs[*k].0 + 1)
        } else {
            format!(
                "piece {} of band {} (curve pair {})",
                j + 1,
                k + 1,
                pairs[*k].0 + 1
            )
        };
        // Struts leave a piece from behind it (along −n¹, away from the groove) or across
        // the band, towards the gap between the slabs.
        let frames = bands[*k].frames();
        let rays: Vec<(Vec3, Vec3)> = seg
            .frames
            .iter()
            .zip(&seg.roots)
            .step_by(2)
            .flat_map(|(&i, &root)| {
                let (u, v) = segments::section_axes(frames, i);
                [-u, v, -v, (v - u).normalize(), (-v - u).normalize()].map(|d| (root, d))
            })
            .collect();
        // First with the strut's whole section clear of the rims' sweep where it leaves;
        // failing that, with its core clear (the carve then trims the strut's flank there).
        let whole = STRUT_RADIUS_MM + ROOT_MARGIN_MM;
        let core = STRUT_CORE_MM + 0.5 * clearance;
        let blame = |points: &[Vec3]| rims_that_block(kin, rims, pairs, core, points);
        let planned = strut_from_rays(
            &rays,
            whole,
            false,
            field,
            &rim_clearance,
            &mut joined,
            hub,
            &what,
            None,
        )
        .or_else(|_| {
            strut_from_rays(
                &rays,
                core,
                false,
                field,
                &rim_clearance,
                &mut joined,
                hub,
                &what,
                Some(&blame),
            )
        });
        match planned {
            Ok(st) => {
                joined.mark_balls(&seg.samples, 0.5);
                struts.push(st);
                band_joined[*k] = true;
            }
            // A piece no strut can reach is left out of the driver (the mesher drops the
            // shells beyond the largest), and the check counts the contacts it carried as
            // lost: whether the mechanism still works is the check's closure to say, not
            // the planner's. Screw-bob's printable design has a band whose largest piece is
            // hemmed in by the rims' sweep while others of its pieces are joined.
            Err(BuildError::NoRoom { detail, .. }) => {
                progress(&format!("{what} stays loose: {detail}"));
                if *j == 0 {
                    band_why[*k] = Some(detail);
                }
            }
            Err(e) => return Err(e),
        }
    }
    // A band of which no piece is joined would leave its pair without a single contact,
    // and the search leaves out every pair the closure does not need (docs/synthesis.md),
    // so the check would fail it: say so now rather than after minutes of carving.
    for (k, why) in band_why.into_iter().enumerate() {
        if let (false, Some(why)) = (band_joined[k], why) {
            let tried = items.iter().filter(|(b, _, _)| *b == k).count();
            return Err(BuildError::NoRoom {
                what: format!("band {} (curve pair {})", k + 1, pairs[k].0 + 1),
                detail: if tried > 1 {
                    format!("none of its {tried} pieces can be; from the largest, {why}")
                } else {
                    why
                },
            });
        }
    }
    Ok(struts)
}

/// Radius of a driver strut's core that must survive the carve where the strut leaves a
/// piece of band hemmed in by the rims' sweep, mm: a 2 mm round core, five perimeters of a
/// 0.4 mm nozzle.
const STRUT_CORE_MM: f64 = 1.0;

/// Pieces of a band with fewer samples than this are crumbs, not given a strut: under
/// a millimetre of band (the mesh keeps them only if they hold a functional point, and then
/// reports the driver in pieces).
const MIN_PIECE_SAMPLES: usize = 8;

fn joined_mark_first(j: &mut Joined, p: &Pieces) {
    if let Some(a) = p.add.first() {
        j.mark_solid(a.as_ref());
    }
}

/// Clearance of a follower point from the driver's swept bands (exact where it matters) and
/// from the driver's hub, column, struts and the support (coarse).
pub struct BandClearance {
    kin: Arc<Kinematics>,
    bands: Vec<Sweep>,
    /// Coarse swept distance of each band (follower frame).
    band_fields: Vec<DistanceField>,
    others: Arc<DistanceField>,
}

impl BandClearance {
    /// The clearance at `p`, exact (for the bands) whenever it is below `need` and above
    /// `floor`; some value not below `need` otherwise, or `floor` where it is not above
    /// that (found at the first band and instant that show it). A band's exact sweep runs
    /// only where its coarse field (a lower bound) does not already settle the question.
    pub fn below(&self, p: Vec3, need: f64, floor: f64) -> f64 {
        self.below_via(p, need, floor, None)
    }

    /// [`BandClearance::below`], each band's search started from `certificates[k]` when
    /// given (one lattice per band).
    fn below_via(
        &self,
        p: Vec3,
        need: f64,
        floor: f64,
        certificates: Option<&[Certificates]>,
    ) -> f64 {
        let mut c = self.others.sample(p);
        // Nearest band by its bound first: its value caps the searches of the others, and
        // once a band's bound is not below the value so far, no later one's is.
        for (coarse, k) in nearest_first(&self.band_fields, p) {
            if c <= floor {
                return floor;
            }
            let bound = need.min(c);
            if coarse >= bound {
                break;
            }
            let band = &self.bands[k];
            let sweep = ExactSweep {
                kin: &self.kin,
                solid: band,
                frame: Frame::Driver,
                target: Frame::Follower,
                cap: bound,
                floor,
            };
            let exact = match certificates {
                Some(lattices) => lattices[k].value(&sweep, p),
                None => sweep.value(p),
            };
            c = c.min(exact);
        }
        c.max(floor)
    }
}

/// A [`BandClearance`] whose searches start from certificates (`swept::Certificates`, one
/// lattice per band), for the many nearby points of one meshing: the webs' feet and the
/// rooted struts' points lie close together, and each search then reopens only what its
/// lattice cell's certificate could not rule out. Values at or below `cap` are those of
/// [`BandClearance::below`] within the sweep's search tolerance (0.1 mm).
struct SharedClearance {
    clear: Arc<BandClearance>,
    certificates: Vec<Certificates>,
}

impl SharedClearance {
    /// Certificates for searches capped at `cap` or below (`need`s above it are searched
    /// on their own).
    fn new(clear: Arc<BandClearance>, cap: f64) -> SharedClearance {
        let certificates = clear
            .bands
            .iter()
            .map(|_| Certificates::new(CERTIFICATE_CELL_MM, cap))
            .collect();
        SharedClearance {
            clear,
            certificates,
        }
    }

    /// As [`BandClearance::below`].
    fn below(&self, p: Vec3, need: f64, floor: f64) -> f64 {
        self.clear
            .below_via(p, need, floor, Some(&self.certificates))
    }
}

/// 3R: plan the support's post from the ball's cup down to the base plate, around the
/// swept volumes of the follower's rims and webs and of the driver.
fn plan_post(
    kin: &Kinematics,
    layout: &Layout,
    follower: &[Balls],
    bands: &[Balls],
    driver: &Pieces,
    support: &mut Pieces,
) -> Result<(), BuildError> {
    let mut obstacles: Vec<Balls> = follower.to_vec();
    obstacles.extend(bands.iter().cloned());
    obstacles.extend(driver.cover.iter().cloned());
    // The grid: from the base up to the ball, as wide as the follower's reach.
    let r = layout.follower_reach + 20.0;
    let grid = crate::geometry::voxel::VoxelGrid::covering(
        Aabb::new([-r, -r, layout.base.1 - 5.0], [r, r, 20.0]),
        PLAN_VOXEL_MM,
    );
    let field = connect::clearance(kin, &obstacles, Frame::Reference, grid);
    let cup_out = BALL_RADIUS_MM + layout.clearance + CUP_WALL_MM;
    // Sources: points on a sphere just outside the cup, below the ball.
    let mut sources = Vec::new();
    for i in 0..40 {
        for j in 0..12 {
            let az = std::f64::consts::TAU * i as f64 / 40.0;
            let el = -std::f64::consts::FRAC_PI_2 + 0.12 * j as f64;
            let d = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let at = d * (cup_out + PILLAR_RADIUS_MM);
            sources.push(connect::Start { root: at, at });
        }
    }
    let mut base = Joined::new(grid);
    base.mark_solid(support.add[0].as_ref());
    let post = connect::strut(
        &field,
        &base,
        &sources,
        Vec3::new(0.0, 0.0, layout.base.1),
        "the support's post to the ball joint",
    )?;
    let start = post.points[0];
    let dir = start.normalize();
    // The cup: a shell around the ball, open away from the post, joined to the post.
    let cup = Cup {
        axis: dir,
        inner: BALL_RADIUS_MM + 0.5 * layout.clearance,
        outer: cup_out,
        half_angle: CUP_HALF_ANGLE_DEG.to_radians(),
    };
    support.cover.push(Balls {
        frame: Frame::Reference,
        centers: vec![dir * (0.5 * (cup.inner + cup.outer))],
        radius: cup.outer,
    });
    let mut pts = vec![dir * (cup.inner + 0.5 * CUP_WALL_MM)];
    pts.extend(post.points.iter().copied());
    let post = ThickPolyline {
        points: pts,
        radius: PILLAR_RADIUS_MM - 1.0,
    };
    support
        .cover
        .push(connect::strut_cover(&post, Frame::Reference));
    support.add.push(Arc::new(cup));
    support.add.push(Arc::new(post));
    Ok(())
}

/// Half-angle of the cup around the 3R ball, measured from the post's direction. 65°: the
/// cup reaches past the ball's equator on the post's side only, so the follower's struts
/// keep most of the sphere of directions.
const CUP_HALF_ANGLE_DEG: f64 = 65.0;

/// A spherical cup: the shell between two radii about the origin, within a cone of
/// directions around `axis`.
struct Cup {
    axis: Vec3,
    inner: f64,
    outer: f64,
    half_angle: f64,
}

impl Sdf for Cup {
    fn dist(&self, p: Vec3) -> f64 {
        let r = p.norm();
        let shell = (r - self.outer).max(self.inner - r);
        // Distance to the cone's boundary (a bound): r·sin(angle beyond the half angle).
        let cosang = if r > 0.0 { p.dot(&self.axis) / r } else { 1.0 };
        let ang = cosang.clamp(-1.0, 1.0).acos();
        let cone = if ang - self.half_angle >= std::f64::consts::FRAC_PI_2 {
            r
        } else {
            r * (ang - self.half_angle).sin()
        };
        shell.max(cone)
    }
    fn bounds(&self) -> Aabb {
        Aabb::new([-self.outer; 3], [self.outer; 3])
    }
}

/// Place the BNO055 pad (and an end-effector post beyond it) on the follower where the
/// driver and support never pass: along +z first, then other directions.
fn place_imu_pad(field: &DistanceField, p: &mut Pieces) -> Result<(), BuildError> {
    let half_diag = 0.5 * IMU_PAD_MM[0].hypot(IMU_PAD_MM[1]);
    let need = half_diag + SUPPORT_MARGIN_MM;
    let dirs = [
        Vec3::z(),
        Vec3::new(0.0, 0.5, 1.0),
        Vec3::new(0.0, -0.5, 1.0),
        Vec3::new(-0.5, 0.0, 1.0),
        Vec3::new(-1.0, 0.0, 0.3),
        Vec3::new(0.0, 1.0, 0.3),
        Vec3::new(0.0, -1.0, 0.3),
        -Vec3::z(),
    ];
    for d in dirs {
        let Some(c) = connect::free_spot(field, d, 15.0, 150.0, need) else {
            continue;
        };
        let d = d.normalize();
        // The pad lies across d; the end-effector post continues along d.
        let rot = nalgebra::Rotation3::rotation_between(&Vec3::z(), &d)
            .unwrap_or_else(nalgebra::Rotation3::identity);
        let pad = crate::geometry::sdf::Cuboid {
            center: c,
            half: Vec3::new(0.5 * IMU_PAD_MM[0], 0.5 * IMU_PAD_MM[1], 1.5),
            rotation: rot,
        };
        let post = Cylinder {
            base: c,
            axis: d,
            length: 15.0,
            radius: 3.0,
        };
        p.cover.push(Balls {
            frame: Frame::Follower,
            centers: vec![c],
            radius: half_diag + 2.0,
        });
        p.cover.push(cover_cylinder(&post, Frame::Follower));
        p.add.push(Arc::new(pad));
        p.add.push(Arc::new(post));
        let sp = 0.5 * IMU_HOLE_SPACING_MM;
        for s in [-sp, sp] {
            p.cut.push(Arc::new(Cylinder {
                base: c + rot * Vec3::new(s, 0.0, -3.0),
                axis: d,
                length: 6.0,
                radius: 1.35,
            }));
        }
        // M3 hole at the end-effector's tip.
        p.cut.push(Arc::new(Cylinder {
            base: c + d * 9.0,
            axis: d,
            length: 7.0,
            radius: 1.25,
        }));
        return Ok(());
    }
    Err(BuildError::NoRoom {
        what: "the IMU pad".into(),
        detail: "no direction from the ball has 30 mm of space the driver never enters".into(),
    })
}

/// A strut from behind a rim to what its part has joined so far, aimed at `toward`: roots
/// `depth` mm behind the curve along −u at every second frame, the strut's first segment
/// kept [`ROOT_MARGIN_MM`] clear of `exact` (see [`strut_from_rays`]).
fn strut_from_behind(
    sweep: &Sweep,
    depth: f64,
    field: &DistanceField,
    exact: &(dyn Fn(Vec3) -> f64 + Sync),
    joined: &mut connect::Joined,
    toward: Vec3,
    what: &str,
) -> Result<ThickPolyline, BuildError> {
    let rays: Vec<(Vec3, Vec3)> = sweep
        .frames()
        .iter()
        .step_by(2)
        .map(|f| (f.o - f.u * depth, -f.u))
        .collect();
    let root_clearance = STRUT_RADIUS_MM + ROOT_MARGIN_MM;
    strut_from_rays(
        &rays,
        root_clearance,
        false,
        field,
        exact,
        joined,
        toward,
        what,
        None,
    )
}

/// Says which of the other part's functional surfaces stopped rays at these points (see
/// [`rims_that_block`]).
type Blame<'a> = &'a (dyn Fn(&[Vec3]) -> String + Sync);

/// [`connect::strut`] from the starts the rays found; when they found none, the error says
/// what stopped the rays (and `blame`, given, whose surfaces).
fn strut_from_starts(
    field: &DistanceField,
    joined: &connect::Joined,
    starts: &connect::RayStarts,
    toward: Vec3,
    what: &str,
    blame: Option<Blame>,
) -> Result<ThickPolyline, BuildError> {
    connect::strut(field, joined, &starts.starts, toward, what).map_err(|e| match e {
        BuildError::NoRoom { what, .. } if starts.starts.is_empty() => BuildError::NoRoom {
            what,
            detail: match blame {
                Some(b) if !starts.blocked_at.is_empty() => {
                    format!("{} ({})", starts.none_detail(), b(&starts.blocked_at))
                }
                _ => starts.none_detail(),
            },
        },
        e => e,
    })
}

/// Which of `solids` (rims or bands, `noun`), swept from frame `from` through `to`, come
/// within `clearance` of the points where rays were stopped, with how many rays each stops
/// (a ray may count for several): "rays stopped by the sweep of pair 6's rim (310), pair
/// 5's rim (40)", the pairs numbered as in the file; `none` when no single one does. The
/// synthesis's island test counts only a pair's own rim (docs/synthesis.md), so this says
/// whether another pair's rim is what hems a piece in.
#[allow(clippy::too_many_arguments)]
fn sweeps_that_block(
    kin: &Kinematics,
    solids: &[Sweep],
    (from, to): (Frame, Frame),
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    noun: &str,
    none: &str,
    clearance: f64,
    points: &[Vec3],
) -> String {
    let mut counts: Vec<(usize, usize)> = solids
        .iter()
        .enumerate()
        .map(|(k, solid)| {
            let swept = SweptEach::new(kin, std::slice::from_ref(solid), from, to);
            let n = points
                .iter()
                .filter(|&&p| swept.value(p, clearance) < clearance)
                .count();
            (pairs[k].0 + 1, n)
        })
        .filter(|&(_, n)| n > 0)
        .collect();
    counts.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let parts: Vec<String> = counts
        .iter()
        .map(|(pair, n)| format!("pair {pair}'s {noun} ({n})"))
        .collect();
    if parts.is_empty() {
        none.to_string()
    } else {
        format!("rays stopped by the sweep of {}", parts.join(", "))
    }
}

/// [`sweeps_that_block`] for the rims seen from the driver.
fn rims_that_block(
    kin: &Kinematics,
    rims: &[Sweep],
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    clearance: f64,
    points: &[Vec3],
) -> String {
    sweeps_that_block(
        kin,
        rims,
        (Frame::Follower, Frame::Driver),
        pairs,
        "rim",
        "no single rim's sweep stops them",
        clearance,
        points,
    )
}

/// A strut from one of `rays` (root, direction away from the contact) to what its part has
/// joined so far, aimed at `toward`; `exact` stays at least `root_clearance` along the ray
/// up to the start, from the root itself when the strut is `trimmed` by that clearance
/// ([`connect::ray_starts`]); the strut is marked joined.
#[allow(clippy::too_many_arguments)]
fn strut_from_rays(
    rays: &[(Vec3, Vec3)],
    root_clearance: f64,
    trimmed: bool,
    field: &DistanceField,
    exact: &(dyn Fn(Vec3) -> f64 + Sync),
    joined: &mut connect::Joined,
    toward: Vec3,
    what: &str,
    blame: Option<Blame>,
) -> Result<ThickPolyline, BuildError> {
    let starts = connect::ray_starts(rays, field, exact, root_clearance, RAY_REACH_MM, trimmed);
    let st = strut_from_starts(field, joined, &starts, toward, what, blame)?;
    joined.mark_balls(&connect::polyline_points(&st, 0.5), st.radius);
    Ok(st)
}

impl Design {
    /// The follower as printed (shrunk by half the clearance), follower frame.
    ///
    /// Each solid is shrunk on its own and each cut grown, not the whole: shrinking a union
    /// by c/2 takes c/2 off the value inside it, and a union's value inside is that of the
    /// first member holding the point ([`Union`]'s `dist`), not the deepest. Where a web or
    /// strut entered the column, a point deep in the column but near the web's face took
    /// the web's shallow value, and the shrink turned it outside: a slab c/2 thick cut out
    /// of the column at every web (at 1 mm clearance half-turn-2to1's follower came out in
    /// 14 pieces; at 0.2 mm, shells of tiny voids). The union of shrunk members, less the
    /// grown cuts, is the shrink of the whole wherever members do not overlap, and at
    /// most c/2 thinner where they meet at an angle.
    pub fn follower_solid(&self) -> impl Sdf + '_ {
        let half = 0.5 * self.clearance;
        let shrunk = |s: Box<dyn Sdf>| -> Box<dyn Sdf> {
            Box::new(Offset {
                inner: s,
                by: -half,
            })
        };
        let mut add: Vec<Box<dyn Sdf>> = self.rims.iter().cloned().map(boxed).map(shrunk).collect();
        // Exact within CARVE_CAP_CELLS cells of the surface after the shrink.
        let far = CARVE_CAP_CELLS * self.cell_mm + half;
        // The largest `need` either trim asks for (the through cut's exceeds the margin's).
        let clear = Arc::new(SharedClearance::new(
            self.band_clearance.clone(),
            WEB_THROUGH_CUT_MM.max(WEB_MARGIN_MM) + far,
        ));
        // Core-rooted struts, trimmed clear of the driver's swept bands.
        let kept_clear = |solid: Arc<dyn Sdf>| -> Box<dyn Sdf> {
            shrunk(Box::new(KeptClear {
                solid,
                clear: clear.clone(),
                far,
            }))
        };
        // Webs are cut through their whole thickness (`WebCut`), not shaved.
        add.extend(self.webs.iter().map(|w| -> Box<dyn Sdf> {
            shrunk(Box::new(WebCut {
                web: w.clone(),
                clear: clear.clone(),
                far,
            }))
        }));
        for s in &self.follower_struts {
            add.push(shrunk(Box::new(s.clone())));
        }
        add.extend(
            self.follower_rooted
                .iter()
                .map(|s| kept_clear(Arc::new(s.clone()))),
        );
        add.extend(
            self.follower_pieces
                .add
                .iter()
                .map(|a| shrunk(boxed(a.clone()))),
        );
        let cut: Vec<Box<dyn Sdf>> = self
            .follower_pieces
            .cut
            .iter()
            .map(|c| -> Box<dyn Sdf> {
                Box::new(Offset {
                    inner: c.clone(),
                    by: half,
                })
            })
            .collect();
        Difference::new(Box::new(Union::new(add)), cut)
    }

    /// The nominal driver material before carving (driver frame).
    fn driver_material(&self) -> Union {
        let mut add: Vec<Box<dyn Sdf>> = self.bands.iter().cloned().map(boxed).collect();
        for s in &self.driver_struts {
            add.push(Box::new(s.clone()));
        }
        add.extend(self.driver_pieces.add.iter().map(|a| boxed(a.clone())));
        Union::new(add)
    }

    /// The driver as printed: its material minus the rims' exact swept volume grown by
    /// half the clearance, minus its bores (driver frame).
    pub fn driver_solid(&self) -> DriverSolid<'_> {
        DriverSolid {
            material: self.driver_material(),
            design: self,
            certificates: self
                .carve_rims
                .iter()
                .map(|_| Certificates::new(CERTIFICATE_CELL_MM, self.carve_cap()))
                .collect(),
        }
    }

    /// The largest swept distance of the rims the carve computes exactly, mm: beyond it the
    /// driver's value is more than [`CARVE_CAP_CELLS`] cells outside the groove.
    fn carve_cap(&self) -> f64 {
        let cap = CARVE_CAP_CELLS * self.cell_mm + 0.5 * self.clearance;
        debug_assert!(cap <= carve_reach(self.cell_mm, self.clearance));
        cap
    }

    /// The support (reference frame).
    pub fn support_solid(&self) -> impl Sdf + '_ {
        let add: Vec<Box<dyn Sdf>> = self
            .support_pieces
            .add
            .iter()
            .map(|a| boxed(a.clone()))
            .collect();
        let cut: Vec<Box<dyn Sdf>> = self
            .support_pieces
            .cut
            .iter()
            .map(|c| boxed(c.clone()))
            .collect();
        Difference::new(Box::new(Union::new(add)), cut)
    }
}

/// A strut rooted by its core, trimmed point by point clear of the driver's swept bands,
/// for the mesher: inside it, values more than `far` from zero are only said to be that
/// far.
struct KeptClear {
    /// The strut.
    solid: Arc<dyn Sdf>,
    /// Its clearance from the driver's swept bands (and the rest of the driver).
    clear: Arc<SharedClearance>,
    /// Beyond this, mm, a value needs no more than its sign and that it is this far: the
    /// mesher reads magnitudes only near the surface (as the driver's carve,
    /// [`CARVE_CAP_CELLS`] cells), and the union and difference the solid enters keep a
    /// value that is at least this far (in either direction) at least this far. The shrink
    /// by half the clearance moves every value by that much, so the follower passes
    /// that half on top ([`Design::follower_solid`]).
    far: f64,
}

impl Sdf for KeptClear {
    fn dist(&self, p: Vec3) -> f64 {
        let v = self.solid.dist(p);
        if v > 0.0 {
            return v;
        }
        // max(v, margin − clearance) differs from v only when clearance < margin − v, and
        // is at most −far wherever both are; it is at least far wherever the clearance is
        // at most margin − far, which the search stops at.
        let need = (WEB_MARGIN_MM - v).min(WEB_MARGIN_MM + self.far);
        v.max(WEB_MARGIN_MM - self.clear.below(p, need, WEB_MARGIN_MM - self.far))
    }
    fn bounds(&self) -> Aabb {
        self.solid.bounds()
    }
}

/// A web kept clear of the driver's swept bands by cuts through its whole thickness, for
/// the mesher: a point of the plate is kept where the clearance at its foot on the plate's
/// mid-surface is at least [`WEB_THROUGH_CUT_MM`]; inside, values more than `far` from
/// zero are only said to be that far (as [`KeptClear`]).
///
/// A web trimmed point by point ([`KeptClear`]) is shaved wherever the bands' sweep passes
/// the plate at a slant or along it, leaving part of its thickness as a film that a slicer
/// prints as stringy islands or not at all (a test finds such films on half-turn-2to1's
/// webs). Cut through, a web keeps its full thickness or is not there, and each cut's edge
/// stands square to the plate. (Most of the "lace" of the webs until 2026-12-05 was not
/// the trim but voids: `ThickTriangles`' value inside.)
struct WebCut {
    /// The web.
    web: Arc<ThickTriangles>,
    /// Its clearance from the driver's swept bands (and the rest of the driver).
    clear: Arc<SharedClearance>,
    /// As [`KeptClear::far`].
    far: f64,
}

/// The clearance from the driver's swept bands a web's mid-surface keeps where the web is
/// kept, mm: the webs' margin plus their half thickness, so that every point of the plate,
/// at most the half thickness from its foot (the clearance is 1-Lipschitz), keeps the
/// margin, as the point-by-point trim did.
pub const WEB_THROUGH_CUT_MM: f64 = WEB_MARGIN_MM + WEB_HALF_THICKNESS_MM;

impl Sdf for WebCut {
    fn dist(&self, p: Vec3) -> f64 {
        // One search gives the plate's value and, inside it, the foot. Outside the plate
        // that value is the web's own (`ThickTriangles::dist`, which also falls back to
        // the box beyond where values are exact).
        let Some((foot, v)) = self.web.nearest_below(p, SWEEP_EXACT_WITHIN_MM) else {
            return self.web.dist(p);
        };
        if v >= 0.0 {
            return v;
        }
        // max(v, cut − clearance at the foot), the clearance needed only below cut − v
        // (as in `KeptClear`).
        let cut = WEB_THROUGH_CUT_MM;
        let need = (cut - v).min(cut + self.far);
        v.max(cut - self.clear.below(foot, need, cut - self.far))
    }
    fn bounds(&self) -> Aabb {
        self.web.bounds()
    }
}

/// The driver as printed (see [`Design::driver_solid`]).
pub struct DriverSolid<'a> {
    material: Union,
    design: &'a Design,
    /// One lattice per part of a rim (`Design::carve_rims`): each is swept on its own, so
    /// that the search's bound on how fast the distance changes is that part's
    /// (`Sdf::lipschitz`: the rims of half-turn-2to1 range from 1.004 to 2.84, their mild
    /// parts stay at or below 1.2, and a union would take the largest).
    certificates: Vec<Certificates>,
}

impl Sdf for DriverSolid<'_> {
    fn dist(&self, p: Vec3) -> f64 {
        let m = self.material.dist(p);
        let cap = self.design.carve_cap();
        let half = 0.5 * self.design.clearance;
        let v = if m >= cap {
            m
        } else {
            // max(m, half − s) is m wherever s ≥ half − m: the search need only tell that,
            // and a lower cap rules out more of the period (outside the material, and
            // just inside it, far more). Each part's search is capped by the smallest
            // distance found so far. Where s ≤ half − cap the point lies in the groove's
            // air at least the cap from its surface, a value that is capped as well: the
            // search stops at the first instant that shows it.
            let swept = SweptEach::new(
                &self.design.kin,
                &self.design.carve_rims,
                Frame::Follower,
                Frame::Driver,
            )
            .with_coarse_each(&self.design.carve_fields)
            .with_certificates(&self.certificates)
            .with_floor(half - cap)
            .value(p, cap.min(half - m));
            m.max(half - swept)
        };
        self.design
            .driver_pieces
            .cut
            .iter()
            .fold(v, |acc, c| acc.max(-c.dist(p)))
    }
    fn bounds(&self) -> Aabb {
        self.material.bounds()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::tests::half_turn;

    /// Guards the two facts synthesis's plate test (`synth::undercut::plate_escapes`) takes
    /// from the planner: where a plate's strut takes root behind its rim, and the clearance
    /// its core needs from there at the default print clearance. Were they to differ,
    /// synthesis would judge rays the planner never casts, or by another need.
    #[test]
    fn plates_root_where_synthesis_tests_them() {
        let planner = RIM_DEPTH_MM + ROOT_DEPTH_MM;
        assert!((planner - crate::synth::undercut::PLATE_ROOT_MM).abs() < 1e-9);
        // And how clear of the bands' sweep a strut rooted by its core must leave it.
        let core = STRUT_CORE_MM + WEB_MARGIN_MM + 0.5 * DEFAULT_CLEARANCE_MM;
        assert!((core - crate::synth::undercut::PLATE_CLEARANCE_MM).abs() < 1e-9);
    }

    /// Guards what a loose piece's message blames: a point on one rim, posed in the driver's
    /// frame at some instant, is within the clearance of that rim's sweep (and named by its
    /// pair's number in the file), a point far from every rim of none.
    #[test]
    fn the_rims_that_stop_a_ray_are_named_by_pair() {
        let (mech, kin) = half_turn();
        let pairs: Vec<(usize, &crate::synth::mechanism::CurvePair)> =
            mech.curve_pairs.iter().enumerate().collect();
        let rims: Vec<Sweep> = pairs
            .iter()
            .map(|(_, cp)| shapes::rim(cp, kin.scale_mm()).unwrap())
            .collect();
        // A point inside pair 2's rim (0.5 mm behind its apex at frame 0), posed in the
        // driver's frame at t = 0.3: inside that rim's sweep.
        let q = rims[1].frames()[0].o - rims[1].frames()[0].u * 0.5;
        let p = kin.follower_to_driver(0.3) * nalgebra::Point3::from(q);
        let far = Vec3::new(1e3, 1e3, 1e3);
        let text = rims_that_block(&kin, &rims, &pairs, 1.1, &[p.coords, p.coords, far]);
        assert!(
            text.starts_with("rays stopped by the sweep of pair 2's rim (2)"),
            "{text}"
        );
        assert_eq!(
            rims_that_block(&kin, &rims, &pairs, 1.1, &[far]),
            "no single rim's sweep stops them"
        );
    }

    /// Guards the follower's shrink by half the clearance against the union's first-holder
    /// values: at 1 mm clearance every point of the follower's column, which webs and struts
    /// enter at each plate, stays inside the follower; before, the column was cut at every
    /// web it met (the follower of `demo --clearance 1` came out in 14 pieces). Only the
    /// sign is asked: inside, a union's value is its first holder's, not the deepest. And
    /// the rod's bore is the rod plus one clearance wide.
    #[test]
    fn the_shrunk_follower_keeps_its_column_whole() {
        let mech = crate::build::tests::printable_mechanism();
        let opts = BuildOptions {
            clearance_mm: 1.0,
            ..BuildOptions::default()
        };
        let kin = Arc::new(Kinematics::new(&mech, mech.scale_mm).unwrap());
        let bench = Bench::default_for(mech.class);
        let d = design(&mech, kin, &bench, &opts, &|_| {}).unwrap();
        // From above the rod's bore (1 mm over the hub's top, grown by half the clearance)
        // into the magnet cap, short of its pocket, every 0.1 mm: the slabs the old shrink
        // cut were 0.5 mm thick on each face of each web.
        let (_, hub_top) = d.layout.follower_hub.expect("a 1R follower has a hub");
        let (_, cap_top) = d
            .layout
            .cap
            .expect("the stepper bench's follower has a magnet cap");
        let (z0, z1) = (hub_top + 2.0, cap_top - MAGNET_THICKNESS_MM - 1.0);
        let f = d.follower_solid();
        let n = ((z1 - z0) / 0.1) as usize;
        let outside: Vec<f64> = (0..=n)
            .map(|i| z0 + (z1 - z0) * i as f64 / n as f64)
            .filter(|&z| f.dist(Vec3::new(0.0, 0.0, z)) >= 0.0)
            .collect();
        assert!(
            outside.is_empty(),
            "{} of {} points of the column's axis are outside the follower, e.g. z = {:?} mm",
            outside.len(),
            n + 1,
            &outside[..outside.len().min(5)]
        );
        // The rod's bore in the hub is the rod plus the clearance wide: the shrink's half
        // on each side, not the 1.5 clearances it once had.
        let (hub_bottom, _) = d.layout.follower_hub.unwrap();
        let z = 0.5 * (hub_bottom + hub_top);
        let bore = 0.5 * (FOLLOWER_SHAFT_MM + opts.clearance_mm);
        for (r, inside) in [(bore - 0.05, false), (bore + 0.05, true)] {
            let v = f.dist(Vec3::new(r, 0.0, z));
            assert_eq!(v < 0.0, inside, "{r} mm off the axis at z = {z}: {v}");
        }
    }

    /// Guards the column's last stretch (e2ca13f): a follower column that stops 0.5 mm
    /// under the magnet cap (half-turn-2to1's printable design) or 1.1 mm under it
    /// (screw-bob's K = 7) is carried 1 mm into it, so the cap is not left loose; one that
    /// stops farther short than [`COLUMN_REACH_TO_CAP_MM`], or already reaches the cap, or
    /// a follower without a cap, is left as planned.
    #[test]
    fn a_column_just_short_of_the_cap_is_carried_into_it() {
        let top = |c: &Cylinder| c.base.z + c.length;
        let planned = |z1: f64| Cylinder::z(0.0, 0.0, 10.0, z1, COLUMN_RADIUS_MM);
        for z1 in [59.5, 59.0, 58.9] {
            assert!((top(&reach_cap(planned(z1), Some(60.0))) - 61.0).abs() < 1e-12);
        }
        for (z1, cap0) in [(57.0, Some(60.0)), (62.0, Some(60.0)), (59.5, None)] {
            let c = reach_cap(planned(z1), cap0);
            assert_eq!(top(&c), z1, "column to {z1}, cap at {cap0:?}");
        }
    }

    /// half-turn-2to1's clearance from the driver's swept bands (nothing else), its
    /// mechanism and its rims.
    fn half_turn_band_clearance() -> (Mechanism, Vec<Sweep>, BandClearance) {
        let (mech, kin) = half_turn();
        let kin = Arc::new(kin);
        let bands: Vec<Sweep> = mech
            .curve_pairs
            .iter()
            .map(|cp| shapes::band(cp, 10.0).unwrap())
            .collect();
        let rims: Vec<Sweep> = mech
            .curve_pairs
            .iter()
            .map(|cp| shapes::rim(cp, 10.0).unwrap())
            .collect();
        let rim_covers: Vec<Balls> = rims
            .iter()
            .map(|r| shapes::sweep_cover(r, Frame::Follower))
            .collect();
        let grid = connect::grid_around(
            &kin,
            &rim_covers.iter().collect::<Vec<_>>(),
            Frame::Follower,
        );
        let band_fields = bands
            .iter()
            .map(|b| {
                let cover = shapes::sweep_cover(b, Frame::Driver);
                connect::clearance(&kin, std::slice::from_ref(&cover), Frame::Follower, grid)
            })
            .collect();
        let clear = BandClearance {
            kin: kin.clone(),
            bands,
            band_fields,
            // Nothing else of the driver near (a field of no obstacles would be infinite,
            // and its interpolation NaN).
            others: Arc::new(DistanceField {
                grid,
                values: vec![1e3; grid.len()],
                outside: 1e3,
            }),
        };
        (mech, rims, clear)
    }

    /// Guards the webs' cut through their whole thickness ([`WebCut`]): on half-turn-2to1's
    /// webs, at feet on their mid-surface, the plate is kept across its whole thickness
    /// where the clearance from the driver's swept bands there is at least
    /// [`WEB_THROUGH_CUT_MM`] and cut across it where it is less; every point kept keeps
    /// [`WEB_MARGIN_MM`]. The point-by-point trim ([`KeptClear`]) leaves films on the same
    /// webs: feet where part of the thickness is kept and part cut.
    #[test]
    fn webs_are_cut_through_their_whole_thickness() {
        let (_, rims, clear) = half_turn_band_clearance();
        let clear = Arc::new(clear);
        let exact = |p: Vec3| clear.below(p, 10.0, f64::NEG_INFINITY);
        // The trims search from certificates, as the follower's meshing does.
        let shared = Arc::new(SharedClearance::new(
            clear.clone(),
            WEB_THROUGH_CUT_MM + 10.0,
        ));
        let h = WEB_HALF_THICKNESS_MM;
        let offsets = [-0.95 * h, -0.5 * h, 0.0, 0.5 * h, 0.95 * h];
        let (mut kept, mut cut, mut films) = (0, 0, 0);
        for rim in &rims {
            let (web, tris) = shapes::web(rim);
            let web = Arc::new(web);
            let through = WebCut {
                web: web.clone(),
                clear: shared.clone(),
                far: 10.0,
            };
            let shaved = KeptClear {
                solid: web.clone(),
                clear: shared.clone(),
                far: 10.0,
            };
            for (i, [a, b, c]) in tris.iter().enumerate().step_by(7) {
                let n = (b - a).cross(&(c - a)).normalize();
                for w in [[0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.3, 0.3, 0.4]] {
                    let foot = a * w[0] + b * w[1] + c * w[2];
                    let points = offsets.map(|s| foot + n * s);
                    // Only where the plate's points have this foot (not at a fold of the
                    // fan), and not at the edge of a cut.
                    let own = points.iter().all(|&p| {
                        web.nearest_within(p, 2.0 * h)
                            .is_some_and(|(f, _)| (f - foot).norm() < 1e-6)
                    });
                    let c_foot = exact(foot);
                    if !own || (c_foot - WEB_THROUGH_CUT_MM).abs() < 0.05 {
                        continue;
                    }
                    let keep = c_foot >= WEB_THROUGH_CUT_MM;
                    for &p in &points {
                        let v = through.dist(p);
                        assert_eq!(
                            v < 0.0,
                            keep,
                            "web triangle {i}, {p:?}: value {v}, clearance at the foot {c_foot}"
                        );
                        if keep {
                            assert!(exact(p) >= WEB_MARGIN_MM - 1e-9, "{p:?}: {}", exact(p));
                        }
                    }
                    if keep {
                        kept += 1;
                    } else {
                        cut += 1;
                    }
                    let signs: Vec<bool> = points.iter().map(|&p| shaved.dist(p) < 0.0).collect();
                    films += usize::from(signs.iter().any(|&s| s != signs[0]));
                }
            }
        }
        assert!(kept >= 20 && cut >= 20, "{kept} feet kept, {cut} cut");
        assert!(
            films > 0,
            "the point-by-point trim left no film to compare with"
        );
    }

    /// Guards the follower's floor ([`BandClearance::below`], which [`KeptClear`] asks with
    /// one): the clearance from the driver's swept bands is the one without a floor wherever
    /// that is above the floor, and the floor wherever it is not, at points around the
    /// follower's curves (in and out of the bands' sweep).
    #[test]
    fn band_clearance_above_its_floor_is_the_one_without() {
        let (mech, _, clear) = half_turn_band_clearance();
        let (need, floor) = (2.0, 0.0);
        let (mut deep, mut between) = (0, 0);
        for i in 0..200 {
            let c2s = &mech.curve_pairs[i % mech.curve_pairs.len()].samples.c2;
            let c2 = c2s[(i * 23) % c2s.len()];
            let off = Vec3::new(
                (i as f64 * 1.9).sin(),
                (i as f64 * 0.8).cos(),
                (i as f64 * 2.3).sin(),
            ) * 3.0;
            let p = Vec3::new(c2[0], c2[1], c2[2]) * 10.0 + off;
            let whole = clear.below(p, need, f64::NEG_INFINITY);
            let floored = clear.below(p, need, floor);
            if whole <= floor {
                deep += 1;
                assert_eq!(floored, floor, "at {p:?}: {whole} without the floor");
            } else {
                between += usize::from(whole < need);
                assert_eq!(floored, whole, "at {p:?}");
            }
        }
        assert!(
            deep >= 20 && between >= 20,
            "{deep} points deep, {between} between"
        );
    }
}
