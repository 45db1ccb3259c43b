//! Measured versus target: turns a recording into follower poses, aligns it with the target
//! law, computes error metrics and timing ratios, and writes the report.
//!
//! It does not talk to devices; it reads recordings.
