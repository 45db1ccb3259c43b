//! Wire protocol between the `mpc-rig` host and the bench firmware.
//!
//! Owns the message types, the framing and the protocol version shared by both ends.
//! It does not own any I/O: callers hand it bytes and take bytes from it.
#![no_std]
