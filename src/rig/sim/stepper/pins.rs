//! Emulated STEP/DIR/EN pins, clock, delay and quadrature counter for the firmware core
//! running in the simulated stepper bench.
//!
//! The STEP pin counts rising edges, signed by the DIR level at the edge and only while
//! the driver is enabled (as an A4988/TMC2209 does); the simulator reads the count after
//! every poll and turns it into motor motion (minus missed steps). Time is simulated: the
//! clock is a counter the simulator advances, and delays return at once. A failed STEP
//! output ([`DriverChip::fail_step_output`]) makes every write to that pin fail, as a
//! shorted or broken STEP line: the firmware then latches its emergency stop.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorKind, ErrorType, OutputPin};

/// A pin write that failed (the STEP output has failed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PinFault;

impl embedded_hal::digital::Error for PinFault {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// Pin levels and step counts of the emulated driver chip.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct DriverPins {
    /// Signed steps taken while enabled (DIR high = +1).
    pub steps: i64,
    /// STEP edges while the driver was disabled (ignored by the chip).
    pub ignored_edges: u64,
    /// STEP level.
    pub step_high: bool,
    /// DIR level.
    pub dir_high: bool,
    /// EN level.
    pub enable_high: bool,
    /// The STEP output has failed: every write to it fails.
    pub step_failed: bool,
}

/// Shared state of the emulated driver chip.
#[derive(Debug, Clone)]
pub struct DriverChip {
    state: Rc<RefCell<DriverPins>>,
    enable_active_low: bool,
}

impl DriverChip {
    /// A chip whose EN input is active low (A4988, TMC2209) or high. EN starts inactive.
    pub fn new(enable_active_low: bool) -> DriverChip {
        DriverChip {
            state: Rc::new(RefCell::new(DriverPins {
                enable_high: enable_active_low,
                ..DriverPins::default()
            })),
            enable_active_low,
        }
    }

    /// Whether the driver is enabled (EN at its active level).
    pub fn enabled(&self) -> bool {
        self.state.borrow().enable_high != self.enable_active_low
    }

    /// Fail the STEP output: from now on every write to it fails.
    pub fn fail_step_output(&self) {
        self.state.borrow_mut().step_failed = true;
    }

    /// Pin state snapshot.
    pub fn pins(&self) -> DriverPins {
        *self.state.borrow()
    }

    /// The STEP pin.
    pub fn step_pin(&self) -> StepPin {
        StepPin(self.clone())
    }

    /// The DIR pin.
    pub fn dir_pin(&self) -> DirPin {
        DirPin(self.clone())
    }

    /// The EN pin.
    pub fn enable_pin(&self) -> EnablePin {
        EnablePin(self.clone())
    }
}

/// STEP output.
pub struct StepPin(DriverChip);
/// DIR output.
pub struct DirPin(DriverChip);
/// EN output.
pub struct EnablePin(DriverChip);

impl ErrorType for StepPin {
    type Error = PinFault;
}
impl ErrorType for DirPin {
    type Error = PinFault;
}
impl ErrorType for EnablePin {
    type Error = PinFault;
}

impl StepPin {
    fn check(&self) -> Result<(), PinFault> {
        if self.0.state.borrow().step_failed {
            Err(PinFault)
        } else {
            Ok(())
        }
    }
}

impl OutputPin for StepPin {
    fn set_low(&mut self) -> Result<(), PinFault> {
        self.check()?;
        self.0.state.borrow_mut().step_high = false;
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), PinFault> {
        self.check()?;
        let enabled = self.0.enabled();
        let mut s = self.0.state.borrow_mut();
        if !s.step_high {
            if enabled {
                s.steps += if s.dir_high { 1 } else { -1 };
            } else {
                s.ignored_edges += 1;
            }
        }
        s.step_high = true;
        Ok(())
    }
}

impl OutputPin for DirPin {
    fn set_low(&mut self) -> Result<(), PinFault> {
        self.0.state.borrow_mut().dir_high = false;
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), PinFault> {
        self.0.state.borrow_mut().dir_high = true;
        Ok(())
    }
}

impl OutputPin for EnablePin {
    fn set_low(&mut self) -> Result<(), PinFault> {
        self.0.state.borrow_mut().enable_high = false;
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), PinFault> {
        self.0.state.borrow_mut().enable_high = true;
        Ok(())
    }
}

/// The simulated microsecond clock, advanced by the simulator.
#[derive(Debug, Clone, Default)]
pub struct SimClock(pub Rc<Cell<u64>>);

impl SimClock {
    /// Set the time (never backwards).
    pub fn set_us(&self, t: u64) {
        if t > self.0.get() {
            self.0.set(t);
        }
    }

    /// The time.
    pub fn get_us(&self) -> u64 {
        self.0.get()
    }
}

/// Delays take no simulated time (the firmware's µs-scale pulse delays are far below the
/// simulator's time step).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDelay;

impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// Called just before the firmware reads an emulated sensor, so that what it reads is the
/// plant at that instant, including steps it pulsed earlier in the same poll. Without it a
/// sample taken right after a step in the same 100 µs substep paired the new step count with
/// the sensor value from before the step (one microstep of driver angle of error on a share
/// of the samples). Empty until the simulator sets it; cheap to clone.
#[derive(Clone, Default)]
pub struct ReadHook(Rc<RefCell<Option<Refresh>>>);

/// What a [`ReadHook`] runs.
pub type Refresh = Rc<dyn Fn()>;

impl std::fmt::Debug for ReadHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.borrow().is_some() {
            "ReadHook(set)"
        } else {
            "ReadHook(empty)"
        })
    }
}

impl ReadHook {
    /// Install the refresh to run before each read.
    pub fn set(&self, refresh: Refresh) {
        *self.0.borrow_mut() = Some(refresh);
    }

    /// Run the refresh, if any (no borrow is held while it runs).
    pub fn fire(&self) {
        let refresh = self.0.borrow().clone();
        if let Some(f) = refresh {
            f();
        }
    }
}

/// A quadrature counter the simulator sets from the plant; reading it fires the hook.
#[derive(Debug, Clone, Default)]
pub struct SimQuadrature(pub Rc<Cell<i32>>, pub ReadHook);

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: steps count on rising edges only, signed by DIR, and only while enabled.
    #[test]
    fn steps_counted_on_enabled_rising_edges() {
        let chip = DriverChip::new(true);
        let (mut step, mut dir, mut en) = (chip.step_pin(), chip.dir_pin(), chip.enable_pin());
        step.set_high().unwrap();
        step.set_low().unwrap();
        assert_eq!(chip.pins().steps, 0);
        assert_eq!(chip.pins().ignored_edges, 1);
        en.set_low().unwrap();
        assert!(chip.enabled());
        dir.set_high().unwrap();
        for _ in 0..3 {
            step.set_high().unwrap();
            step.set_high().unwrap();
            step.set_low().unwrap();
        }
        dir.set_low().unwrap();
        step.set_high().unwrap();
        assert_eq!(chip.pins().steps, 2);
    }
}
