//! Alignment of the measured run with the target law: the constant offsets a bench always
//! has, estimated and reported rather than hidden.
//!
//! Scalar DOFs (1R, 1R1T) follow the model
//!
//! ```text
//! y_j(i) = f_j(φ_i − δ₀ − d_i·λ) + c_j − d_i·s_ij·β_j/2 + noise
//! ```
//!
//! with the measured driver angle φ_i, the run direction d_i (+1 forward, −1 reverse), the
//! sign s_ij of the target's slope f_j′ and the unknowns: δ₀ a constant driver-angle offset
//! (the follower acts as if the driver were δ₀ behind: a phase lag, or a homing error — the
//! two look the same), c_j a constant sensor offset per DOF, and, only when both directions
//! were recorded, λ a direction-dependent driver-angle offset (half a dead band between
//! driver and follower, plus any time lag times the driver speed) and β_j a dead band on the
//! follower side (follower units), a width and so never negative: where the free fit puts
//! one below zero it is held at zero and the rest fitted again, and a held one the
//! residuals then pull upwards is let go (an active set, [`WIDTH_RELEASE_COSINE`]). The fit
//! is a weighted Gauss–Newton least-squares over all measured samples, started from a grid
//! search over δ₀;
//! standard errors come from the normal matrix. Parameters that the data cannot separate
//! (e.g. δ₀ and c for a uniform law) are flagged, not guessed.
//!
//! 3R orientations follow `R_m = R_w · R(φ − δ₀) · R_c` with a constant world-frame offset
//! R_w (IMU heading) and a constant mounting offset R_c: a grid over δ₀ (with R_w, R_c from
//! alternating chordal means) starts a Gauss–Newton fit of R_w, R_c, δ₀ and, with both
//! directions, λ on the rotation-vector residuals log(R_m·R̂⁻¹).
//!
//! This module does not compute error statistics; see [`super::metrics`].

use nalgebra::{DMatrix, DVector, UnitQuaternion};

use super::run::{MeasuredRun, Phase};
use super::target::{PeriodicTable, RotationTable, TargetLaw, DWELL_SLOPE};
use super::AnalysisError;

/// Grid step for the initial driver-offset search, degrees. Default 1°: the Gauss–Newton
/// refinement converges from anywhere within a few degrees of the
/// optimum for the laws we synthesize, and 360 grid points on a subset cost milliseconds.
pub const ALIGN_GRID_STEP_DEG: f64 = 1.0;

/// Samples used by the grid search (evenly strided subset). Default 20 000: enough to
/// resolve a 1° grid on noisy data, small enough that the search stays ≪ 100 ms for 3.6 M
/// samples.
pub const ALIGN_GRID_SUBSET: usize = 20_000;

/// Samples used by the 3R grid search, which costs more per sample (rotation means).
/// Default 3 000.
pub const ALIGN_GRID_SUBSET_3R: usize = 3_000;

/// Gauss–Newton iterations at most. Default 30; the fit is nearly linear near the optimum
/// and normally converges in 3–6.
pub const ALIGN_MAX_ITERATIONS: usize = 30;

/// Convergence: stop when the driver-offset and lag updates are below this many degrees.
/// Default 10⁻⁹°, far below any measurable offset.
pub const ALIGN_TOLERANCE_DEG: f64 = 1e-9;

/// Largest driver-angle step per Gauss–Newton iteration, degrees. Default 5°: keeps a bad
/// linearization from jumping to another basin.
pub const ALIGN_MAX_STEP_DEG: f64 = 5.0;

/// A parameter is "not determined by the data" when its standard error exceeds this many
/// of its units (degrees or mm). Default 1000: a singular direction of the normal matrix
/// shows up as a standard error many orders of magnitude above any real offset.
pub const UNDETERMINED_STD: f64 = 1000.0;

/// An estimated parameter with its standard error (from the least-squares normal matrix;
/// optimistic when residuals are correlated in time).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Estimate {
    /// The estimate.
    pub value: f64,
    /// One standard error.
    pub std_err: f64,
    /// False when the data cannot separate this parameter from another one (its value is
    /// then a minimum-norm choice, not a measurement).
    pub determined: bool,
}

impl Estimate {
    fn new(value: f64, std_err: f64) -> Self {
        let determined = std_err.is_finite() && std_err < UNDETERMINED_STD;
        Self {
            value,
            std_err,
            determined,
        }
    }
}

/// Which degree of freedom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dof {
    /// Rotation about z, degrees.
    Rz,
    /// Translation along z, millimetres.
    Tz,
}

impl Dof {
    /// Short name used in file and field names.
    pub fn name(self) -> &'static str {
        match self {
            Dof::Rz => "rz",
            Dof::Tz => "tz",
        }
    }

    /// Unit suffix used in field names.
    pub fn unit(self) -> &'static str {
        match self {
            Dof::Rz => "deg",
            Dof::Tz => "mm",
        }
    }
}

/// Offsets of one scalar DOF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DofOffsets {
    /// Which DOF.
    pub dof: Dof,
    /// Constant sensor offset c (DOF units), reduced to (−180°, 180°] for rotations.
    pub sensor_offset: Estimate,
    /// Whole turns removed from the sensor offset (degrees, a multiple of 360; 0 for tz).
    pub turn_shift: f64,
    /// Follower-side dead band β (DOF units), when both directions were recorded. Never
    /// negative: where the fit gives a negative width it is held at 0 (standard error 0)
    /// and the other parameters fitted again (see `fit_widths_nonnegative`).
    pub backlash: Option<Estimate>,
    /// The negative β the fit gave before [`Self::backlash`] was held at 0 for it.
    pub backlash_free: Option<f64>,
}

impl DofOffsets {
    /// The full offset subtracted from the measurement (sensor offset plus turn shift).
    pub fn total_offset(&self) -> f64 {
        self.sensor_offset.value + self.turn_shift
    }
}

/// Constant rotations of a 3R alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationOffsets {
    /// World-frame offset R_w (left factor).
    pub world: UnitQuaternion<f64>,
    /// Mounting offset R_c (right factor).
    pub mount: UnitQuaternion<f64>,
}

/// The fitted offsets.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    /// Constant driver-angle offset δ₀ in driver degrees (positive: the follower is where the
    /// target puts it δ₀ degrees of driver angle earlier, i.e. it lags).
    pub driver_offset_deg: Estimate,
    /// Direction-dependent driver-angle offset λ in driver degrees (forward runs see δ₀ + λ,
    /// reverse runs δ₀ − λ): half the driver-side backlash plus any time lag × speed. Only
    /// when both directions were recorded.
    pub lag_driver_deg: Option<Estimate>,
    /// Scalar DOFs (1R, 1R1T).
    pub dofs: Vec<DofOffsets>,
    /// 3R constant rotations.
    pub rotation: Option<RotationOffsets>,
    /// Whether forward and reverse samples were both present.
    pub both_directions: bool,
    /// Samples used (non-settle).
    pub samples: usize,
}

/// Fit the offsets of `run` against `law`.
pub fn align(run: &MeasuredRun, law: &TargetLaw) -> Result<Alignment, AnalysisError> {
    let idx: Vec<usize> = run.measured_indices().collect();
    if idx.len() < 10 {
        return Err(AnalysisError::NotEnoughData(format!(
            "{} measured (non-settle) samples; alignment needs at least 10",
            idx.len()
        )));
    }
    let has_fwd = idx.iter().any(|&i| run.phase[i] == Phase::Forward);
    let has_rev = idx.iter().any(|&i| run.phase[i] == Phase::Reverse);
    let both = has_fwd && has_rev;
    if let Some(rot_law) = &law.rotation {
        let measured = run.rotation.as_ref().ok_or_else(|| {
            AnalysisError::Mismatch(
                "the target is 3R but the recording has no orientation sensor (IMU)".into(),
            )
        })?;
        return Ok(align_rotation(run, measured, rot_law, &idx, both));
    }
    let mut dofs: Vec<ScalarDof<'_>> = Vec::new();
    if let Some(t) = &law.rz_deg {
        let y = run.rz_deg.as_ref().ok_or_else(|| {
            AnalysisError::Mismatch(
                "the target turns about z but the recording has no rotation sensor (rz)".into(),
            )
        })?;
        dofs.push(ScalarDof::new(Dof::Rz, y, t));
    }
    if let Some(t) = &law.tz_mm {
        let y = run.tz_mm.as_ref().ok_or_else(|| {
            AnalysisError::Mismatch(
                "the target is 1R1T but the recording has no height sensor (tz)".into(),
            )
        })?;
        dofs.push(ScalarDof::new(Dof::Tz, y, t));
    }
    if dofs.is_empty() {
        return Err(AnalysisError::Mismatch("the target law has no DOF".into()));
    }
    Ok(align_scalar(run, &dofs, &idx, both))
}

struct ScalarDof<'a> {
    dof: Dof,
    y: &'a [f64],
    table: &'a PeriodicTable,
    weight: f64,
}

impl<'a> ScalarDof<'a> {
    fn new(dof: Dof, y: &'a [f64], table: &'a PeriodicTable) -> Self {
        let (lo, hi) = table.range();
        Self {
            dof,
            y,
            table,
            weight: 1.0 / (hi - lo).max(1.0),
        }
    }
}

fn strided(idx: &[usize], max: usize) -> Vec<usize> {
    let stride = idx.len().div_ceil(max).max(1);
    idx.iter().step_by(stride).copied().collect()
}

/// Grid order 0, +s, −s, +2s, … so that ties go to the smallest |δ|.
fn grid() -> impl Iterator<Item = f64> {
    let n = (180.0 / ALIGN_GRID_STEP_DEG).round() as i64;
    (0..=2 * n).map(move |k| {
        let m = (k + 1) / 2;
        let s = if k % 2 == 1 { 1.0 } else { -1.0 };
        s * m as f64 * ALIGN_GRID_STEP_DEG
    })
}

fn align_scalar(run: &MeasuredRun, dofs: &[ScalarDof<'_>], idx: &[usize], both: bool) -> Alignment {
    // 1. Grid search for δ₀ with c solved as a mean, λ = β = 0.
    let sub = strided(idx, ALIGN_GRID_SUBSET);
    let mut best = (f64::INFINITY, 0.0);
    for delta in grid() {
        let mut cost = 0.0;
        for d in dofs {
            let (mut s, mut s2) = (0.0, 0.0);
            for &i in &sub {
                let r = d.y[i] - d.table.value(run.driver_deg[i] - delta);
                s += r;
                s2 += r * r;
            }
            let n = sub.len() as f64;
            cost += d.weight * d.weight * (s2 - s * s / n);
        }
        if cost < best.0 * (1.0 - 1e-12) {
            best = (cost, delta);
        }
    }
    // 2. Gauss–Newton on all measured samples.
    let nd = dofs.len();
    let per = if both { 2 } else { 1 };
    let np = (if both { 2 } else { 1 }) + nd * per;
    let c_at = |j: usize| (if both { 2 } else { 1 }) + j * per;
    let mut p = DVector::<f64>::zeros(np);
    p[0] = best.1;
    for (j, d) in dofs.iter().enumerate() {
        let n = sub.len() as f64;
        p[c_at(j)] = sub
            .iter()
            .map(|&i| d.y[i] - d.table.value(run.driver_deg[i] - best.1))
            .sum::<f64>()
            / n;
    }
    // Gauss–Newton with the parameters marked in `held` kept where they are (their column of
    // the Jacobian is zero, so the minimum-norm step leaves them alone).
    let fit = |p: &mut DVector<f64>, held: &[bool]| -> HeldFit {
        let mut out = HeldFit {
            jtj: DMatrix::<f64>::zeros(np, np),
            ssr: 0.0,
            pull: DVector::<f64>::zeros(np),
            column2: DVector::<f64>::zeros(np),
        };
        let mut row = vec![0.0; np];
        for _ in 0..ALIGN_MAX_ITERATIONS {
            let HeldFit {
                jtj,
                ssr,
                pull,
                column2,
            } = &mut out;
            jtj.fill(0.0);
            pull.fill(0.0);
            column2.fill(0.0);
            let mut jtr = DVector::<f64>::zeros(np);
            *ssr = 0.0;
            for &i in idx {
                let dir = run.phase[i].direction();
                let lag = if both { p[1] } else { 0.0 };
                let phi = run.driver_deg[i] - p[0] - dir * lag;
                for (j, d) in dofs.iter().enumerate() {
                    let (f, fp) = d.table.eval(phi);
                    let s = if fp.abs() <= DWELL_SLOPE {
                        0.0
                    } else {
                        fp.signum()
                    };
                    let cj = c_at(j);
                    let beta = if both { p[cj + 1] } else { 0.0 };
                    let pred = f + p[cj] - dir * s * beta / 2.0;
                    let w = d.weight;
                    let r = w * (d.y[i] - pred);
                    row.iter_mut().for_each(|v| *v = 0.0);
                    row[0] = -fp * w;
                    if both {
                        row[1] = -dir * fp * w;
                        row[cj + 1] = -dir * s / 2.0 * w;
                    }
                    row[cj] = w;
                    for (k, (v, h)) in row.iter_mut().zip(held).enumerate() {
                        if *h {
                            pull[k] += *v * r;
                            column2[k] += *v * *v;
                            *v = 0.0;
                        }
                    }
                    add_row(jtj, &mut jtr, &row, r);
                    *ssr += r * r;
                }
            }
            fill_lower(jtj);
            let mut step = solve_pinv(jtj, &jtr);
            let lim = |v: f64| v.clamp(-ALIGN_MAX_STEP_DEG, ALIGN_MAX_STEP_DEG);
            step[0] = lim(step[0]);
            if both {
                step[1] = lim(step[1]);
            }
            *p += &step;
            let small = step[0].abs() < ALIGN_TOLERANCE_DEG
                && (!both || step[1].abs() < ALIGN_TOLERANCE_DEG);
            if small {
                break;
            }
        }
        out
    };
    // A dead band is a width, never negative (the two directions' gap is then the driver
    // side's).
    let widths: Vec<usize> = if both {
        (0..nd).map(|j| c_at(j) + 1).collect()
    } else {
        Vec::new()
    };
    let (HeldFit { jtj, ssr, .. }, held, free) = fit_widths_nonnegative(&mut p, &widths, fit);
    let dof_count = (idx.len() * nd) as f64;
    let sigma2 = ssr / (dof_count - np as f64).max(1.0);
    let cov = covariance(&jtj, sigma2);
    let est = |k: usize| Estimate::new(p[k], cov[(k, k)].max(0.0).sqrt());
    let offsets = dofs
        .iter()
        .enumerate()
        .map(|(j, d)| {
            let cj = c_at(j);
            let mut e = est(cj);
            let turn_shift = if d.dof == Dof::Rz {
                360.0 * (e.value / 360.0).round()
            } else {
                0.0
            };
            e.value -= turn_shift;
            DofOffsets {
                dof: d.dof,
                sensor_offset: e,
                turn_shift,
                backlash: both.then(|| {
                    if held[cj + 1] {
                        Estimate::new(0.0, 0.0)
                    } else {
                        est(cj + 1)
                    }
                }),
                backlash_free: both.then(|| free[cj + 1]).flatten(),
            }
        })
        .collect();
    Alignment {
        driver_offset_deg: est(0),
        lag_driver_deg: both.then(|| est(1)),
        dofs: offsets,
        rotation: None,
        both_directions: both,
        samples: idx.len(),
    }
}

/// Add one residual `r` whose Jacobian row is `row` to the normal equations: Jᵀr, and the
/// upper triangle of JᵀJ (see [`fill_lower`]). Zero entries of the row add nothing and are
/// skipped.
fn add_row(jtj: &mut DMatrix<f64>, jtr: &mut DVector<f64>, row: &[f64], r: f64) {
    for (a, &ra) in row.iter().enumerate() {
        if ra == 0.0 {
            continue;
        }
        jtr[a] += ra * r;
        for (b, &rb) in row.iter().enumerate().skip(a) {
            jtj[(a, b)] += ra * rb;
        }
    }
}

/// One Gauss–Newton fit with some parameters held where they are, as its last
/// linearization saw it.
struct HeldFit {
    /// JᵀJ of the free parameters (a held one's row and column are zero).
    jtj: DMatrix<f64>,
    /// Sum of the squared weighted residuals.
    ssr: f64,
    /// Per held parameter, Σ jₖ·r over the rows (jₖ the row's entry for it before it was
    /// zeroed): positive when moving it up would lower the residuals. Zero for free ones.
    pull: DVector<f64>,
    /// Per held parameter, Σ jₖ². Zero for free ones.
    column2: DVector<f64>,
}

/// A held width is let go when the cosine between its column and the residual vector is
/// above this. Default 10⁻⁶: the sums behind it carry round-off near 10⁻¹², so this is far
/// above noise, and a width whose column is that nearly orthogonal to the residuals would
/// move the fit by less than it can resolve.
pub const WIDTH_RELEASE_COSINE: f64 = 1e-6;

/// Fit with the parameters `widths` kept non-negative, by active set: a width the fit puts
/// below zero is held at zero (with every other negative one) and the rest fitted again; a
/// held width the residuals pull upwards (see [`HeldFit::pull`]) is let go again, each at
/// most once, so the rounds end. Holding several at once can hold one that only the others'
/// negative values made negative; letting it go finds the constrained optimum (a quadratic
/// example in the tests). Returns the last fit, which parameters are held and, per held
/// one, the value the fit before its hold gave it.
fn fit_widths_nonnegative(
    p: &mut DVector<f64>,
    widths: &[usize],
    mut fit: impl FnMut(&mut DVector<f64>, &[bool]) -> HeldFit,
) -> (HeldFit, Vec<bool>, Vec<Option<f64>>) {
    let np = p.len();
    let mut held = vec![false; np];
    let mut released = vec![false; np];
    let mut free = vec![None; np];
    loop {
        let out = fit(p, &held);
        let negative: Vec<usize> = widths
            .iter()
            .copied()
            .filter(|&k| !held[k] && p[k] < 0.0)
            .collect();
        if !negative.is_empty() {
            for k in negative {
                free[k] = Some(p[k]);
                held[k] = true;
                p[k] = 0.0;
            }
            continue;
        }
        let cosine = |k: usize| {
            let norm = (out.column2[k] * out.ssr).sqrt();
            if norm > 0.0 {
                out.pull[k] / norm
            } else {
                0.0
            }
        };
        let release = widths
            .iter()
            .copied()
            .filter(|&k| held[k] && !released[k] && cosine(k) > WIDTH_RELEASE_COSINE)
            .max_by(|&a, &b| cosine(a).total_cmp(&cosine(b)));
        match release {
            Some(k) => {
                held[k] = false;
                released[k] = true;
                free[k] = None;
            }
            None => return (out, held, free),
        }
    }
}

/// Copy JᵀJ's upper triangle, which [`add_row`] fills, into its lower one.
fn fill_lower(jtj: &mut DMatrix<f64>) {
    for a in 0..jtj.nrows() {
        for b in 0..a {
            jtj[(a, b)] = jtj[(b, a)];
        }
    }
}

/// Singular values below this fraction of the largest count as zero in the normal
/// matrix. Default 10⁻⁹: exact collinearity (a uniform law's driver and sensor offsets)
/// shows up at round-off level (≈10⁻¹⁶), while genuinely separable parameters stay many
/// orders above it.
pub const SINGULAR_RELATIVE: f64 = 1e-9;

/// Minimum-norm least-squares step (pseudo-inverse of the normal matrix): directions the
/// data do not determine get no step at all, so nothing drifts along them.
fn solve_pinv(jtj: &DMatrix<f64>, jtr: &DVector<f64>) -> DVector<f64> {
    let svd = jtj.clone().svd(true, true);
    let smax = svd.singular_values.max();
    svd.solve(jtr, (SINGULAR_RELATIVE * smax).max(1e-300))
        .unwrap_or_else(|_| DVector::zeros(jtr.len()))
}

/// Covariance σ²·(JᵀJ)⁺, with infinite variance for parameters that lie in the normal
/// matrix's null space (not determined by the data).
fn covariance(jtj: &DMatrix<f64>, sigma2: f64) -> DMatrix<f64> {
    let n = jtj.nrows();
    let svd = jtj.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let tol = SINGULAR_RELATIVE * smax;
    let Some(v_t) = svd.v_t.as_ref() else {
        return DMatrix::from_element(n, n, f64::INFINITY);
    };
    let mut cov = DMatrix::<f64>::zeros(n, n);
    let mut null_weight = vec![0.0; n];
    for (i, &sv) in svd.singular_values.iter().enumerate() {
        let v = v_t.row(i);
        if sv > tol {
            for a in 0..n {
                for b in 0..n {
                    cov[(a, b)] += v[a] * v[b] / sv;
                }
            }
        } else {
            for (k, w) in null_weight.iter_mut().enumerate() {
                *w += v[k] * v[k];
            }
        }
    }
    cov *= sigma2;
    for (k, w) in null_weight.iter().enumerate() {
        if *w > 1e-6 {
            cov[(k, k)] = f64::INFINITY;
        }
    }
    cov
}

/// Sign-aligned chordal mean of unit quaternions.
fn quat_mean(qs: impl Iterator<Item = UnitQuaternion<f64>>) -> UnitQuaternion<f64> {
    let mut acc = nalgebra::Quaternion::new(0.0, 0.0, 0.0, 0.0);
    let mut first: Option<nalgebra::Quaternion<f64>> = None;
    for q in qs {
        let c = *q.quaternion();
        let f = *first.get_or_insert(c);
        acc += if f.dot(&c) < 0.0 { -c } else { c };
    }
    if acc.norm() < 1e-300 {
        UnitQuaternion::identity()
    } else {
        UnitQuaternion::from_quaternion(acc)
    }
}

struct RotFit {
    cost: f64,
    world: UnitQuaternion<f64>,
    mount: UnitQuaternion<f64>,
}

/// World and mount offsets for a fixed δ by alternating chordal means (used to start the
/// Gauss–Newton fit from the grid).
fn fit_rotations(
    run: &MeasuredRun,
    measured: &[UnitQuaternion<f64>],
    law: &RotationTable,
    idx: &[usize],
    delta: f64,
    iterations: usize,
) -> RotFit {
    let target = |i: usize| law.eval(run.driver_deg[i] - delta);
    let (mut world, mut mount) = (UnitQuaternion::identity(), UnitQuaternion::identity());
    for _ in 0..iterations {
        world = quat_mean(
            idx.iter()
                .map(|&i| measured[i] * (target(i) * mount).inverse()),
        );
        mount = quat_mean(
            idx.iter()
                .map(|&i| (world * target(i)).inverse() * measured[i]),
        );
    }
    let cost = idx
        .iter()
        .map(|&i| {
            let a = measured[i].angle_to(&(world * target(i) * mount));
            a * a
        })
        .sum();
    RotFit { cost, world, mount }
}

/// Gauss–Newton over (α world, β mount, δ₀[, λ]) on the rotation-vector residuals
/// e = log(R_m · (R_w R(φ − δ₀ − d·λ) R_c)⁻¹).
fn gauss_newton_rotation(
    run: &MeasuredRun,
    measured: &[UnitQuaternion<f64>],
    law: &RotationTable,
    idx: &[usize],
    both: bool,
    start: (f64, UnitQuaternion<f64>, UnitQuaternion<f64>),
) -> (
    DVector<f64>,
    DMatrix<f64>,
    UnitQuaternion<f64>,
    UnitQuaternion<f64>,
) {
    let np = if both { 8 } else { 7 };
    let (mut delta, mut world, mut mount) = start;
    let mut lag = 0.0;
    let mut jtj = DMatrix::<f64>::zeros(np, np);
    let mut ssr = 0.0;
    let h = 0.01;
    for _ in 0..ALIGN_MAX_ITERATIONS {
        jtj.fill(0.0);
        let mut jtr = DVector::<f64>::zeros(np);
        ssr = 0.0;
        for &i in idx {
            let dir = run.phase[i].direction();
            let phi = run.driver_deg[i] - delta - dir * lag;
            let rt = law.eval(phi);
            let e_rot = world * rt * mount;
            let e = (measured[i] * e_rot.inverse()).scaled_axis();
            // Angular velocity of the target per driver degree, in the reference frame.
            let omega = (law.eval(phi + h) * law.eval(phi - h).inverse()).scaled_axis() / (2.0 * h);
            let w_omega = world * omega;
            let rm = e_rot.to_rotation_matrix();
            let rm = rm.matrix();
            // Rows: residual component r = 0..3; columns: α(3), β(3), δ, λ.
            for r in 0..3 {
                let mut row = [0.0; 8];
                row[r] = -1.0;
                for c in 0..3 {
                    row[3 + c] = -rm[(r, c)];
                }
                row[6] = w_omega[r];
                if both {
                    row[7] = dir * w_omega[r];
                }
                add_row(&mut jtj, &mut jtr, &row[..np], e[r]);
                ssr += e[r] * e[r];
            }
        }
        fill_lower(&mut jtj);
        let step = -solve_pinv(&jtj, &jtr);
        let lim = |v: f64| v.clamp(-ALIGN_MAX_STEP_DEG, ALIGN_MAX_STEP_DEG);
        world = UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(step[0], step[1], step[2]))
            * world;
        mount *=
            UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(step[3], step[4], step[5]));
        delta += lim(step[6]);
        if both {
            lag += lim(step[7]);
        }
        let small = step.iter().take(6).all(|v| v.abs() < 1e-12)
            && step[6].abs() < ALIGN_TOLERANCE_DEG
            && (!both || step[7].abs() < ALIGN_TOLERANCE_DEG);
        if small {
            break;
        }
    }
    let sigma2 = ssr / ((3 * idx.len()) as f64 - np as f64).max(1.0);
    let mut p = DVector::<f64>::zeros(2);
    p[0] = delta;
    p[1] = lag;
    (p, covariance(&jtj, sigma2), world, mount)
}

fn align_rotation(
    run: &MeasuredRun,
    measured: &[UnitQuaternion<f64>],
    law: &RotationTable,
    idx: &[usize],
    both: bool,
) -> Alignment {
    let coarse = strided(idx, ALIGN_GRID_SUBSET_3R);
    let mut best = (
        f64::INFINITY,
        0.0,
        UnitQuaternion::identity(),
        UnitQuaternion::identity(),
    );
    for delta in grid() {
        let fit = fit_rotations(run, measured, law, &coarse, delta, 2);
        if fit.cost < best.0 * (1.0 - 1e-12) {
            best = (fit.cost, delta, fit.world, fit.mount);
        }
    }
    let (p, cov, world, mount) =
        gauss_newton_rotation(run, measured, law, idx, both, (best.1, best.2, best.3));
    let std = |k: usize| cov[(k, k)].max(0.0).sqrt();
    Alignment {
        driver_offset_deg: Estimate::new(p[0], std(6)),
        lag_driver_deg: both.then(|| Estimate::new(p[1], std(7))),
        dofs: Vec::new(),
        rotation: Some(RotationOffsets { world, mount }),
        both_directions: both,
        samples: idx.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::synthetic::{smooth_turn, SyntheticBench};

    /// Guards identifiability reporting: on a uniform law (θ = φ) a driver offset and a
    /// sensor offset are indistinguishable, and the fit says so instead of inventing a split.
    #[test]
    fn uniform_law_flags_driver_offset_as_undetermined() {
        let law = TargetLaw::rotation_1r("uniform", |t| 360.0 * t);
        let run = SyntheticBench {
            driver_offset_deg: 2.0,
            noise: 0.01,
            seed: 3,
            ..Default::default()
        }
        .generate(&law);
        let al = align(&run, &law).unwrap();
        assert!(
            !al.driver_offset_deg.determined,
            "{:?}",
            al.driver_offset_deg
        );
        // The sum is what the data determine: follower = φ − 2 → c − δ₀ = −2.
        let c = al.dofs[0].total_offset();
        assert!((c - al.driver_offset_deg.value + 2.0).abs() < 0.01);
    }

    /// Guards the grid search range: a large driver offset (−150°) is found, not a nearby
    /// local minimum.
    #[test]
    fn large_driver_offset_is_found() {
        let law = smooth_turn();
        let run = SyntheticBench {
            driver_offset_deg: -150.0,
            noise: 0.02,
            seed: 8,
            ..Default::default()
        }
        .generate(&law);
        let al = align(&run, &law).unwrap();
        assert!(
            (al.driver_offset_deg.value + 150.0).abs() < 0.02,
            "{:?}",
            al.driver_offset_deg
        );
        assert!(al.driver_offset_deg.determined);
    }

    /// Guards the dead band's sign: a follower-side dead band is a width. A run whose
    /// directions are swapped shows a 1° dead band as a −1° one to the free fit; the fit
    /// then holds it at 0 (reporting the free value) and refits, where the true run keeps
    /// its 1° and nothing held.
    #[test]
    fn a_negative_dead_band_is_held_at_zero() {
        let law = smooth_turn();
        let run = SyntheticBench {
            backlash: 1.0,
            reverse_cycles: 3.0,
            noise: 0.01,
            seed: 5,
            ..Default::default()
        }
        .generate(&law);
        let dof = |al: &Alignment| al.dofs[0];
        let al = align(&run, &law).unwrap();
        let b = dof(&al).backlash.unwrap();
        assert!((b.value - 1.0).abs() < 0.02, "{b:?}");
        assert_eq!(dof(&al).backlash_free, None);

        let mut swapped = run.clone();
        for ph in &mut swapped.phase {
            *ph = match *ph {
                Phase::Forward => Phase::Reverse,
                Phase::Reverse => Phase::Forward,
                Phase::Settle => Phase::Settle,
            };
        }
        let al = align(&swapped, &law).unwrap();
        let b = dof(&al).backlash.unwrap();
        assert_eq!((b.value, b.std_err, b.determined), (0.0, 0.0, true));
        let free = dof(&al).backlash_free.expect("the free fit's value");
        assert!((free + 1.0).abs() < 0.02, "free fit {free}");
        assert!(al.driver_offset_deg.value.is_finite());
    }

    /// A linear least-squares fit in the shape `align_scalar`'s closure has: two DOFs share
    /// the slope u (as they share the driver-side lag) and each has its own width bᵢ;
    /// rows (a, y) of DOF i predict a·u + bᵢ.
    fn shared_slope_fit(
        rows: [&'static [(f64, f64)]; 2],
    ) -> impl FnMut(&mut DVector<f64>, &[bool]) -> HeldFit {
        move |p: &mut DVector<f64>, held: &[bool]| {
            let mut out = HeldFit {
                jtj: DMatrix::zeros(3, 3),
                ssr: 0.0,
                pull: DVector::zeros(3),
                column2: DVector::zeros(3),
            };
            // Two rounds: the first lands on the optimum, the second's sums are taken there.
            for _ in 0..2 {
                out.jtj.fill(0.0);
                out.pull.fill(0.0);
                out.column2.fill(0.0);
                out.ssr = 0.0;
                let mut jtr = DVector::zeros(3);
                for (i, dof) in rows.iter().enumerate() {
                    for &(a, y) in dof.iter() {
                        let mut row = [a, 0.0, 0.0];
                        row[1 + i] = 1.0;
                        let r = y - (a * p[0] + p[1 + i]);
                        for k in 0..3 {
                            if held[k] {
                                out.pull[k] += row[k] * r;
                                out.column2[k] += row[k] * row[k];
                                row[k] = 0.0;
                            }
                        }
                        add_row(&mut out.jtj, &mut jtr, &row, r);
                        out.ssr += r * r;
                    }
                }
                fill_lower(&mut out.jtj);
                *p += solve_pinv(&out.jtj, &jtr);
            }
            out
        }
    }

    /// Guards the active set of the widths: when the free fit puts two widths below zero,
    /// holding both can hold one that only the other's negative value pulled down. Here DOF
    /// 1 alone says b₁ = −0.1 and DOF 2 says b₂ = −1 with the same slope 2; with both held
    /// the shared slope falls to 1.67 and DOF 1's residuals all point up, so b₁ is let go
    /// and settles at 0.718 (u = 1.4545), while b₂ stays held. The result is also the best
    /// of all four ways of holding the widths that leave none negative.
    #[test]
    fn a_held_width_the_residuals_pull_up_is_let_go() {
        let rows: [&'static [(f64, f64)]; 2] =
            [&[(1.0, 1.9), (2.0, 3.9)], &[(1.0, 1.0), (2.0, 3.0)]];
        let mut p = DVector::zeros(3);
        let (out, held, free) = fit_widths_nonnegative(&mut p, &[1, 2], shared_slope_fit(rows));
        assert_eq!(held, [false, false, true]);
        assert!((p[0] - 16.0 / 11.0).abs() < 1e-12, "u = {}", p[0]);
        assert!(
            (p[1] - 0.718_181_818_181_818_2).abs() < 1e-12,
            "b1 = {}",
            p[1]
        );
        assert_eq!(p[2], 0.0);
        assert_eq!(free[1], None);
        assert!((free[2].expect("b2 held") + 1.0).abs() < 1e-12, "{free:?}");
        let best = (0..4)
            .filter_map(|mask: usize| {
                let hold = [false, mask & 1 != 0, mask & 2 != 0];
                let mut q = DVector::zeros(3);
                let fit = shared_slope_fit(rows)(&mut q, &hold);
                (q[1] >= 0.0 && q[2] >= 0.0).then_some(fit.ssr)
            })
            .fold(f64::INFINITY, f64::min);
        assert!((out.ssr - best).abs() < 1e-12, "{} against {best}", out.ssr);
    }

    /// Guards the input checks: a 3R target without an IMU column is a clear mismatch.
    #[test]
    fn missing_sensor_is_a_mismatch() {
        let law = TargetLaw::spherical("s", |_| UnitQuaternion::identity(), Vec::new());
        let run = SyntheticBench::default().generate(&smooth_turn());
        let e = align(&run, &law).unwrap_err().to_string();
        assert!(e.contains("IMU"), "{e}");
    }
}
