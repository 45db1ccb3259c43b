//! Motion specifications: what the follower must do over one period.
//!
//! Owns parsing (TOML keyframes, dense CSV), validation with file/line/field errors,
//! periodic C² interpolation (on SO(3) for rotations), sampling of poses with analytic first
//! and second time derivatives, and the *target law* (follower pose as a function of the
//! driver angle) that the bench compares against. It does not synthesize anything and knows
//! nothing of curve pairs.
