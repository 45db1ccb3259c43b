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
//! follower side (follower units). The fit is a weighted
//! Gauss–Newton least-squares over all measured samples, started from a grid search over δ₀;
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
    /// Follower-side dead band β (DOF units), when both directions were recorded.
    pub backlash: Option<Estimate>,
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
    let mut jtj = DMatrix::<f64>::zeros(np, np);
    let mut ssr = 0.0;
    let mut row = vec![0.0; np];
    for _ in 0..ALIGN_MAX_ITERATIONS {
        jtj.fill(0.0);
        let mut jtr = DVector::<f64>::zeros(np);
        ssr = 0.0;
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
                for a in 0..np {
                    if row[a] == 0.0 {
                        continue;
                    }
                    jtr[a] += row[a] * r;
                    for b in a..np {
                        jtj[(a, b)] += row[a] * row[b];
                    }
                }
                ssr += r * r;
            }
        }
        for a in 0..np {
            for b in 0..a {
                jtj[(a, b)] = jtj[(b, a)];
            }
        }
        let step = solve_ridge(&jtj, &jtr);
        let mut step = step;
        let lim = |v: f64| v.clamp(-ALIGN_MAX_STEP_DEG, ALIGN_MAX_STEP_DEG);
        step[0] = lim(step[0]);
        if both {
            step[1] = lim(step[1]);
        }
        p += &step;
        let small =
            step[0].abs() < ALIGN_TOLERANCE_DEG && (!both || step[1].abs() < ALIGN_TOLERANCE_DEG);
        if small {
            break;
        }
    }
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
                backlash: both.then(|| est(cj + 1)),
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

fn ridge(jtj: &DMatrix<f64>) -> DMatrix<f64> {
    let scale = jtj.diagonal().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut m = jtj.clone();
    for k in 0..m.nrows() {
        m[(k, k)] += 1e-12 * scale.max(1e-300);
    }
    m
}

fn solve_ridge(jtj: &DMatrix<f64>, jtr: &DVector<f64>) -> DVector<f64> {
    let m = ridge(jtj);
    m.clone()
        .cholesky()
        .map(|c| c.solve(jtr))
        .or_else(|| m.lu().solve(jtr))
        .unwrap_or_else(|| DVector::zeros(jtr.len()))
}

fn covariance(jtj: &DMatrix<f64>, sigma2: f64) -> DMatrix<f64> {
    let n = jtj.nrows();
    let inv = ridge(jtj)
        .try_inverse()
        .unwrap_or_else(|| DMatrix::from_element(n, n, f64::INFINITY));
    inv * sigma2
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
                for a in 0..np {
                    jtr[a] += row[a] * e[r];
                    for b in a..np {
                        jtj[(a, b)] += row[a] * row[b];
                    }
                }
                ssr += e[r] * e[r];
            }
        }
        for a in 0..np {
            for b in 0..a {
                jtj[(a, b)] = jtj[(b, a)];
            }
        }
        let step = -solve_ridge(&jtj, &jtr);
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
