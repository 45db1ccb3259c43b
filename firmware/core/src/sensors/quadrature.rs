//! Quadrature decoding: turns successive A/B channel levels into a signed edge count.
//!
//! Owns the 4×-decoding transition table and the detection of impossible transitions (both
//! channels changed at once: an edge was missed). It does not read pins: a board calls
//! [`QuadratureDecoder::update`] from a pin-change interrupt or a PIO/timer loop, or uses a
//! hardware counter instead (see [`crate::platform::QuadratureCounter`]).

use crate::platform::QuadratureCounter;

/// Gray-code state of (A, B): 00 → 01 → 11 → 10 → 00 is one direction.
fn state(a: bool, b: bool) -> u8 {
    ((a as u8) << 1) | b as u8
}

/// Count change for a transition `old → new` (index `old << 2 | new`); 2 marks an invalid
/// double change.
const TABLE: [i8; 16] = [
    0, 1, -1, 2, //
    -1, 0, 2, 1, //
    1, 2, 0, -1, //
    2, -1, 1, 0,
];

/// A 4×-resolution quadrature decoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QuadratureDecoder {
    last: u8,
    count: i32,
    errors: u32,
}

impl QuadratureDecoder {
    /// A decoder whose channels currently read `a`, `b`.
    pub fn new(a: bool, b: bool) -> Self {
        Self {
            last: state(a, b),
            count: 0,
            errors: 0,
        }
    }

    /// Feed the present channel levels.
    pub fn update(&mut self, a: bool, b: bool) {
        let s = state(a, b);
        match TABLE[((self.last << 2) | s) as usize] {
            2 => self.errors = self.errors.wrapping_add(1),
            d => self.count = self.count.wrapping_add(d as i32),
        }
        self.last = s;
    }

    /// Transitions where both channels changed at once (edges lost).
    pub fn errors(&self) -> u32 {
        self.errors
    }
}

impl QuadratureCounter for QuadratureDecoder {
    fn count(&mut self) -> i32 {
        self.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORWARD: [(bool, bool); 4] = [(false, false), (false, true), (true, true), (true, false)];

    /// Guards 4× counting in both directions: one full Gray cycle is ±4 counts.
    #[test]
    fn full_cycles_count_four_edges_each() {
        let mut q = QuadratureDecoder::new(false, false);
        for _ in 0..3 {
            for &(a, b) in FORWARD[1..].iter().chain(&FORWARD[..1]) {
                q.update(a, b);
            }
        }
        assert_eq!(q.count(), 12);
        for _ in 0..5 {
            for &(a, b) in FORWARD.iter().rev() {
                q.update(a, b);
            }
        }
        assert_eq!(q.count(), 12 - 20);
        assert_eq!(q.errors(), 0);
    }

    /// Guards that repeated levels count nothing and a double change is an error.
    #[test]
    fn no_change_and_double_change() {
        let mut q = QuadratureDecoder::new(false, false);
        q.update(false, false);
        assert_eq!(q.count(), 0);
        q.update(true, true);
        assert_eq!((q.count(), q.errors()), (0, 1));
    }
}
