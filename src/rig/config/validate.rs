//! Semantic checks of a parsed rig file: what TOML and serde cannot say (a positive gear
//! ratio, a port name that exists, a sensor that fits the driver's kind).
//!
//! Numbers are checked declaratively, one line per field, in the manner of Klipper's
//! `configfile.py` (`getfloat(option, minval=, maxval=, above=, below=)`): a field's
//! [`Bounds`] say what is accepted and also write the message when it is not. Checks that
//! relate fields to each other (names that must exist or differ, sensors a driver can read)
//! are spelled out below. A failure is the field's path ([`Seg`]s, rendered and located by
//! [`super::lines`]) and what is wrong.
//!
//! Owns no defaults and no schema (that is [`super::schema`]).

use super::lines::Seg::{self, Idx, Key};
use super::*;

/// A failed check: where, and what is wrong.
pub(super) type Failure = (Vec<Seg>, String);

/// What a number may be: inclusive `minval` / `maxval`, exclusive `above` / `below`, always
/// finite (Klipper's option names).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct Bounds {
    minval: Option<f64>,
    maxval: Option<f64>,
    above: Option<f64>,
    below: Option<f64>,
    /// What the number is, added to the message.
    note: Option<&'static str>,
}

impl Bounds {
    /// Any finite number.
    pub const FINITE: Bounds = Bounds {
        minval: None,
        maxval: None,
        above: None,
        below: None,
        note: None,
    };
    /// A finite number above 0.
    pub const POSITIVE: Bounds = Bounds::FINITE.above(0.0);

    /// At least `v`.
    pub const fn minval(self, v: f64) -> Bounds {
        Bounds {
            minval: Some(v),
            ..self
        }
    }
    /// At most `v`.
    pub const fn maxval(self, v: f64) -> Bounds {
        Bounds {
            maxval: Some(v),
            ..self
        }
    }
    /// Greater than `v`.
    pub const fn above(self, v: f64) -> Bounds {
        Bounds {
            above: Some(v),
            ..self
        }
    }

    /// Say what the number is in the message (`(motor or servo revolutions per driver
    /// revolution)`).
    pub const fn note(self, what: &'static str) -> Bounds {
        Bounds {
            note: Some(what),
            ..self
        }
    }

    /// Whether `v` is accepted.
    pub fn admits(&self, v: f64) -> bool {
        v.is_finite()
            && self.minval.is_none_or(|m| v >= m)
            && self.maxval.is_none_or(|m| v <= m)
            && self.above.is_none_or(|m| v > m)
            && self.below.is_none_or(|m| v < m)
    }

    /// What is accepted, as the message for a value that is not: "must be a positive
    /// number", "must be a number from 0.001 to 1000", "must be a number above 0 and at most
    /// 180".
    pub fn describe(&self) -> String {
        let note = self.note.map_or(String::new(), |n| format!(" ({n})"));
        if (Bounds {
            note: None,
            ..*self
        }) == Bounds::POSITIVE
        {
            return format!("must be a positive number{note}");
        }
        let mut parts = Vec::new();
        match (self.minval, self.maxval) {
            (Some(lo), Some(hi)) => parts.push(format!("from {lo} to {hi}")),
            (Some(lo), None) => parts.push(format!("at least {lo}")),
            (None, Some(hi)) => parts.push(format!("at most {hi}")),
            (None, None) => {}
        }
        if let Some(a) = self.above {
            parts.insert(0, format!("above {a}"));
        }
        if let Some(b) = self.below {
            parts.push(format!("below {b}"));
        }
        if parts.is_empty() {
            format!("must be a finite number{note}")
        } else {
            format!("must be a number {}{note}", parts.join(" and "))
        }
    }
}

/// Limits of the numbers in a rig file, each with its reason where it is not obvious.
mod limits {
    use super::super::{MAX_GEAR_RATIO, MAX_SAMPLE_RATE_HZ};
    use super::Bounds;

    /// Motor or servo revolutions per driver revolution ([`MAX_GEAR_RATIO`]).
    pub const GEAR_RATIO: Bounds = Bounds::FINITE
        .minval(1.0 / MAX_GEAR_RATIO)
        .maxval(MAX_GEAR_RATIO)
        .note("motor or servo revolutions per driver revolution");
    /// What the firmware and the sessions are specified for ([`MAX_SAMPLE_RATE_HZ`]).
    pub const SAMPLE_RATE_HZ: Bounds = Bounds::POSITIVE
        .maxval(MAX_SAMPLE_RATE_HZ)
        .note("samples per second");
    /// The device's dead-man watchdog: at least two 10 ms heartbeats, at most a minute.
    pub const WATCHDOG_MS: Bounds = Bounds::FINITE
        .minval(20.0)
        .maxval(60_000.0)
        .note("milliseconds");
    /// A follower error beyond half a turn is no longer a distance from the target.
    pub const FOLLOWER_ERROR_DEG: Bounds = Bounds::POSITIVE
        .maxval(180.0)
        .note("degrees of follower rotation");
    /// Protocol 2.0 IDs: 253 and up are reserved (254 broadcasts).
    pub const DYNAMIXEL_ID: Bounds = Bounds::FINITE
        .minval(0.0)
        .maxval(252.0)
        .note("a Dynamixel ID");
    /// The firmware's two encoder channels.
    pub const CHANNEL: Bounds = Bounds::FINITE
        .minval(0.0)
        .maxval(1.0)
        .note("the firmware has channels 0 and 1");
}

/// Check `value` of field `key` under `at` against `bounds`.
fn number(at: &[Seg], key: &'static str, value: f64, bounds: Bounds) -> Result<(), Failure> {
    if bounds.admits(value) {
        Ok(())
    } else {
        Err((path(at, key), bounds.describe()))
    }
}

/// A direction or sign: 1 or −1.
fn sign(at: &[Seg], key: &'static str, value: Sign) -> Result<(), Failure> {
    if value == 1 || value == -1 {
        Ok(())
    } else {
        Err((path(at, key), "must be 1 or -1".into()))
    }
}

/// A port name the rig's `[[ports]]` defines.
fn port(rig: &RigConfig, at: &[Seg], key: &'static str, name: &str) -> Result<(), Failure> {
    if rig.port(name).is_some() {
        Ok(())
    } else {
        Err((path(at, key), format!("no [[ports]] entry named `{name}`")))
    }
}

fn path(at: &[Seg], key: &'static str) -> Vec<Seg> {
    let mut p = at.to_vec();
    p.push(Key(key));
    p
}

fn fail<T>(at: Vec<Seg>, message: impl Into<String>) -> Result<T, Failure> {
    Err((at, message.into()))
}

/// Every semantic check of a rig, in file order; the first failure.
pub(super) fn validate(rig: &RigConfig) -> Result<(), Failure> {
    if rig.name.trim().is_empty() {
        return fail(vec![Key("name")], "must not be empty");
    }
    ports(rig)?;
    driver(rig)?;
    for (i, s) in rig.sensors.iter().enumerate() {
        sensor(rig, i, s)?;
    }
    sensor_board(rig)?;
    number(
        &[Key("sampling")],
        "rate_hz",
        rig.sampling.rate_hz,
        limits::SAMPLE_RATE_HZ,
    )?;
    let safety = [Key("safety")];
    let s = &rig.safety;
    number(&safety, "max_speed_rpm", s.max_speed_rpm, Bounds::POSITIVE)?;
    number(&safety, "max_run_s", s.max_run_s, Bounds::POSITIVE)?;
    number(
        &safety,
        "watchdog_ms",
        f64::from(s.watchdog_ms),
        limits::WATCHDOG_MS,
    )?;
    number(
        &safety,
        "max_follower_error_deg",
        s.max_follower_error_deg,
        limits::FOLLOWER_ERROR_DEG,
    )
}

fn ports(rig: &RigConfig) -> Result<(), Failure> {
    if rig.ports.is_empty() {
        return fail(vec![Key("ports")], "at least one [[ports]] entry is needed");
    }
    for (i, p) in rig.ports.iter().enumerate() {
        let at = [Key("ports"), Idx(i)];
        if rig.ports[..i].iter().any(|q| q.name == p.name) {
            return fail(
                path(&at, "name"),
                format!("port name `{}` is used twice", p.name),
            );
        }
        number(&at, "baud", f64::from(p.baud), Bounds::POSITIVE)?;
    }
    Ok(())
}

fn driver(rig: &RigConfig) -> Result<(), Failure> {
    let at = [Key("driver")];
    match &rig.driver {
        DriverConfig::StepperFirmware(s) => {
            port(rig, &at, "port", &s.port)?;
            number(
                &at,
                "steps_per_rev",
                f64::from(s.steps_per_rev),
                Bounds::POSITIVE,
            )?;
            // The firmware's rule, from the wire crate that states it.
            let valid = u16::try_from(s.microsteps)
                .is_ok_and(|m| mpc_wire::command::VALID_MICROSTEPS.contains(&m));
            if !valid {
                return fail(path(&at, "microsteps"), "must be a power of two, 1..=256");
            }
            number(&at, "gear_ratio", s.gear_ratio, limits::GEAR_RATIO)?;
            number(&at, "max_speed_rpm", s.max_speed_rpm, Bounds::POSITIVE)?;
            number(&at, "max_accel", s.max_accel, Bounds::POSITIVE)?;
            sign(&at, "direction", s.direction)
        }
        DriverConfig::Dynamixel(d) => {
            port(rig, &at, "port", &d.port)?;
            number(&at, "id", f64::from(d.id), limits::DYNAMIXEL_ID)?;
            number(&at, "baud", f64::from(d.baud), Bounds::POSITIVE)?;
            number(&at, "gear_ratio", d.gear_ratio, limits::GEAR_RATIO)?;
            sign(&at, "direction", d.direction)
        }
    }
}

/// Recording columns whose names a sensor may not take.
const RESERVED_COLUMNS: [&str; 5] = [
    "device_time_us",
    "host_time_s",
    "phase",
    "driver_angle_deg",
    "flags",
];

fn sensor(rig: &RigConfig, i: usize, s: &SensorConfig) -> Result<(), Failure> {
    let at = [Key("sensors"), Idx(i)];
    let name = s.name();
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return fail(
            path(&at, "name"),
            "must be non-empty and use only letters, digits, `_` and `-`",
        );
    }
    if RESERVED_COLUMNS.contains(&name) {
        return fail(
            path(&at, "name"),
            format!("`{name}` is a reserved column name"),
        );
    }
    let cols = s.columns();
    for (j, other) in rig.sensors[..i].iter().enumerate() {
        if other
            .columns()
            .iter()
            .any(|c| cols.iter().any(|d| d.name == c.name))
        {
            return fail(
                path(&at, "name"),
                format!("column name clashes with sensors[{j}] `{}`", other.name()),
            );
        }
    }
    match s {
        SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => {
            number(&at, "channel", f64::from(e.channel), limits::CHANNEL)?;
            sign(&at, "sign", e.sign)?;
            match (e.dof, e.counts_per_rev, e.mm_per_count) {
                (Dof::Rz, Some(c), _) => number(&at, "counts_per_rev", c, Bounds::POSITIVE)?,
                (Dof::Rz, None, _) if matches!(s, SensorConfig::As5600(_)) => {}
                (Dof::Rz, None, _) => {
                    return fail(
                        path(&at, "counts_per_rev"),
                        "needed for a rotary (dof = \"rz\") encoder",
                    )
                }
                (Dof::Tz, _, Some(m)) if m.is_finite() && m != 0.0 => {}
                (Dof::Tz, _, _) => {
                    return fail(
                        path(&at, "mm_per_count"),
                        "needed (non-zero) for a linear (dof = \"tz\") encoder",
                    )
                }
            }
            number(&at, "zero_offset", e.zero_offset, Bounds::FINITE)?;
        }
        SensorConfig::Imu(m) => {
            let n = m.mounting.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !n.is_finite() || (n - 1.0).abs() > MOUNTING_NORM_TOLERANCE {
                return fail(
                    path(&at, "mounting"),
                    format!("must be a unit quaternion [w, x, y, z] (norm is {n:.4})"),
                );
            }
        }
        SensorConfig::Dynamixel(d) => {
            port(rig, &at, "port", &d.port)?;
            number(&at, "id", f64::from(d.id), limits::DYNAMIXEL_ID)?;
            if let DriverConfig::Dynamixel(drv) = &rig.driver {
                if drv.port == d.port && drv.id == d.id {
                    return fail(path(&at, "id"), "same id as the driver servo");
                }
            }
            number(&at, "counts_per_rev", d.counts_per_rev, Bounds::POSITIVE)?;
            sign(&at, "sign", d.sign)?;
        }
    }
    // Who reads the sensor: the stepper firmware's board, a `[sensor_board]`, or the
    // driver's Dynamixel bus.
    if s.is_firmware()
        && matches!(rig.driver, DriverConfig::Dynamixel(_))
        && rig.sensor_board.is_none()
    {
        return fail(
            path(&at, "kind"),
            "a firmware sensor on a Dynamixel-driven rig needs our firmware board: add `[sensor_board]` with the board's `port`",
        );
    }
    if let SensorConfig::Dynamixel(d) = s {
        match &rig.driver {
            DriverConfig::Dynamixel(drv) if drv.port != d.port => {
                return fail(
                    path(&at, "port"),
                    format!(
                        "a follower servo must be on the driver's bus `{}` (one Dynamixel bus per rig)",
                        drv.port
                    ),
                );
            }
            DriverConfig::StepperFirmware(_) => {
                return fail(
                    path(&at, "kind"),
                    "a Dynamixel follower encoder needs a Dynamixel driver on its bus; a stepper-firmware rig measures the follower with firmware sensors (as5600, quadrature, imu)",
                );
            }
            DriverConfig::Dynamixel(_) => {}
        }
    }
    Ok(())
}

fn sensor_board(rig: &RigConfig) -> Result<(), Failure> {
    let Some(board) = &rig.sensor_board else {
        return Ok(());
    };
    let at = [Key("sensor_board")];
    match &rig.driver {
        DriverConfig::StepperFirmware(_) => {
            return fail(
                path(&at, "port"),
                "the stepper-firmware driver's board reads the firmware sensors; `[sensor_board]` is only for a Dynamixel-driven rig",
            );
        }
        DriverConfig::Dynamixel(d) if d.port == board.port => {
            return fail(
                path(&at, "port"),
                format!(
                    "`{}` is the Dynamixel bus; the firmware board needs a port of its own",
                    board.port
                ),
            );
        }
        DriverConfig::Dynamixel(_) => {}
    }
    port(rig, &at, "port", &board.port)?;
    if !rig.sensors.iter().any(SensorConfig::is_firmware) {
        return fail(
            path(&at, "port"),
            "the sensor board reads no sensor: add a firmware sensor (as5600, quadrature, imu) or remove `[sensor_board]`",
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the declarative bounds: what each admits (finite only, inclusive min/max,
    /// exclusive above) and the message it writes for what it does not.
    #[test]
    fn bounds_admit_and_describe() {
        assert!(Bounds::POSITIVE.admits(1e-9));
        assert!(!Bounds::POSITIVE.admits(0.0));
        assert!(!Bounds::POSITIVE.admits(f64::INFINITY));
        assert!(!Bounds::FINITE.admits(f64::NAN));
        assert!(limits::GEAR_RATIO.admits(0.001) && limits::GEAR_RATIO.admits(1000.0));
        assert!(!limits::GEAR_RATIO.admits(1e9));
        assert_eq!(Bounds::POSITIVE.describe(), "must be a positive number");
        assert_eq!(
            limits::GEAR_RATIO.describe(),
            "must be a number from 0.001 to 1000 (motor or servo revolutions per driver revolution)"
        );
        assert_eq!(
            limits::FOLLOWER_ERROR_DEG.describe(),
            "must be a number above 0 and at most 180 (degrees of follower rotation)"
        );
        assert_eq!(Bounds::FINITE.describe(), "must be a finite number");
    }
}
