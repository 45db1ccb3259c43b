//! The report writer: every file is written, `summary.json` carries units in its field
//! names and a verdict against the tolerances, and the HTML report is self-contained.

use mpc_rig::analysis::report::{write_report, SourceInfo};
use mpc_rig::analysis::synthetic::{piecewise_half_turn, SyntheticBench};
use mpc_rig::analysis::{analyze, AnalysisOptions, ReportOptions};

fn source() -> SourceInfo {
    SourceInfo {
        recording_dir: "synthetic".into(),
        complete: Some(true),
        end_reason: None,
        rows: 0,
        stale_rows: 0,
        held_rows: 0,
        late_rows: 0,
        truncated_last_line: false,
        degraded: None,
        device_counts: serde_json::json!({}),
        target_kind: "motion".into(),
        target_path: "synthetic".into(),
    }
}

/// Guards the report files and verdicts: a 1R run with backlash writes all charts, the
/// Markdown and self-contained HTML reports and a summary whose fields name their units; a
/// loose tolerance passes, a tight one fails and names the missed check.
#[test]
fn writes_all_files_and_judges_tolerances() {
    let law = piecewise_half_turn(2.0 / 3.0);
    let bench = SyntheticBench {
        driver_backlash_deg: 2.0,
        noise: 0.05,
        quantum: 360.0 / 4096.0,
        forward_cycles: 3.0,
        reverse_cycles: 2.0,
        rate_hz: 200.0,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &AnalysisOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let loose = ReportOptions {
        tol_deg: Some(5.0),
        tol_ratio: Some(0.1),
        ..Default::default()
    };
    let s = write_report(dir.path(), &a, &run, &law, source(), &loose).unwrap();
    assert_eq!(s.pass, Some(true), "{:?}", s.checks);
    for f in &s.files {
        let p = dir.path().join(f);
        assert!(
            std::fs::metadata(&p)
                .map(|m| m.len() > 100)
                .unwrap_or(false),
            "{f}"
        );
    }
    for f in [
        "follower_rz.png",
        "error_rz.svg",
        "cycles_rz.png",
        "histogram_rz.png",
        "timing.png",
    ] {
        assert!(
            s.files.iter().any(|x| x == f),
            "{f} missing from {:?}",
            s.files
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert!(json["headline"]["rms_error_deg"].as_f64().unwrap() > 0.0);
    assert!((json["headline"]["timing_ratio_target"].as_f64().unwrap() - 2.0).abs() < 1e-9);
    assert!(json["errors"][0]["overall"]["rms_deg"].is_number());
    assert!(json["lag"]["backlash_driver_deg"].as_f64().unwrap() > 1.5);
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    // Every picture embedded: dense scatters as PNG, the rest as inline SVG (smaller,
    // zoomable), and none linked.
    assert!(html.contains("data:image/png;base64,"));
    assert!(html.contains("<figure role=\"img\" aria-label=\"") && html.contains("<svg "));
    assert!(
        !html.contains("src=\"follower") && !html.contains(".svg\""),
        "HTML must not link external images"
    );
    assert!(
        html.contains("device counters</td><td>"),
        "counters as words, not JSON: {html}"
    );
    assert!(
        !html.contains("{&quot;") && !html.contains("{\"crc"),
        "raw JSON in the HTML"
    );
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(md.contains("PASS") && md.contains("![") && md.contains("follower_rz.png"));

    let tight = ReportOptions {
        tol_deg: Some(0.001),
        ..Default::default()
    };
    let s = write_report(dir.path(), &a, &run, &law, source(), &tight).unwrap();
    assert_eq!(s.pass, Some(false));
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        md.contains("FAIL") && md.contains("rms_error_rz_deg"),
        "{md}"
    );
}

/// Guards the headline of a run without a whole cycle (issue 20: a run that disconnected
/// got "error RMS 0.025°" after a −41° driver offset was fitted on 0 cycles): no error or
/// timing figure is given, the summary says why in these words, and a tolerance counts as
/// missed.
#[test]
fn a_run_without_a_complete_cycle_gets_no_error_figures() {
    let law = piecewise_half_turn(2.0 / 3.0);
    let bench = SyntheticBench {
        driver_offset_deg: -41.0,
        noise: 0.05,
        quantum: 360.0 / 4096.0,
        forward_cycles: 0.7,
        reverse_cycles: 0.0,
        rate_hz: 200.0,
        ..Default::default()
    };
    let run = bench.generate(&law);
    let a = analyze(&run, &law, &AnalysisOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = ReportOptions {
        tol_deg: Some(5.0),
        ..Default::default()
    };
    let s = write_report(dir.path(), &a, &run, &law, source(), &opts).unwrap();
    let h = &s.headline;
    assert_eq!(h.cycles, 0);
    assert_eq!(
        h.not_enough_data.as_deref(),
        Some(
            "not enough data: no complete driver revolution was recorded (a cycle counts \
             when 90 % of it is covered), so no error or timing figures are given; the \
             offsets were fitted on part of a revolution"
        )
    );
    assert_eq!(h.rms_error_deg, None);
    assert_eq!(h.max_error_deg, None);
    assert_eq!(h.timing_ratio_measured, None);
    assert_eq!(s.pass, Some(false));
    assert_eq!(s.checks[0].measured, None);
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        md.contains("**Not enough data: no complete driver revolution"),
        "{md}"
    );
    assert!(!md.contains("Rotation error after alignment"), "{md}");
}

/// Guards the comparison's refusal of a prediction made for another mechanism than the
/// target (whole message, the report not written), and that a prediction for the target
/// itself, or one that names no mechanism (made before digests), is compared.
#[test]
fn a_prediction_for_another_mechanism_is_refused() {
    let mut law = piecewise_half_turn(2.0 / 3.0);
    law.mechanism_digest = Some("a".repeat(64));
    let run = SyntheticBench {
        forward_cycles: 2.0,
        rate_hz: 200.0,
        ..Default::default()
    }
    .generate(&law);
    let a = analyze(&run, &law, &AnalysisOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prediction = dir.path().join("prediction.json");
    let write_prediction = |digest: Option<&str>| {
        crate::analysis_sim_bench::uniform_prediction_for(&prediction, 0.5, digest)
    };
    let opts = ReportOptions {
        prediction: Some(prediction.clone()),
        ..Default::default()
    };
    let out = dir.path().join("report");
    write_prediction(Some(&"b".repeat(64)));
    let err = write_report(&out, &a, &run, &law, source(), &opts).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "invalid option --prediction: {}: a prediction for another mechanism than the \
             target (its \
             mechanism digest is bbbbbbbbbbbb…, the target's aaaaaaaaaaaa…). Predict the \
             target: mpc-rig simulate MECHANISM",
            prediction.display()
        )
    );
    assert!(!out.join("report.md").exists(), "no report written");
    for digest in [Some("a".repeat(64)), None] {
        write_prediction(digest.as_deref());
        let s = write_report(&out, &a, &run, &law, source(), &opts).unwrap();
        assert!(s.prediction.is_some(), "compared with the prediction");
    }
}
