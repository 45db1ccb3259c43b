//! Dynamixel X-series model names and the model numbers they report on ping (e-manual).
//!
//! Owns only the name ↔ number table the backend uses to check that the servo on the bus is
//! the one the rig file names. Every model listed shares the XL430 control table layout the
//! backend relies on (addresses 11, 44, 64, 98, 104, 108, 112, 116, 120, 128, 132, the
//! indirect addresses at 168 and data at 224) and 4096 pulses per revolution.

/// (name, model number) of the X-series servos with the shared "X430/X540" control table.
pub const MODELS: &[(&str, u16)] = &[
    ("XL430-W250", 1060),
    ("2XL430-W250", 1090),
    ("XC430-W150", 1070),
    ("XC430-W240", 1080),
    ("2XC430-W250", 1160),
    ("XM430-W210", 1030),
    ("XM430-W350", 1020),
    ("XH430-W210", 1010),
    ("XH430-W350", 1000),
    ("XH430-V210", 1050),
    ("XH430-V350", 1040),
    ("XM540-W150", 1130),
    ("XM540-W270", 1120),
    ("XH540-W150", 1110),
    ("XH540-W270", 1100),
];

/// Model number for a model name (case-insensitive, a trailing `-T`/`-R` suffix ignored).
pub fn model_number(name: &str) -> Option<u16> {
    let upper = name.trim().to_ascii_uppercase();
    let base = upper
        .strip_suffix("-T")
        .or_else(|| upper.strip_suffix("-R"))
        .unwrap_or(&upper);
    MODELS.iter().find(|(n, _)| *n == base).map(|(_, m)| *m)
}

/// Model name for a model number, if known.
pub fn model_name(number: u16) -> Option<&'static str> {
    MODELS.iter().find(|(_, m)| *m == number).map(|(n, _)| *n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the names used in rig files (XL430-W250 = 1060, XM430-W350 = 1020) and the
    /// tolerance for the `-T` product suffix and letter case.
    #[test]
    fn names_map_to_e_manual_model_numbers() {
        assert_eq!(model_number("XL430-W250"), Some(1060));
        assert_eq!(model_number("xl430-w250-t"), Some(1060));
        assert_eq!(model_number("XM430-W350-R"), Some(1020));
        assert_eq!(model_number("AX-12A"), None);
        assert_eq!(model_name(1030), Some("XM430-W210"));
        assert_eq!(model_name(12), None);
    }
}
