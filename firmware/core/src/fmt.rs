//! Logging macros in embassy's style: `trace!`, `debug!`, `info!`, `warn!` and `error!`
//! forward to [`defmt`](https://docs.rs/defmt) when this crate is built with its `defmt`
//! feature (the board, which ships the frames over RTT), and expand to nothing otherwise
//! (host tests and the simulated bench), so the device logic needs no logger to be tested.
//!
//! Messages use defmt's format syntax (`{=u32}`, `{=u8:#x}`, `{}` for `Format` types).
//! Without the feature the arguments are still evaluated by reference, so a variable used
//! only in a log message does not become "unused" and side effects do not differ.

macro_rules! log_at {
    ($level:ident, $fmt:literal $(, $arg:expr)* $(,)?) => {{
        #[cfg(feature = "defmt")]
        ::defmt::$level!($fmt $(, $arg)*);
        #[cfg(not(feature = "defmt"))]
        {
            let _ = ($(&$arg,)*);
        }
    }};
}

#[allow(unused_macros)]
macro_rules! trace {
    ($($t:tt)*) => { log_at!(trace, $($t)*) };
}
#[allow(unused_macros)]
macro_rules! debug {
    ($($t:tt)*) => { log_at!(debug, $($t)*) };
}
#[allow(unused_macros)]
macro_rules! info {
    ($($t:tt)*) => { log_at!(info, $($t)*) };
}
#[allow(unused_macros)]
macro_rules! warn {
    ($($t:tt)*) => { log_at!(warn, $($t)*) };
}
#[allow(unused_macros)]
macro_rules! error {
    ($($t:tt)*) => { log_at!(error, $($t)*) };
}
