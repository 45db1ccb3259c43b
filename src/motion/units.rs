//! A motion read at the bench's scale: model units as millimetres and "per period" as
//! "per second" at a driver speed.
//!
//! Motions and synthesis work in model units and in fractions of one period (one driver
//! revolution); that is what the paper and the files speak. A person at the bench reads
//! millimetres and seconds (issue 20). [`BenchScale`] is the one place that converts: a
//! length in model units times `scale_mm`, a rate per period times the periods per second
//! at the driver speed. Commands show both where a person reads a figure: the model units
//! that match the files, and the millimetres and seconds that match the parts and the bench.
//!
//! This module converts and words figures; it does not decide the scale (a mechanism file's
//! `scale_mm`, else [`super::DEFAULT_SCALE_MM`]) or the speed (the command's `--speed`, else
//! [`DEFAULT_BENCH_RPM`]).

use super::DEFAULT_SCALE_MM;

/// The driver speed a figure "per second" assumes unless told otherwise, rpm: the default
/// `--speed` of `measure` and `demo` (one owner: both take their default from here). 30 rpm
/// is one period in 2 s: slow enough for a printed prototype's first run, fast enough that a
/// 3 + 3 cycle measurement takes a quarter of a minute.
pub const DEFAULT_BENCH_RPM: f64 = 30.0;

/// Millimetres per model unit and the driver speed a rate per second is read at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchScale {
    /// Millimetres per model unit (a mechanism file's `scale_mm`).
    pub scale_mm: f64,
    /// Driver speed, rpm: one period is one driver revolution.
    pub rpm: f64,
}

impl Default for BenchScale {
    fn default() -> Self {
        BenchScale {
            scale_mm: DEFAULT_SCALE_MM,
            rpm: DEFAULT_BENCH_RPM,
        }
    }
}

impl BenchScale {
    /// A scale, or why it cannot be one.
    pub fn new(scale_mm: f64, rpm: f64) -> Result<BenchScale, String> {
        if !(scale_mm.is_finite() && scale_mm > 0.0) {
            return Err(format!(
                "scale {scale_mm} mm per model unit must be a positive number"
            ));
        }
        if !(rpm.is_finite() && rpm > 0.0) {
            return Err(format!("speed {rpm} rpm must be a positive number"));
        }
        Ok(BenchScale { scale_mm, rpm })
    }

    /// Seconds per period (one driver revolution).
    pub fn period_s(&self) -> f64 {
        60.0 / self.rpm
    }

    /// Periods per second.
    fn per_s_factor(&self) -> f64 {
        self.rpm / 60.0
    }

    /// A length in model units, in millimetres.
    pub fn mm(&self, units: f64) -> f64 {
        units * self.scale_mm
    }

    /// A rate per period (e.g. model units or radians per period), per second.
    pub fn per_s(&self, per_period: f64) -> f64 {
        per_period * self.per_s_factor()
    }

    /// A rate per period² (an acceleration), per second².
    pub fn per_s2(&self, per_period2: f64) -> f64 {
        per_period2 * self.per_s_factor() * self.per_s_factor()
    }

    /// A speed, `"30 rpm"`, for axis labels and figures.
    pub fn speed_text(&self) -> String {
        format!("{} rpm", trim(self.rpm, 2))
    }

    /// What the scale says, in words: `"1 model unit = 10 mm; one period (a driver turn) =
    /// 2 s at 30 rpm"`.
    pub fn describe(&self) -> String {
        format!(
            "1 model unit = {} mm; {}",
            trim(self.scale_mm, 3),
            self.describe_period()
        )
    }

    /// The time half, for a motion without lengths: `"one period (a driver turn) = 2 s at
    /// 30 rpm"`.
    pub fn describe_period(&self) -> String {
        format!(
            "one period (a driver turn) = {} s at {}",
            trim(self.period_s(), 3),
            self.speed_text()
        )
    }
}

/// A number with at most `decimals` decimals and no trailing zeros (`10`, `2.5`, `0.667`),
/// without the sign of a value that rounds to zero ([`fixed`]).
pub fn trim(x: f64, decimals: usize) -> String {
    let s = fixed(x, decimals);
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `v` with exactly `decimals` decimals, without the sign of a value that rounds to zero:
/// "-0.000" reads as a negative figure where there is none (issue 20).
pub fn fixed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the conversions every command's mm and per-second figures rest on: a period
    /// is one driver turn, so at 30 rpm it lasts 2 s and a rate per period halves.
    #[test]
    fn converts_lengths_and_rates_at_the_bench_speed() {
        let s = BenchScale::new(10.0, 30.0).unwrap();
        assert_eq!(s.period_s(), 2.0);
        assert_eq!(s.mm(1.5), 15.0);
        assert_eq!(s.per_s(std::f64::consts::TAU), std::f64::consts::PI);
        assert_eq!(s.per_s2(8.0), 2.0);
        assert_eq!(
            s.describe(),
            "1 model unit = 10 mm; one period (a driver turn) = 2 s at 30 rpm"
        );
        assert_eq!(
            BenchScale::new(12.5, 45.0).unwrap().describe(),
            "1 model unit = 12.5 mm; one period (a driver turn) = 1.333 s at 45 rpm"
        );
        assert_eq!(BenchScale::default(), s);
    }

    /// Guards the refusals of a scale no figure can be read at, worded whole.
    #[test]
    fn refuses_a_scale_or_speed_that_is_not_positive() {
        assert_eq!(
            BenchScale::new(0.0, 30.0).unwrap_err(),
            "scale 0 mm per model unit must be a positive number"
        );
        assert_eq!(
            BenchScale::new(10.0, f64::NAN).unwrap_err(),
            "speed NaN rpm must be a positive number"
        );
    }

    /// Guards the two number forms, fixed decimals and no trailing zeros: neither shows a
    /// negative zero.
    #[test]
    fn trims_numbers() {
        assert_eq!(trim(10.0, 3), "10");
        assert_eq!(trim(2.50, 3), "2.5");
        assert_eq!(trim(-0.0001, 3), "0");
        assert_eq!(trim(0.6666, 3), "0.667");
        assert_eq!(fixed(-0.04, 1), "0.0");
        assert_eq!(fixed(-0.06, 1), "-0.1");
        assert_eq!(fixed(2.5, 2), "2.50");
    }
}
