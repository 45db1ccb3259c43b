//! Bit sets carried on the wire: which sensors (a capability, a configuration and the
//! fields present in a sample batch), per-sample flags and device status flags.
//!
//! Owns the bit assignments; unknown bits are rejected when decoding so that a newer peer
//! cannot be silently misread.

macro_rules! bitset {
    (
        $(#[$meta:meta])*
        $name:ident($repr:ty) {
            $( $(#[$fmeta:meta])* $flag:ident = $bit:expr; )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
        pub struct $name(pub $repr);

        impl $name {
            $( $(#[$fmeta])* pub const $flag: Self = Self(1 << $bit); )*
            /// No bit set.
            pub const EMPTY: Self = Self(0);
            /// Every defined bit.
            pub const ALL: Self = Self(0 $( | (1 << $bit) )*);

            /// The raw bits.
            pub const fn bits(self) -> $repr {
                self.0
            }
            /// The set from raw bits, or `None` if an undefined bit is set.
            pub const fn from_bits(bits: $repr) -> Option<Self> {
                if bits | Self::ALL.0 == Self::ALL.0 { Some(Self(bits)) } else { None }
            }
            /// Whether every bit of `other` is set here.
            pub const fn contains(self, other: Self) -> bool {
                self.0 & other.0 == other.0
            }
            /// Whether no bit is set.
            pub const fn is_empty(self) -> bool {
                self.0 == 0
            }
            /// This set with the bits of `other` added.
            pub const fn union(self, other: Self) -> Self {
                Self(self.0 | other.0)
            }
            /// This set with the bits of `other` removed.
            pub const fn difference(self, other: Self) -> Self {
                Self(self.0 & !other.0)
            }
            /// Set or clear the bits of `other`.
            pub fn set(&mut self, other: Self, on: bool) {
                if on { self.0 |= other.0 } else { self.0 &= !other.0 }
            }
        }

        impl core::ops::BitOr for $name {
            type Output = Self;
            fn bitor(self, rhs: Self) -> Self {
                self.union(rhs)
            }
        }
    };
}

bitset! {
    /// A set of sensors: used for capabilities, the enabled sensors of a configuration and
    /// the fields present in every sample of a batch.
    SensorSet(u8) {
        /// First AS5600 magnetic absolute encoder (12-bit raw angle).
        ENCODER_A = 0;
        /// Second AS5600 (on an I²C mux channel or a second bus).
        ENCODER_B = 1;
        /// Quadrature encoder counter (signed count of edges).
        QUADRATURE = 2;
        /// Orientation sensor (BNO055 fused quaternion).
        IMU = 3;
    }
}

bitset! {
    /// Flags of one sample.
    SampleFlags(u8) {
        /// The IMU quaternion of this sample is new; when clear it repeats the latest value.
        IMU_FRESH = 0;
        /// Encoder A could not be read (the value repeats the last good reading).
        ENCODER_A_FAULT = 1;
        /// Encoder B could not be read.
        ENCODER_B_FAULT = 2;
        /// The IMU could not be read.
        IMU_FAULT = 3;
        /// The motor was stepping at this instant.
        MOVING = 4;
        /// The driver was enabled.
        ENABLED = 5;
        /// The emergency stop was latched.
        ESTOP = 6;
        /// This sample was taken late: at least one sampling tick was missed before it.
        OVERRUN = 7;
    }
}

bitset! {
    /// Device state flags reported in a status.
    StatusFlags(u16) {
        /// A valid configuration has been applied.
        CONFIGURED = 0;
        /// The driver is enabled (EN asserted).
        ENABLED = 1;
        /// Steps are being generated.
        MOVING = 2;
        /// Sample batches are being streamed.
        STREAMING = 3;
        /// The emergency stop is latched (cleared only by `ClearEmergencyStop`).
        ESTOP_LATCHED = 4;
        /// The dead-man watchdog stopped the motor since the last status query.
        WATCHDOG_TRIPPED = 5;
        /// Encoder A answered at its last read.
        ENCODER_A_OK = 6;
        /// Encoder B answered at its last read.
        ENCODER_B_OK = 7;
        /// The IMU answered at its last read.
        IMU_OK = 8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards that undefined bits are refused, defined ones accepted.
    #[test]
    fn from_bits_rejects_undefined_bits() {
        assert_eq!(SensorSet::from_bits(0b1111), Some(SensorSet::ALL));
        assert_eq!(SensorSet::from_bits(0b1_0000), None);
        assert_eq!(SampleFlags::from_bits(0xFF), Some(SampleFlags::ALL));
        assert_eq!(StatusFlags::from_bits(1 << 9), None);
    }

    /// Guards set algebra used by the device for its flags.
    #[test]
    fn set_and_contains_work() {
        let mut s = SensorSet::ENCODER_A | SensorSet::IMU;
        assert!(s.contains(SensorSet::IMU));
        assert!(!s.contains(SensorSet::ENCODER_B));
        s.set(SensorSet::IMU, false);
        assert_eq!(s, SensorSet::ENCODER_A);
        assert!(SensorSet::EMPTY.is_empty());
    }
}
