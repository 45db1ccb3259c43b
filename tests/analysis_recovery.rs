//! The analysis recovers imperfections injected into synthetic recordings: driver-angle and
//! sensor offsets, lag, backlash, noise, timing distortions, gaps, and 3R frame offsets.
//! Each test states the tolerance it holds the estimator to.

use mpc_rig::analysis::synthetic::{piecewise_half_turn, smooth_turn, SyntheticBench};
use mpc_rig::analysis::target::{KeyPose, TargetLaw};
use mpc_rig::analysis::{analyze, AnalysisOptions};
use nalgebra::UnitQuaternion;

fn opts() -> AnalysisOptions {
    AnalysisOptions::default()
}

/// Guards alignment: a 3° driver-angle offset and a 5° sensor offset on a smooth law with
/// 0.05° noise are recovered within 0.02°, and the aligned RMS error equals the noise
/// within 5 %, while the unaligned error is large.
#[test]
fn recovers_driver_and_sensor_offsets() {
    let law = smooth_turn();
    let bench = SyntheticBench {
        driver_offset_deg: 3.0,
        rz_offset_deg: -5.0,
        noise: 0.05,
        forward_cycles: 3.0,
        seed: 7,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    let d = a.alignment.driver_offset_deg;
    assert!((d.value - 3.0).abs() < 0.02, "driver offset {d:?}");
    let c = a.alignment.dofs[0].sensor_offset;
    assert!((c.value + 5.0).abs() < 0.02, "sensor offset {c:?}");
    let rz = &a.channels[0];
    assert!(
        (rz.overall.rms / 0.05 - 1.0).abs() < 0.05,
        "rms {}",
        rz.overall.rms
    );
    assert!(rz.unaligned.unwrap().rms > 4.0);
    assert!(a.backlash.is_none());
}

/// Guards backlash separation: with forward and reverse runs, a 2° driver-side dead band
/// (the rig plant's kind), a 1° follower-side dead band and a 1.5° phase lag are recovered
/// within 0.1° each, and the model-free hysteresis lies between the follower dead band and
/// the sum of both effects at the law's steepest slope.
#[test]
fn recovers_driver_and_follower_backlash_and_phase_lag() {
    let law = piecewise_half_turn(2.0 / 3.0);
    let bench = SyntheticBench {
        driver_offset_deg: 1.5,
        driver_backlash_deg: 2.0,
        backlash: 1.0,
        noise: 0.02,
        forward_cycles: 3.0,
        reverse_cycles: 3.0,
        seed: 11,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    assert!(a.alignment.both_directions);
    let lag = a.phase_lag.driver_deg;
    assert!((lag.value - 1.5).abs() < 0.1, "phase lag {lag:?}");
    let ms = a.phase_lag.ms.unwrap();
    assert!((ms - 1.5 / 60.0 * 1e3).abs() < 2.0, "{ms} ms");
    let b = a.backlash.as_ref().unwrap();
    assert!(
        (b.driver_deg.value - 2.0).abs() < 0.1,
        "driver backlash {:?}",
        b.driver_deg
    );
    let (dof, fb) = b.follower[0];
    assert_eq!(dof, mpc_rig::analysis::Dof::Rz);
    assert!((fb.value - 1.0).abs() < 0.1, "follower backlash {fb:?}");
    let h = a.channels[0].hysteresis.unwrap();
    assert!(
        h.mean > 1.0 && h.mean < 1.0 + 2.0 * 1.5 + 0.2,
        "hysteresis {h:?}"
    );
}

/// Guards time-lag recovery: a 50 ms lag at 10 rpm (3° of driver angle, changing sign with
/// the direction) appears as a 6° driver-side dead band equivalent within 0.1°.
#[test]
fn time_lag_shows_as_direction_dependent_offset() {
    let law = smooth_turn();
    let bench = SyntheticBench {
        lag_s: 0.05,
        noise: 0.02,
        forward_cycles: 2.0,
        reverse_cycles: 2.0,
        seed: 12,
        ..Default::default()
    };
    let a = analyze(&bench.generate(&law), &law, &opts()).unwrap();
    let b = a.backlash.unwrap().driver_deg;
    assert!((b.value - 6.0).abs() < 0.1, "{b:?}");
    assert!(a.phase_lag.driver_deg.value.abs() < 0.1);
}

/// Guards the timing estimator's exactness: on a noiseless piecewise-linear 2:1 law (kinks
/// between samples, at the 180° and 360° crossings) the measured ratio is 2 to 1e-9, and so
/// is the driver-angle span ratio.
#[test]
fn timing_is_exact_on_noiseless_piecewise_linear_law() {
    let law = piecewise_half_turn(2.0 / 3.0);
    let bench = SyntheticBench {
        rate_hz: 997.0, // not a divisor of the period: kinks fall between samples
        forward_cycles: 4.0,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    let t = a.timing.unwrap();
    assert!(t.cycles.len() >= 3, "{} cycles", t.cycles.len());
    let r = t.ratios[0];
    assert!((r.target - 2.0).abs() < 1e-9, "target {}", r.target);
    assert!((r.measured - 2.0).abs() < 1e-9, "measured {}", r.measured);
    assert!((r.measured_span_ratio - 2.0).abs() < 1e-9);
    for c in &t.cycles {
        assert!(
            (c.ratios[0] - 2.0).abs() < 1e-9,
            "cycle {} ratio {}",
            c.cycle,
            c.ratios[0]
        );
        assert!((c.spans_deg[0] - 240.0).abs() < 1e-6);
    }
}

/// Guards the timing estimator under noise and quantization: over 20 seeds, a distorted
/// mechanism (first half-turn in 70 % of the period, true ratio 7/3) measured with 0.05°
/// noise and AS5600 quantization is within its own reported U95 in at least 18 runs and
/// within 2·U95 in all, while the target ratio is still reported as 2.
#[test]
fn timing_ratio_within_reported_uncertainty_under_noise() {
    let target = piecewise_half_turn(2.0 / 3.0);
    let actual = piecewise_half_turn(0.7);
    let truth = 0.7 / 0.3;
    let mut inside = 0;
    for seed in 0..20 {
        let bench = SyntheticBench {
            noise: 0.05,
            quantum: 360.0 / 4096.0,
            forward_cycles: 3.0,
            rate_hz: 500.0,
            seed,
            ..Default::default()
        };
        let run = bench.generate(&actual);
        let a = analyze(&run, &target, &opts()).unwrap();
        let r = a.timing.unwrap().ratios[0];
        assert!((r.target - 2.0).abs() < 1e-9);
        let err = (r.measured - truth).abs();
        assert!(r.u95 > 0.0 && r.u95 < 0.05, "u95 {}", r.u95);
        assert!(
            err <= 2.0 * r.u95,
            "seed {seed}: {} vs {truth} ± {}",
            r.measured,
            r.u95
        );
        if err <= r.u95 {
            inside += 1;
        }
    }
    assert!(inside >= 18, "{inside}/20 within U95");
}

/// Guards user-named crossings: `--timing 0,90,180,270,360` gives three consecutive
/// ratios, each matching the piecewise law's true ratios.
#[test]
fn user_named_crossings_give_all_consecutive_ratios() {
    let law = piecewise_half_turn(2.0 / 3.0);
    let run = SyntheticBench::default().generate(&law);
    let o = AnalysisOptions {
        timing_levels: Some(mpc_rig::analysis::timing::parse_levels("0, 90,180,270,360").unwrap()),
    };
    let t = analyze(&run, &law, &o).unwrap().timing.unwrap();
    let expect = [1.0, 2.0, 1.0];
    for (r, e) in t.ratios.iter().zip(expect) {
        assert!((r.measured - e).abs() < 1e-6, "{r:?}");
        assert!((r.target - e).abs() < 1e-9);
    }
    assert!(mpc_rig::analysis::timing::parse_levels("0,180,180").is_err());
    assert!(mpc_rig::analysis::timing::parse_levels("0,x").is_err());
}

/// Guards sample-rate statistics and cycle bookkeeping: 2 % dropped samples are counted as
/// gaps with the right number of missing samples (±10 %), and per-cycle statistics cover
/// every forward cycle with the complete ones at full coverage.
#[test]
fn gaps_and_cycles_are_reported() {
    let law = smooth_turn();
    let bench = SyntheticBench {
        drop_probability: 0.02,
        noise: 0.01,
        forward_cycles: 3.0,
        seed: 3,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    let expected_missing = 0.02 * (4.0 * 6.0 * 1000.0);
    let m = a.sampling.missing_samples_estimate as f64;
    assert!((m / expected_missing - 1.0).abs() < 0.1, "missing {m}");
    assert!(a.sampling.gaps > 0);
    let complete: Vec<_> = a.channels[0]
        .per_cycle
        .iter()
        .filter(|c| c.coverage >= 0.99)
        .collect();
    assert_eq!(complete.len(), 3, "{:?}", a.channels[0].per_cycle);
    let rep = a.channels[0].repeatability.unwrap();
    assert!(rep.rms_std < 0.01, "{rep:?}");
}

fn figure_eight_like() -> TargetLaw {
    let rot = |t: f64| {
        let w = 2.0 * std::f64::consts::PI * t;
        UnitQuaternion::from_euler_angles(0.5 * w.sin(), 0.35 * (2.0 * w).sin(), 0.4 * w.cos())
    };
    let keys = (0..4)
        .map(|k| {
            let t = k as f64 / 4.0;
            KeyPose {
                t,
                rotation: rot(t),
            }
        })
        .collect();
    TargetLaw::spherical("eight", rot, keys)
}

/// Guards 3R alignment: an IMU heading offset of 30°, a 2° mounting error and a 4°
/// driver-angle offset with 0.1° per-axis noise are removed; the driver offset is recovered
/// within 0.05° and the geodesic RMS error is the noise's (√3·0.1° within 10 %); key poses
/// are all passed with small errors.
#[test]
fn recovers_3r_frame_offsets_and_driver_offset() {
    let law = figure_eight_like();
    let bench = SyntheticBench {
        driver_offset_deg: 4.0,
        noise: 0.1,
        world_offset: UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians()),
        mount_offset: UnitQuaternion::from_euler_angles(2f64.to_radians(), 0.0, 0.0),
        forward_cycles: 2.0,
        rate_hz: 200.0,
        seed: 5,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    assert_eq!(a.class, "3R");
    let d = a.alignment.driver_offset_deg.value;
    assert!((d - 4.0).abs() < 0.05, "driver offset {d}");
    let rms = a.channels[0].overall.rms;
    let expect = 3f64.sqrt() * 0.1;
    assert!((rms / expect - 1.0).abs() < 0.1, "rms {rms} vs {expect}");
    assert_eq!(a.key_poses.len(), 4);
    for k in &a.key_poses {
        assert!(k.passes >= 2 && k.mean_deg < 0.5, "{k:?}");
    }
}

/// Guards 3R lag and backlash visibility: with reverse runs and a 1.5° dead band the
/// forward/reverse hysteresis of the error rotation is about the dead band (1–2.5°).
#[test]
fn shows_3r_hysteresis() {
    let law = figure_eight_like();
    let bench = SyntheticBench {
        backlash: 1.5,
        forward_cycles: 2.0,
        reverse_cycles: 2.0,
        rate_hz: 100.0,
        seed: 9,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &opts()).unwrap();
    let h = a.rotation_hysteresis.unwrap();
    assert!(h.mean > 1.0 && h.mean < 2.5, "{h:?}");
}

/// Guards determinism: the same seed gives bit-identical figures, a different seed does not.
#[test]
fn same_seed_same_figures() {
    let law = smooth_turn();
    let mk = |seed| {
        let bench = SyntheticBench {
            noise: 0.1,
            driver_offset_deg: 2.0,
            seed,
            ..Default::default()
        };
        let a = analyze(&bench.generate(&law), &law, &opts()).unwrap();
        (
            a.alignment.driver_offset_deg.value,
            a.channels[0].overall.rms,
        )
    };
    assert_eq!(mk(1), mk(1));
    assert_ne!(mk(1), mk(2));
}
