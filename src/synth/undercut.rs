//! Contacts a printed pair keeps: where a pair's own rim, moving with the follower, cuts
//! its driver band at another instant and so removes the contact it is designed to make.
//!
//! The printed follower carries each curve c²ₖ as a rim (a half ellipse with its apex on
//! the curve and its major axis along the follower's outward normal n²ₖ, paper §5.3), and
//! the driver's band is carved by that rim over a whole period. A contact c¹ₖ(u) survives
//! the carve only if the rim never reaches past it at any other instant t: the classical
//! undercutting of gear design, which the paper's local conditions (Eq. 4) do not see. This
//! module owns that test on sampled curves, in model units, and the printed section it is
//! made for ([`RIM_DEPTH_MM`], [`RIM_HALF_WIDTH_MM`]; `build::dims` reads them from here).
//! It also finds the contacts the build cannot keep although no rim cuts them: runs of
//! band between two cuts that the rim's sweep hems in behind and on both sides, so no
//! strut can leave them ([`island_contacts`]), and a pair's whole follower plate when its
//! own band's sweep leaves no strut a way off it ([`plate_escapes`]). Synthesis drops all
//! of them before it judges closure, so a design closes with the contacts its parts keep;
//! `Mechanism::check` reports the same figure for a file. The rays of both tests are the
//! build planner's, and they count as free where the planner's coarse field would
//! ([`ESCAPE_FREE_MM`]).
//!
//! It tests each pair against its own rim and band only: another pair's lie in another
//! slab (the slabs are disjoint and `band_gap` apart), and the built parts' check
//! (`build::check`) measures every rim against every band on the meshes. It does not model
//! the follower's web or struts (the build plans those around the driver).

use super::math::{Mat3, V3};

/// Which form of this module's rules a printed-rim design was judged by: 2 since the
/// island test reaches as far as the build's rays, the plates' escape is tested and lost
/// runs are widened by [`LOST_EDGE_MM`] (2026-12-04); 3 since a plate's rays need
/// [`PLATE_CLEARANCE_MM`] from their root on (2026-12-05); 4 since the cut test steps along
/// each contact's path between instants ([`CUT_STEP_MM`], 2026-12-05). Caches of designs
/// (`demo`) key on it, so a design judged by older rules is synthesized again rather than
/// handed to a build that disowns it.
pub const RULES: u32 = 4;

/// Follower rim: half-ellipse semi-axis along the contact normal (how deep the rim is).
/// 3 mm: deep enough that the driver's groove walls hold it, shallow enough to fit the 5 mm
/// gaps between the bands at the default 10 mm per model unit.
pub const RIM_DEPTH_MM: f64 = 3.0;
/// Follower rim: half-ellipse semi-axis across the normal (half the rim's thickness).
/// 1.6 mm: a 3.2 mm rim is eight 0.4 mm perimeters, and the apex radius b²/a = 0.85 mm is
/// still well above the nozzle width.
pub const RIM_HALF_WIDTH_MM: f64 = 1.6;
/// Driver band: half width across the contact curve. 3.5 mm: a 7 mm band flanks the
/// 3.2 mm rim with 1.9 mm walls on each side of the groove.
pub const BAND_HALF_WIDTH_MM: f64 = 3.5;
/// Driver band: depth of material behind the contact (along the driver's inward normal).
/// 3.5 mm: more than two 1.2 mm walls below the groove bottom.
pub const BAND_DEPTH_MM: f64 = 3.5;
/// Driver band: how far the band stands out past the contact towards the follower (the
/// groove's depth before carving). 1.5 mm: half the rim depth, so the walls guide the rim
/// while the follower's web (at the rim's full depth) stays clear of them.
pub const BAND_LIP_MM: f64 = 1.5;
/// How far past a contact a rim must reach for the contact to count as cut, mm. 0.1 mm: the
/// built parts' check calls a contact lost when its gap exceeds the clearance by as much.
pub const CUT_TOLERANCE_MM: f64 = 0.1;
/// Longest step between two tests along a contact's path through the follower's frame, mm.
/// Between two of the file's instants a driver point moves about a millimetre past the rim,
/// and a rim can cut it for less than one sample: on screw-bob's K = 7 design, pair 3's
/// contacts at t = 0.264–0.283 are 0.104 mm deep a quarter sample after the instant three
/// samples earlier and 0.067 mm at that instant, and the build lost them. Passing the rim's
/// apex round (radius b²/a = 0.85 mm) a point's depth falls off as s²/(2 · 0.85 mm) either
/// side of its deepest, so tests 0.25 mm apart miss at most 0.25²/(8 · 0.85) ≈ 0.009 mm of
/// it, a tenth of [`CUT_TOLERANCE_MM`].
pub const CUT_STEP_MM: f64 = 0.25;
/// Most tests on one step of a contact's path between two instants: at [`CUT_STEP_MM`],
/// 16 mm of relative travel per sample, ten times the examples' fastest.
const MAX_CUT_STEPS: usize = 64;

/// How far along a driver band from a lost contact the contacts beside it are lost too,
/// mm: the built parts lose a little more than the tests, at the ends of the lost runs,
/// where the carve ends a groove or a piece is left out (the mesher rounds that edge on
/// 0.4 mm cells; that it is the cause is a reading, not measured). Measured against the
/// build's check (share of the period lost per pair): on screw-bob at K = 7 the test
/// without it said 58.1/10.3/18.9/35.0/19.2/27.5/32.8 %, with it 59.7/10.8/20.0/36.9/
/// 19.7/28.1/34.2 %, and the build measured 60.8/11.9/20.6/36.1/21.7/27.8/33.6 %; on
/// half-turn-2to1 at K = 5, 29.7/30.0/55.0 %, 30.6/30.6/55.6 % and 33.1/30.3/55.0 % for the
/// pairs that lose any. 2 mm overshot as many pairs as it matched.
pub const LOST_EDGE_MM: f64 = 1.5;

/// Where a strut leaves a band, behind its contact, mm: the build roots driver struts in
/// the deepest row of the carved band (`build::segments`), about 0.5 mm in front of the
/// band's 3.5 mm deep back face.
pub const ESCAPE_ROOT_MM: f64 = 3.0;
/// How far from its root a strut may have to run before it is in free space, mm: the
/// build's rays reach as far (`build::parts` reads it from here), so a piece this test
/// anchors is one the build can leave.
pub const ESCAPE_REACH_MM: f64 = 12.0;
/// The clearance a strut's core keeps from the rims' sweep where it leaves a band, mm: the
/// build's 1 mm core plus half the default 0.2 mm print clearance.
pub const ESCAPE_CLEARANCE_MM: f64 = 1.1;
/// How clear of the rims' sweep a point must be for a strut to run on from it, mm: the
/// build's strut radius plus its margin (2.2 + 1.2, `build::dims::STRUT_RADIUS_MM` and
/// `STRUT_MARGIN_MM`; a test there keeps the sum equal to this).
pub const ESCAPE_STRUT_MM: f64 = 3.4;
/// How much the build's planning field understates the rims' swept distance near a band,
/// mm. The planner finds a strut's start where its coarse field (a lower bound from a ball
/// cover of each rim on 1 mm voxels, `build::swept::swept_field`) reads
/// [`ESCAPE_STRUT_MM`], and along the rays that leave screw-bob's band 6 that field read
/// 2.35 mm (median; 10th–90th percentile 1.16–2.84) below the exact swept distance where
/// the latter was 3–7 mm. A ray this test calls free has to reach that far.
pub const PLANNER_UNDERSTATEMENT_MM: f64 = 2.4;
/// How clear of its rim's sweep a ray must get for the build to start a strut there, mm.
pub const ESCAPE_FREE_MM: f64 = ESCAPE_STRUT_MM + PLANNER_UNDERSTATEMENT_MM;

/// Where a strut leaves a follower plate, behind its rim's apex along −n², mm: the build
/// roots it 1 mm behind the rim's 3 mm deep flat side (`build::parts`; a test there keeps
/// the two equal).
pub const PLATE_ROOT_MM: f64 = 4.0;
/// Where a ray is tested between its root and its first millimetre, mm (the build's
/// `connect::ray_starts` reads it from here): half of it, so no stretch untested is
/// longer than the 1 mm steps beyond.
pub const ROOT_STEP_MM: f64 = 0.5;
/// The clearance from the band's sweep a strut leaving a plate keeps from its root on, mm:
/// where none leaves with its whole section clear, the build roots one by its 1 mm core
/// and trims it as the webs are (nothing within their 0.8 mm margin of the bands' sweep,
/// and half the 0.2 mm print clearance more), so the core survives only this far out
/// (`build::parts`; a test there keeps the two equal). Screw-bob's K = 7 design passed at
/// [`ESCAPE_CLEARANCE_MM`] from 1 mm out; its plate 6 strut's root was 0.6 mm from the
/// band's sweep and the rim came out of the build loose.
pub const PLATE_CLEARANCE_MM: f64 = 1.9;

/// The rim section in model units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RimSection {
    /// Semi-axis along the normal.
    pub depth: f64,
    /// Semi-axis across the normal.
    pub half_width: f64,
    /// Depth past a contact that cuts it.
    pub tolerance: f64,
    /// [`ESCAPE_ROOT_MM`] in model units.
    pub escape_root: f64,
    /// [`ESCAPE_REACH_MM`] in model units.
    pub escape_reach: f64,
    /// [`ESCAPE_CLEARANCE_MM`] in model units.
    pub escape_clearance: f64,
    /// [`ESCAPE_FREE_MM`] in model units.
    pub escape_free: f64,
    /// [`PLATE_ROOT_MM`] in model units.
    pub plate_root: f64,
    /// [`PLATE_CLEARANCE_MM`] in model units.
    pub plate_clearance: f64,
    /// [`LOST_EDGE_MM`] in model units.
    pub lost_edge: f64,
    /// [`CUT_STEP_MM`] in model units.
    pub cut_step: f64,
    /// The driver band's [`BAND_HALF_WIDTH_MM`] in model units.
    pub band_half_width: f64,
    /// [`BAND_DEPTH_MM`] in model units.
    pub band_depth: f64,
    /// [`BAND_LIP_MM`] in model units.
    pub band_lip: f64,
}

impl RimSection {
    /// The printed rim at `scale_mm` millimetres per model unit.
    pub fn printed(scale_mm: f64) -> Self {
        Self {
            depth: RIM_DEPTH_MM / scale_mm,
            half_width: RIM_HALF_WIDTH_MM / scale_mm,
            tolerance: CUT_TOLERANCE_MM / scale_mm,
            escape_root: ESCAPE_ROOT_MM / scale_mm,
            escape_reach: ESCAPE_REACH_MM / scale_mm,
            escape_clearance: ESCAPE_CLEARANCE_MM / scale_mm,
            escape_free: ESCAPE_FREE_MM / scale_mm,
            plate_root: PLATE_ROOT_MM / scale_mm,
            plate_clearance: PLATE_CLEARANCE_MM / scale_mm,
            lost_edge: LOST_EDGE_MM / scale_mm,
            cut_step: CUT_STEP_MM / scale_mm,
            band_half_width: BAND_HALF_WIDTH_MM / scale_mm,
            band_depth: BAND_DEPTH_MM / scale_mm,
            band_lip: BAND_LIP_MM / scale_mm,
        }
    }
}

/// One instant's rigid map from driver-local to follower-local coordinates: y = A·x + b.
#[derive(Clone, Copy, Debug)]
pub struct DriverToFollower {
    /// Rotation R₂ᵀ·Rz(φ).
    pub a: Mat3,
    /// Translation R₂ᵀ·(D − T₂).
    pub b: [f64; 3],
}

impl DriverToFollower {
    /// From the follower's rotation `r2` and translation `t2` in frame R, the driver angle
    /// `phi` and the driver axis offset `dx`.
    pub fn new(r2: &Mat3, t2: [f64; 3], phi: f64, dx: f64) -> Self {
        let rz = super::math::rz(phi);
        let a = std::array::from_fn(|r| {
            std::array::from_fn(|c| (0..3).map(|k| r2[k][r] * rz[k][c]).sum())
        });
        let b = V3::new(dx - t2[0], -t2[1], -t2[2]).rot_t(r2).vals();
        Self { a, b }
    }

    fn apply(&self, x: V3<f64>) -> V3<f64> {
        x.rot(&self.a) + V3::from(self.b)
    }

    /// The inverse map, follower-local to driver-local: x = Aᵀ·(y − b).
    fn unapply(&self, y: V3<f64>) -> V3<f64> {
        (y - V3::from(self.b)).rot_t(&self.a)
    }
}

/// Samples of the follower curve per chunk when pruning by bounding spheres.
const CHUNK: usize = 16;

/// The contacts of one pair that its own rim cuts.
///
/// `c2[i]`, `n2[i]` (follower-local curve and outward normal) and `c1[i]` (driver-local
/// curve) are sampled at the instants of `poses[i]`, evenly over one period. Returns, per
/// instant i, whether the rim at some other instant reaches more than `rim.tolerance` past
/// c¹(i). The rim's section at each sample is tested within half the distance to the
/// neighbouring samples along the tangent, so it is exact up to the curves' sampling. In
/// time, c¹(i)'s path through the follower's frame is taken straight between two instants
/// (the true path bows off that chord by r·θ²/8, about 0.006 mm at 150 mm from the
/// driver's axis and 1° per sample) and tested every `rim.cut_step` along it
/// ([`CUT_STEP_MM`]), so a cut shorter than one sample is seen.
pub fn cut_contacts(
    c2: &[[f64; 3]],
    n2: &[[f64; 3]],
    c1: &[[f64; 3]],
    poses: &[DriverToFollower],
    rim: &RimSection,
) -> Vec<bool> {
    let n = c2.len();
    if n < 3 || n2.len() != n || c1.len() != n || poses.len() != n {
        return vec![false; n];
    }
    let rims = Sections::new(c2, n2, rim.depth + rim.half_width);
    let mut cut = vec![false; n];
    for (i, pose) in poses.iter().enumerate() {
        let next = &poses[(i + 1) % n];
        for (u, flag) in cut.iter_mut().enumerate() {
            if *flag {
                continue;
            }
            let x = V3::from(c1[u]);
            let (from, to) = (pose.apply(x), next.apply(x));
            let steps = ((to - from).norm() / rim.cut_step).ceil() as usize;
            *flag = rims.any_along(from, to, steps.clamp(1, MAX_CUT_STEPS), |s, y| {
                s.cuts(y, rim)
            });
        }
    }
    cut
}

/// The contacts of one pair the printed parts lose: those its own rim cuts
/// ([`cut_contacts`]) and those left on islands of band ([`island_contacts`]), each run of
/// them widened by [`LOST_EDGE_MM`] along the band; all of them when no strut can leave the
/// pair's follower plate ([`plate_escapes`]). `n1[i]` is the driver-local outward normal;
/// the other arguments are as for [`cut_contacts`].
pub fn lost_contacts(
    c2: &[[f64; 3]],
    n2: &[[f64; 3]],
    c1: &[[f64; 3]],
    n1: &[[f64; 3]],
    poses: &[DriverToFollower],
    rim: &RimSection,
) -> Vec<bool> {
    if !plate_escapes(c2, n2, c1, n1, poses, rim) {
        return vec![true; c2.len()];
    }
    let cut = cut_contacts(c2, n2, c1, poses, rim);
    let island = island_contacts(c2, n2, c1, n1, poses, rim, &cut);
    let lost: Vec<bool> = cut.iter().zip(island).map(|(c, i)| *c || i).collect();
    widen_lost(&lost, c1, rim.lost_edge)
}

/// `lost` with every contact within arc length `edge` along c¹ of a lost one lost too
/// ([`LOST_EDGE_MM`]).
fn widen_lost(lost: &[bool], c1: &[[f64; 3]], edge: f64) -> Vec<bool> {
    let n = lost.len();
    if n < 2 || c1.len() != n || lost.iter().all(|l| *l) || lost.iter().all(|l| !l) {
        return lost.to_vec();
    }
    let step = |i: usize, j: usize| (V3::from(c1[i]) - V3::from(c1[j])).norm();
    let mut out = lost.to_vec();
    for i in (0..n).filter(|&i| lost[i]) {
        // Walk both ways from a lost contact until `edge` of arc is used up.
        for dir in [1, n - 1] {
            let (mut j, mut arc) = (i, 0.0);
            loop {
                let k = (j + dir) % n;
                arc += step(j, k);
                if arc > edge || lost[k] {
                    break;
                }
                out[k] = true;
                j = k;
            }
        }
    }
    out
}

/// The contacts that lie on islands of band: runs of contacts the rim does not cut (`cut`
/// from [`cut_contacts`]) from none of whose samples a strut could leave the band clear of
/// the rim's sweep, so the build can only leave them out.
///
/// From each contact, rays start [`ESCAPE_ROOT_MM`] behind it (along −n¹, the driver's
/// inward normal `n1` negated) and run up to [`ESCAPE_REACH_MM`] behind or across the band
/// (−n¹, ±v, −n¹ ± v with v = T̂¹ × n¹), testing points 1 mm apart, as the build's rays do
/// (`build::connect::ray_starts`). A ray is free when it reaches a point [`ESCAPE_FREE_MM`]
/// clear of the rim at every instant (where the build's planner sees room for a strut)
/// before any of its points comes within [`ESCAPE_CLEARANCE_MM`] of the rim at some instant
/// (where the carve would cut the strut's core). A run with one free ray is anchored. This
/// is the pair's own rim only, as [`cut_contacts`]; it does not see the follower's web,
/// struts or other rims, which the build plans around.
pub fn island_contacts(
    c2: &[[f64; 3]],
    n2: &[[f64; 3]],
    c1: &[[f64; 3]],
    n1: &[[f64; 3]],
    poses: &[DriverToFollower],
    rim: &RimSection,
    cut: &[bool],
) -> Vec<bool> {
    let n = c2.len();
    let mut island = vec![false; n];
    if n < 3 || n1.len() != n || cut.len() != n || cut.iter().all(|c| !c) {
        // Nothing cut: the band is whole and the build roots its strut anywhere.
        return island;
    }
    let rims = Sections::new(c2, n2, rim.depth + rim.half_width + rim.escape_free);
    let clear = Clear {
        need: rim.escape_clearance,
        from_root: false,
    };
    let free_from = |u: usize| -> bool {
        let c = V3::from(c1[u]);
        let nn = V3::from(n1[u]).unit();
        let t = (V3::from(c1[(u + 1) % n]) - V3::from(c1[(u + n - 1) % n])).unit();
        let v = t.cross(nn).unit();
        let root = c - nn.scalec(rim.escape_root);
        any_ray_free(root, -nn, v, poses, rim, clear, |pose, p, margin| {
            rims.near(pose.apply(p), rim, margin)
        })
    };
    // Runs of uncut contacts, cyclically, starting after a cut sample.
    let start = (0..n).find(|&i| cut[i]).unwrap_or(0);
    let mut i = 1;
    while i <= n {
        let u = (start + i) % n;
        if cut[u] {
            i += 1;
            continue;
        }
        let mut run = Vec::new();
        while i <= n && !cut[(start + i) % n] {
            run.push((start + i) % n);
            i += 1;
        }
        if !run.iter().any(|&u| free_from(u)) {
            for u in run {
                island[u] = true;
            }
        }
    }
    island
}

/// Whether a strut can leave the pair's follower plate clear of the pair's own driver band:
/// from some sample of c², a ray starting [`PLATE_ROOT_MM`] behind the curve (along −n²)
/// and running behind or across the rim (−n², ±v, −n² ± v with v = T̂² × n²) gets
/// [`ESCAPE_FREE_MM`] clear of the band's sweep through the follower frame before it comes
/// within [`PLATE_CLEARANCE_MM`] of it, from its root on, as in [`island_contacts`] with
/// the parts' roles swapped. The build's planner tries the same rays from its plates
/// (`build::parts`); a plate none of them leaves cannot be joined to the follower, and its
/// pair keeps nothing. That is the planner's last resort, a strut rooted by its core; the
/// planner first tries struts whose whole section is clear from 1 mm out, which need
/// nothing at the root, so this test may refuse a plate the planner could join that way.
/// The other way round, it sees only the pair's own band, where the planner sees every
/// band and the driver's hub, column and struts too.
/// The band is the uncarved one (as the planner sees it): its lip, which the rim's groove
/// removes, is counted as material.
pub fn plate_escapes(
    c2: &[[f64; 3]],
    n2: &[[f64; 3]],
    c1: &[[f64; 3]],
    n1: &[[f64; 3]],
    poses: &[DriverToFollower],
    rim: &RimSection,
) -> bool {
    let n = c2.len();
    if n < 3 || n2.len() != n || c1.len() != n || n1.len() != n || poses.len() != n {
        return true;
    }
    let reach = rim.band_depth.max(rim.band_lip).hypot(rim.band_half_width) + rim.escape_free;
    let bands = Sections::new(c1, n1, reach);
    let rims = Sections::new(c2, n2, 0.0);
    let clear = Clear {
        need: rim.plate_clearance,
        from_root: true,
    };
    rims.sections.iter().any(|sec| {
        let root = sec.apex - sec.normal.scalec(rim.plate_root);
        any_ray_free(
            root,
            -sec.normal,
            sec.binormal,
            poses,
            rim,
            clear,
            |pose, p, margin| bands.near_band(pose.unapply(p), rim, margin),
        )
    })
}

/// How close to an obstacle a ray may come before a strut's core would be cut (model
/// units), and whether that holds from the ray's root or from its first millimetre (the
/// build's `connect::ray_starts` with `from_root`).
#[derive(Clone, Copy)]
struct Clear {
    need: f64,
    from_root: bool,
}

/// Whether one of the planner's five rays from `root` (along `back`, ±`v` and the two
/// diagonals between) is free: on its points 1 mm apart, up to [`ESCAPE_REACH_MM`], it
/// reaches one that is `rim.escape_free` clear of an obstacle at every instant before any
/// comes within `clear.need` of it at some instant (nor, with `clear.from_root`, the root
/// or the point [`ROOT_STEP_MM`] out). `near(pose, p, margin)` says whether `p` lies within
/// `margin` of the obstacle at the instant of `pose`.
fn any_ray_free(
    root: V3<f64>,
    back: V3<f64>,
    v: V3<f64>,
    poses: &[DriverToFollower],
    rim: &RimSection,
    clear: Clear,
    near: impl Fn(&DriverToFollower, V3<f64>, f64) -> bool,
) -> bool {
    // One millimetre in model units: the spacing of the points tested along a ray.
    let step = rim.escape_reach / ESCAPE_REACH_MM;
    let steps = ESCAPE_REACH_MM.floor() as usize;
    // Whether a strut may run on from `p` (Some(true)), its core would be cut there
    // (Some(false)), or neither (None: the ray goes on).
    let verdict = |p: V3<f64>| -> Option<bool> {
        let mut free = true;
        for pose in poses {
            if near(pose, p, rim.escape_free) {
                if near(pose, p, clear.need) {
                    return Some(false);
                }
                free = false;
            }
        }
        free.then_some(true)
    };
    // The root and ROOT_STEP_MM out only need the core clear: no strut starts there.
    let core_cut = |p: V3<f64>| poses.iter().any(|pose| near(pose, p, clear.need));
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [back, v, -v, (back + v).scalec(h), (back - v).scalec(h)]
        .iter()
        .any(|&d| {
            let near_root = [0.0, ROOT_STEP_MM];
            if clear.from_root
                && near_root
                    .iter()
                    .any(|&s| core_cut(root + d.scalec(step * s)))
            {
                return false;
            }
            (1..=steps)
                .find_map(|k| verdict(root + d.scalec(step * k as f64)))
                .unwrap_or(false)
        })
}

/// A sampled curve's sections (a rim's half ellipses or a band's rectangles) with bounding
/// spheres per [`CHUNK`] samples, for "is this point in or near it" queries.
struct Sections {
    sections: Vec<Section>,
    chunks: Vec<(V3<f64>, f64, std::ops::Range<usize>)>,
}

impl Sections {
    fn new(c2: &[[f64; 3]], n2: &[[f64; 3]], reach: f64) -> Self {
        let n = c2.len();
        let sections = (0..n).map(|s| Section::new(c2, n2, s)).collect();
        let chunks = (0..n)
            .step_by(CHUNK)
            .map(|lo| {
                let r = lo..(lo + CHUNK).min(n);
                let c = r
                    .clone()
                    .fold(V3::zero(), |acc, s| acc + V3::from(c2[s]))
                    .scalec(1.0 / r.len() as f64);
                let rad = r
                    .clone()
                    .map(|s| (V3::from(c2[s]) - c).norm())
                    .fold(0.0, f64::max);
                (c, rad + reach, r)
            })
            .collect();
        Self { sections, chunks }
    }

    /// Whether `y` (follower frame) lies within `margin` of the rim's half ellipse.
    fn near(&self, y: V3<f64>, rim: &RimSection, margin: f64) -> bool {
        self.any(y, |s| s.near(y, rim, margin))
    }

    /// Whether `x` (driver frame) lies within `margin` of the band's section.
    fn near_band(&self, x: V3<f64>, rim: &RimSection, margin: f64) -> bool {
        self.any(x, |s| s.near_band(x, rim, margin))
    }

    /// Whether `test(section, y)` holds at one of `steps` points evenly along the segment
    /// from `from` (included) to `to` (excluded: the next segment's first point) for a
    /// section whose chunk's sphere holds that point. The chunks the segment passes are
    /// found once for all its points.
    fn any_along(
        &self,
        from: V3<f64>,
        to: V3<f64>,
        steps: usize,
        test: impl Fn(&Section, V3<f64>) -> bool,
    ) -> bool {
        let d = to - from;
        let len2 = d.norm2();
        let passed: Vec<_> = self
            .chunks
            .iter()
            .filter(|(c, r, _)| {
                let along = if len2 > 0.0 {
                    ((*c - from).dot(d) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (from + d.scalec(along) - *c).norm2() <= r * r
            })
            .collect();
        if passed.is_empty() {
            return false;
        }
        (0..steps).any(|j| {
            let y = from + d.scalec(j as f64 / steps as f64);
            passed.iter().any(|(c, r, range)| {
                (y - *c).norm2() <= r * r && range.clone().any(|s| test(&self.sections[s], y))
            })
        })
    }

    /// Whether `test` holds for a section whose chunk's sphere holds `y` (follower frame).
    fn any(&self, y: V3<f64>, test: impl Fn(&Section) -> bool) -> bool {
        self.chunks.iter().any(|(c, r, range)| {
            (y - *c).norm2() <= r * r && range.clone().any(|s| test(&self.sections[s]))
        })
    }
}

/// The rim's section at one sample: its apex, frame and the tangential extent it stands for.
struct Section {
    apex: V3<f64>,
    tangent: V3<f64>,
    normal: V3<f64>,
    binormal: V3<f64>,
    half_step: f64,
}

impl Section {
    fn new(c2: &[[f64; 3]], n2: &[[f64; 3]], s: usize) -> Self {
        let n = c2.len();
        let at = |i: usize| V3::from(c2[i % n]);
        let (prev, here, next) = (at(s + n - 1), at(s), at(s + 1));
        let tangent = (next - prev).unit();
        let raw = V3::from(n2[s]);
        let normal = (raw - tangent.scale(raw.dot(tangent))).unit();
        Self {
            apex: here,
            tangent,
            normal,
            binormal: tangent.cross(normal),
            // Half the larger neighbouring step, so the sections tile the curve.
            half_step: 0.5 * (next - here).norm().max((here - prev).norm()),
        }
    }

    /// Whether `y` lies within `margin` of the section's half ellipse (the ellipse grown
    /// by `margin` on both semi-axes, which contains the true offset region near the
    /// apex and slightly exceeds it on the flanks).
    fn near(&self, y: V3<f64>, rim: &RimSection, margin: f64) -> bool {
        let d = y - self.apex;
        if d.dot(self.tangent).abs() > self.half_step + margin {
            return false;
        }
        let h = -d.dot(self.normal);
        let w = d.dot(self.binormal);
        if h < -margin || h > rim.depth + margin {
            return false;
        }
        let (a, b) = (rim.depth, rim.half_width);
        ((h - a) / (a + margin)).hypot(w / (b + margin)) < 1.0
    }

    /// Whether `x` lies within `margin` of the band's rectangle at this sample (lip ahead of
    /// the curve along the normal, depth behind it, half width across; the rectangle grown
    /// by `margin` on every side, which holds the true offset region and exceeds it at the
    /// corners).
    fn near_band(&self, x: V3<f64>, rim: &RimSection, margin: f64) -> bool {
        let d = x - self.apex;
        if d.dot(self.tangent).abs() > self.half_step + margin {
            return false;
        }
        let h = d.dot(self.normal);
        h >= -rim.band_depth - margin
            && h <= rim.band_lip + margin
            && d.dot(self.binormal).abs() <= rim.band_half_width + margin
    }

    /// Whether `y` lies inside the section's half ellipse by more than the tolerance.
    fn cuts(&self, y: V3<f64>, rim: &RimSection) -> bool {
        let d = y - self.apex;
        if d.dot(self.tangent).abs() > self.half_step {
            return false;
        }
        // Depth behind the apex and offset across the normal.
        let h = -d.dot(self.normal);
        let w = d.dot(self.binormal);
        if h <= rim.tolerance || h > rim.depth {
            return false;
        }
        let (a, b) = (rim.depth, rim.half_width);
        let (qh, qw) = ((h - a) / a, w / b);
        let q = qh.hypot(qw);
        if q >= 1.0 {
            return false;
        }
        // First-order distance to the ellipse: (1 − |q|) over the gradient of |q|.
        let g = (qh / a).hypot(qw / b) / q.max(f64::MIN_POSITIVE);
        (1.0 - q) / g.max(f64::MIN_POSITIVE) > rim.tolerance
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// c², n², c¹ and the driver-to-follower maps of a sampled pair.
    type Sampled = (
        Vec<[f64; 3]>,
        Vec<[f64; 3]>,
        Vec<[f64; 3]>,
        Vec<DriverToFollower>,
    );

    /// Two discs rolling on each other (a friction-wheel pair, driver radius 3 at d_x = 6,
    /// follower radius 3 turning the other way), with the contact normal along the line of
    /// centres: the rim touches each driver point only at its own instant, so nothing is cut.
    fn wheels(n: usize, follower_speed: f64) -> Sampled {
        let (r, dx) = (3.0, 6.0);
        let mut c2 = Vec::new();
        let mut n2 = Vec::new();
        let mut c1 = Vec::new();
        let mut poses = Vec::new();
        for i in 0..n {
            let t = i as f64 / n as f64;
            let phi = TAU * t;
            let psi = -follower_speed * TAU * t;
            // Contact at (r, 0, 0) in R, every instant.
            let r2 = super::super::math::rz(psi);
            c2.push(V3::new(r, 0.0, 0.0).rot_t(&r2).vals());
            // Follower's outward normal points from the follower to the driver (+x).
            n2.push(V3::new(1.0, 0.0, 0.0).rot_t(&r2).vals());
            c1.push(
                V3::new(r - dx, 0.0, 0.0)
                    .rot_t(&super::super::math::rz(phi))
                    .vals(),
            );
            poses.push(DriverToFollower::new(&r2, [0.0; 3], phi, dx));
        }
        (c2, n2, c1, poses)
    }

    /// Rolling wheels keep every contact: the rim is tangent at the contact and clear of the
    /// driver curve elsewhere.
    #[test]
    fn rolling_wheels_keep_every_contact() {
        let (c2, n2, c1, poses) = wheels(360, 1.0);
        let cut = cut_contacts(&c2, &n2, &c1, &poses, &RimSection::printed(10.0));
        assert_eq!(cut.iter().filter(|c| **c).count(), 0);
    }

    /// A follower curve whose rim sweeps back through its own driver curve: the same wheel
    /// pair with the follower's normal reversed (the rim's body then lies on the driver's
    /// side of the contact, inside the band), so every contact is cut.
    #[test]
    fn a_rim_on_the_driver_side_cuts_its_contacts() {
        let (c2, n2, c1, poses) = wheels(360, 1.0);
        let flipped: Vec<[f64; 3]> = n2.iter().map(|v| (-V3::from(*v)).vals()).collect();
        let cut = cut_contacts(&c2, &flipped, &c1, &poses, &RimSection::printed(10.0));
        assert_eq!(cut.iter().filter(|c| **c).count(), 360);
    }

    /// A cut that lasts less than one sample: the contact's path through the follower's
    /// frame crosses the rim 0.5 mm behind its apex between two instants, at each of which
    /// it lies outside the rim, beyond its flank. `cut_contacts` steps along that path, so
    /// the contact is cut; tested at the instants alone it would not be.
    #[test]
    fn a_cut_between_two_instants_is_seen() {
        let n = 8;
        let rim = RimSection::printed(10.0);
        // The rim runs round a circle of radius 3 in the xy plane, its normal outward, so
        // its half ellipse stands along z (the binormal) ±0.16 and 0.3 deep towards the axis.
        let (c2, n2): (Vec<[f64; 3]>, Vec<[f64; 3]>) = (0..n)
            .map(|i| {
                let (s, c) = (TAU * i as f64 / n as f64).sin_cos();
                ([3.0 * c, 3.0 * s, 0.0], [c, s, 0.0])
            })
            .unzip();
        // Contact 0's path (the follower frame is the driver's, shifted): its own point,
        // then above and below section 2's rim, crossing it 0.05 behind the apex between
        // instants 3 and 4, then back down to its own point.
        let inside = V3::from(c2[2]) - V3::from(n2[2]).scalec(0.05);
        let z = V3::new(0.0, 0.0, 1.0);
        let own = V3::from(c2[0]);
        let path = [
            own,
            own + z.scalec(10.0),
            inside + z.scalec(10.0),
            inside + z.scalec(0.5),
            inside - z.scalec(0.5),
            inside - z.scalec(10.0),
            own - z.scalec(10.0),
            own - z.scalec(10.0),
        ];
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let poses: Vec<DriverToFollower> = path
            .iter()
            .map(|y| DriverToFollower {
                a: identity,
                b: (*y - own).vals(),
            })
            .collect();
        let rims = Sections::new(&c2, &n2, rim.depth + rim.half_width);
        assert!(
            path.iter().all(|y| !rims.any(*y, |s| s.cuts(*y, &rim))),
            "no instant alone cuts contact 0"
        );
        let cut = cut_contacts(&c2, &n2, &c2, &poses, &rim);
        assert!(
            cut[0],
            "the crossing between instants 3 and 4 cuts contact 0"
        );
    }

    /// The driver's outward normal n¹ of the wheels (−x in R at the contact).
    fn wheel_n1(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let phi = TAU * i as f64 / n as f64;
                V3::new(-1.0, 0.0, 0.0)
                    .rot_t(&super::super::math::rz(phi))
                    .vals()
            })
            .collect()
    }

    /// Guards the island test: with half the contacts marked cut, the other half is an
    /// island when the rim sweeps behind and beside the band everywhere along it (the rim
    /// on the driver's side of the contact sweeps an annulus 3 mm deep into the driver),
    /// and anchored when the rim stays on the follower's side (rolling wheels), but only
    /// while its rays can reach the free space the planner needs.
    #[test]
    fn a_run_hemmed_in_by_the_rims_sweep_is_an_island() {
        let n = 120;
        let (c2, n2, c1, poses) = wheels(n, 1.0);
        let n1 = wheel_n1(n);
        let rim = RimSection::printed(10.0);
        let cut: Vec<bool> = (0..n).map(|i| i < n / 2).collect();
        let rolling = island_contacts(&c2, &n2, &c1, &n1, &poses, &rim, &cut);
        assert_eq!(rolling.iter().filter(|c| **c).count(), 0);
        let flipped: Vec<[f64; 3]> = n2.iter().map(|v| (-V3::from(*v)).vals()).collect();
        let hemmed = island_contacts(&c2, &flipped, &c1, &n1, &poses, &rim, &cut);
        let expected: Vec<bool> = cut.iter().map(|c| !c).collect();
        assert_eq!(hemmed, expected);
        // A ray from 3 mm inside the rolling driver's disc is at most 15 mm from the rim's
        // sweep at the end of its 12 mm: asking 16 mm of free space leaves every run an
        // island, where the planner's 5.8 mm anchored them all.
        let beyond = RimSection {
            escape_free: 1.6,
            ..rim
        };
        let unreachable = island_contacts(&c2, &n2, &c1, &n1, &poses, &beyond, &cut);
        assert_eq!(unreachable, expected);
    }

    /// Guards the plate's escape: the rolling wheels' band stays outside the follower's
    /// disc but for its 1.5 mm lip, so a strut leaves the plate from behind its rim; a band
    /// whose lip reaches 20 mm into the follower sweeps over the whole back of the rim and
    /// every side of it, so none can, and the pair keeps no contact at all.
    #[test]
    fn a_plate_its_band_sweeps_around_keeps_nothing() {
        let n = 120;
        let (c2, n2, c1, poses) = wheels(n, 1.0);
        let n1 = wheel_n1(n);
        let rim = RimSection::printed(10.0);
        assert!(plate_escapes(&c2, &n2, &c1, &n1, &poses, &rim));
        let kept = lost_contacts(&c2, &n2, &c1, &n1, &poses, &rim);
        assert_eq!(kept.iter().filter(|l| **l).count(), 0);
        let deep = RimSection {
            band_lip: 2.0,
            ..rim
        };
        assert!(!plate_escapes(&c2, &n2, &c1, &n1, &poses, &deep));
        let lost = lost_contacts(&c2, &n2, &c1, &n1, &poses, &deep);
        assert_eq!(lost, vec![true; n]);
    }

    /// Guards the plates' clearance from the root ([`RULES`] 3): a point 1.7 mm in front of
    /// the rays' root (towards the rim's apex) stops every ray at its root when the core
    /// must keep [`PLATE_CLEARANCE_MM`] from there on, and none of them when it need only
    /// from the first millimetre out (the rule that passed screw-bob's K = 7 plate 6, whose
    /// rim the build's trim then cut loose).
    #[test]
    fn a_plate_ray_needs_its_core_clear_from_the_root() {
        let (_, _, _, poses) = wheels(12, 1.0);
        let rim = RimSection::printed(10.0);
        let (root, n, v) = (
            V3::new(0.0, 0.0, 0.0),
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, 1.0, 0.0),
        );
        let obstacle = root + n.scalec(0.17);
        let near = |_: &DriverToFollower, p: V3<f64>, margin: f64| (p - obstacle).norm() < margin;
        let free = |from_root| {
            let clear = Clear {
                need: rim.plate_clearance,
                from_root,
            };
            any_ray_free(root, -n, v, &poses, &rim, clear, near)
        };
        assert!(free(false));
        assert!(!free(true));
    }

    /// Guards the widening of lost runs: by arc length along c¹, both ways, across the
    /// loop's closing sample, and never of a pair that keeps all or nothing.
    #[test]
    fn lost_runs_widen_by_arc_length_both_ways() {
        // 20 samples 1 apart (chord) on a circle.
        let r = 0.5 / (std::f64::consts::PI / 20.0).sin();
        let c1: Vec<[f64; 3]> = (0..20)
            .map(|i| {
                let a = TAU * i as f64 / 20.0;
                [r * a.cos(), r * a.sin(), 0.0]
            })
            .collect();
        let mut lost = vec![false; 20];
        lost[0] = true;
        lost[10] = true;
        let wide = widen_lost(&lost, &c1, 1.5);
        let idx: Vec<usize> = (0..20).filter(|&i| wide[i]).collect();
        assert_eq!(idx, vec![0, 1, 9, 10, 11, 19]);
        assert_eq!(widen_lost(&lost, &c1, 0.9), lost);
        assert_eq!(widen_lost(&[false; 20], &c1, 5.0), vec![false; 20]);
    }

    /// The map and its inverse are inverses: follower to driver and back.
    #[test]
    fn the_inverse_map_undoes_the_map() {
        let (_, _, c1, poses) = wheels(36, 1.0);
        for (i, pose) in poses.iter().enumerate() {
            let x = V3::from(c1[i]) + V3::new(0.3, -0.2, 0.7);
            let back = pose.unapply(pose.apply(x));
            assert!((back - x).norm() < 1e-12, "sample {i}");
        }
    }

    /// The driver-to-follower map takes a driver curve point to the follower curve point it
    /// touches at the same instant.
    #[test]
    fn the_map_takes_each_contact_to_its_follower_point() {
        let (c2, _, c1, poses) = wheels(36, 1.0);
        for i in 0..36 {
            let y = poses[i].apply(V3::from(c1[i]));
            assert!((y - V3::from(c2[i])).norm() < 1e-12, "sample {i}");
        }
    }
}
