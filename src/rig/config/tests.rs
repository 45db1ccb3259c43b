//! Loading, validation messages and calibration of rig files.

use super::*;
use nalgebra::UnitQuaternion;

const GOOD: &str = r#"
name = "test"
[[ports]]
name = "fw"
path = "/dev/null"

[driver]
kind = "stepper-firmware"
port = "fw"
steps_per_rev = 200
microsteps = 16
max_speed_rpm = 60
max_accel = 720

[[sensors]]
kind = "as5600"
name = "follower"
dof = "rz"
sign = -1
zero_offset = 100

[[sensors]]
kind = "imu"
name = "imu"
mounting = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
"#;

fn load(text: &str) -> Result<RigConfig, ConfigError> {
    RigConfig::from_toml_str(text, Path::new("rigs/t.toml"))
}

/// Guards: a valid file loads with defaults filled in and columns in sensor order.
#[test]
fn loads_valid_config_with_defaults() {
    let cfg = load(GOOD).unwrap();
    assert_eq!(cfg.sampling.rate_hz, DEFAULT_SAMPLE_RATE_HZ);
    assert_eq!(cfg.safety.watchdog_ms, DEFAULT_WATCHDOG_MS);
    let cols: Vec<_> = cfg.sensor_columns().into_iter().map(|c| c.name).collect();
    assert_eq!(
        cols,
        ["follower_counts", "imu_qw", "imu_qx", "imu_qy", "imu_qz"]
    );
    let DriverConfig::StepperFirmware(s) = &cfg.driver else {
        panic!()
    };
    assert_eq!(s.microsteps_per_driver_rev(), 3200.0);
    assert!((s.steps_to_driver_deg(1600) - 180.0).abs() < 1e-12);
}

/// Guards: a semantic error names file, line and field.
#[test]
fn invalid_value_names_file_line_and_field() {
    let text = GOOD.replace("microsteps = 16", "microsteps = 12");
    let err = load(&text).unwrap_err().to_string();
    assert_eq!(
        err,
        "rigs/t.toml:11: field `driver.microsteps`: must be a power of two, 1..=256"
    );
    let text = GOOD.replace("sign = -1", "sign = 2");
    let err = load(&text).unwrap_err().to_string();
    assert!(
        err.starts_with("rigs/t.toml:19: field `sensors[0].sign`"),
        "{err}"
    );
}

/// Guards: unknown fields and wrong types are parse errors with a line.
#[test]
fn unknown_field_is_rejected_with_line() {
    let text = GOOD.replace(
        "steps_per_rev = 200",
        "steps_per_rev = 200\nstep_per_rev = 1",
    );
    let err = load(&text).unwrap_err();
    match &err {
        ConfigError::Parse { line, message, .. } => {
            assert!(message.contains("step_per_rev"), "{message}");
            assert_eq!(*line, 11);
        }
        other => panic!("{other}"),
    }
}

/// Guards: the shipped mixed rig (Dynamixel driver + firmware board) loads, splits into
/// its two devices' parts in column order, and each misuse of `[sensor_board]` is an
/// error naming the field.
#[test]
fn mixed_rig_loads_and_sensor_board_misuse_is_rejected() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/sim-dynamixel-imu.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let cfg = load(&text).unwrap();
    assert!(cfg.is_mixed());
    assert_eq!(cfg.part(true).sensors.len(), 1);
    assert!(cfg.part(false).sensors.is_empty());
    let cases = [
        (
            text.replace("[sensor_board]\nport = \"board\"", ""),
            "sensors[0].kind",
            "needs our firmware board",
        ),
        (
            text.replace(
                "[sensor_board]\nport = \"board\"",
                "[sensor_board]\nport = \"dxl\"",
            ),
            "sensor_board.port",
            "is the Dynamixel bus",
        ),
        (
            text.replace(
                "[sensor_board]\nport = \"board\"",
                "[sensor_board]\nport = \"pico\"",
            ),
            "sensor_board.port",
            "no [[ports]] entry named `pico`",
        ),
    ];
    for (t, field, msg) in cases {
        let err = load(&t).unwrap_err().to_string();
        assert!(
            err.contains(&format!("field `{field}`")) && err.contains(msg),
            "{err}"
        );
    }
    // A board on a stepper-firmware rig is refused.
    let err = load(&format!("{GOOD}\n[sensor_board]\nport = \"fw\"\n"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sensor_board.port") && err.contains("only for a Dynamixel-driven rig"),
        "{err}"
    );
}

/// Guards: a reference to a port that does not exist is caught.
#[test]
fn dangling_port_reference_is_rejected() {
    let text = GOOD.replace("port = \"fw\"", "port = \"nope\"");
    let err = load(&text).unwrap_err().to_string();
    assert!(err.contains("driver.port") && err.contains("nope"), "{err}");
}

/// Guards: raw → physical conversions apply offset, sign and scale.
#[test]
fn to_physical_applies_calibration() {
    let cfg = load(GOOD).unwrap();
    let enc = &cfg.sensors[0];
    // AS5600 without counts_per_rev uses its 4096 counts per turn.
    assert_eq!(enc.counts_per_rev(), Some(4096.0));
    assert!((enc.to_physical(100.0 + 1024.0).unwrap() + 90.0).abs() < 1e-12);
    let SensorConfig::Imu(imu) = &cfg.sensors[1] else {
        panic!()
    };
    // IMU mounted turned +90° about z: an IMU reading of +90° about z is follower rest.
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    assert!(imu.follower_rotation(q).angle() < 1e-12);
}

/// Guards: `--port` overrides by bare path (single port) or by NAME=PATH.
#[test]
fn port_overrides() {
    let mut cfg = load(GOOD).unwrap();
    cfg.apply_port_overrides(&["/dev/ttyX".into()]).unwrap();
    assert_eq!(cfg.ports[0].path.as_deref(), Some(Path::new("/dev/ttyX")));
    cfg.apply_port_overrides(&["fw=/dev/ttyY".into()]).unwrap();
    assert_eq!(cfg.ports[0].path.as_deref(), Some(Path::new("/dev/ttyY")));
    let err = cfg.apply_port_overrides(&["dxl=/dev/ttyZ".into()]);
    assert!(err.unwrap_err().to_string().contains("no port named `dxl`"));
}

/// Guards: the Dynamixel driver and follower-encoder variants parse (dxl's rigs).
#[test]
fn dynamixel_variants_parse() {
    let text = r#"
name = "dxl"
[[ports]]
name = "bus"
baud = 57600
[driver]
kind = "dynamixel"
port = "bus"
id = 1
model = "XL430-W250"
mode = "velocity"
profile_acceleration = 50
[[sensors]]
kind = "dynamixel"
name = "follower"
port = "bus"
id = 2
"#;
    let cfg = load(text).unwrap();
    assert_eq!(cfg.sensors[0].counts_per_rev(), Some(4096.0));
    let DriverConfig::Dynamixel(d) = &cfg.driver else {
        panic!()
    };
    assert_eq!(d.mode, DynamixelMode::Velocity);
    assert_eq!(d.baud, 57600);
    let clash = text.replace("id = 2", "id = 1");
    let err = load(&clash).unwrap_err().to_string();
    assert!(err.contains("sensors[0].id"), "{err}");
}

/// Guards: the config round-trips through JSON (it is embedded in the sidecar).
#[test]
fn json_round_trip() {
    let cfg = load(GOOD).unwrap();
    let json = serde_json::to_string(&cfg).unwrap();
    let back: RigConfig = serde_json::from_str(&json).unwrap();
    assert_eq!(cfg, back);
}
