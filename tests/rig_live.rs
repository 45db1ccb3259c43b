//! `measure --live` as a user's browser meets it (issue 20: a live view): the page's address
//! is printed, the state it polls carries the run's figures and the follower against the
//! target while the simulated stepper bench runs, and its Stop button ends the run as
//! Ctrl-C does (motor stopped, recording kept and marked cancelled, exit 130), with the
//! end shown to the page before the program exits.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use mpc_rig::rig::recording::Recording;
use serde_json::Value;

use crate::support::bench::{repo, stepper_sim};
use crate::support::serial_group;

/// One HTTP request to `host:port`; the status code and the body, or `None` when nothing
/// answers there (the program has exited).
fn http(addr: &str, method: &str, path: &str) -> Option<(u16, String)> {
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: 0\r\n\r\n"
    )
    .ok()?;
    let mut answer = String::new();
    s.read_to_string(&mut answer).ok()?;
    let (head, body) = answer.split_once("\r\n\r\n")?;
    let code = head.split(' ').nth(1)?.parse().ok()?;
    Some((code, body.to_string()))
}

/// Guards the live view end to end on the simulated stepper bench: figures and points while
/// running, the Stop button's effect on the motor, the recording and the exit code, and the
/// end reaching the page.
#[test]
fn the_live_view_follows_the_run_and_its_stop_button_stops_it() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let mut child = Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
        .args(["measure", "--rig"])
        .arg(repo("rigs/sim-stepper.toml"))
        .arg("--port")
        .arg(sim.path())
        .arg("--motion")
        .arg(repo("data/motions/half-turn-2to1.toml"))
        .args([
            "--speed",
            "30",
            "--cycles",
            "20",
            "--no-analysis",
            "--live",
            "-o",
        ])
        .arg(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    let url = first
        .strip_prefix("live view: http://")
        .and_then(|rest| rest.strip_suffix("/ (open it in a browser)\n"))
        .unwrap_or_else(|| panic!("first line: {first:?}"));
    assert!(url.starts_with("127.0.0.1:"), "binds the loopback: {url}");
    // The rest of standard error, kept draining so the child never blocks on it.
    let rest = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });

    let (code, page) = http(url, "GET", "/").unwrap();
    assert_eq!(code, 200);
    assert!(page.contains("<canvas id=\"law\">") && page.contains("id=\"stop\""));

    // Poll as the page does until a second of the forward run has been seen.
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut next = 0u64;
    let mut followed = 0usize;
    let state = loop {
        let (code, body) = http(url, "GET", &format!("/state?since={next}")).unwrap();
        assert_eq!(code, 200);
        let s: Value = serde_json::from_str(&body).unwrap();
        let points = s["points"].as_array().unwrap();
        if let Some(p) = points.first() {
            assert_eq!(
                p["seq"].as_u64(),
                Some(next),
                "the points continue the cursor"
            );
        }
        for p in points {
            if p["phase"] == "forward" && p["aligned"] == true {
                let (f, t, e) = (&p["follower_deg"], &p["target_deg"], &p["error_deg"]);
                let (f, t, e) = (
                    f.as_f64().unwrap(),
                    t.as_f64().unwrap(),
                    e.as_f64().unwrap(),
                );
                assert!((f - t - e).abs() < 1e-9, "follower = target + error: {p}");
                assert!(e.abs() < 1.0, "a faultless bench follows its target: {p}");
                followed += 1;
            }
        }
        next = s["next"].as_u64().unwrap();
        if followed >= 200 {
            break s;
        }
        assert!(
            Instant::now() < deadline,
            "the live view never showed the run: {s}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(state["target"], "half-turn-2to1");
    assert_eq!(state["class"], "1R");
    assert_eq!(state["ended"], Value::Null);
    let status = &state["status"];
    assert_eq!(status["phase"], "forward");
    assert_eq!(status["cycles"], 20);
    assert!(status["samples"].as_u64().unwrap() > 1000, "{status}");
    assert!(
        status["sample_rate_hz"].as_f64().unwrap() > 500.0,
        "{status}"
    );

    let (code, body) = http(url, "POST", "/stop").unwrap();
    assert_eq!((code, body.as_str()), (200, "{\"stop_requested\":true}"));
    // The end reaches the page before the program exits.
    let mut ended = None;
    while let Some((_, body)) = http(url, "GET", &format!("/state?since={next}")) {
        let s: Value = serde_json::from_str(&body).unwrap();
        assert_eq!(s["stop_requested"], true);
        if let Some(e) = s["ended"].as_str() {
            ended = Some(e.to_string());
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let status = child.wait().unwrap();
    let stderr = rest.join().unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(
        stderr.contains("live view: stop requested from the page"),
        "{stderr}"
    );
    let ended = ended.expect("the page saw the end");
    assert_eq!(ended, format!("cancelled (recording {})", dir.display()));

    let rec = Recording::load(&dir).unwrap();
    assert!(!rec.meta.complete);
    assert_eq!(rec.meta.end_reason.as_deref(), Some("cancelled"));
    assert_eq!(rec.meta.counts.samples as usize, rec.len());
    std::thread::sleep(Duration::from_millis(100));
    let motor = sim.stop().unwrap();
    assert!(!motor.enabled && !motor.moving, "{motor:?}");
}
