//! Device logic of the bench firmware: step generation, sensors, sampler, watchdog and
//! command dispatch, generic over embedded-hal traits and an injectable clock.
//!
//! It owns no board code: the RP2040 binary in `firmware/rp2040` and the host's simulated
//! bench both drive it.
#![no_std]
