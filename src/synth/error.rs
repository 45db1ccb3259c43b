//! Errors of the synthesis module.
//!
//! Owns [`SynthError`]; every variant names what went wrong and where (file, field, K/d_x),
//! and the infeasible/cancelled variants carry the best mechanism found so far.

use std::path::PathBuf;

use super::mechanism::Mechanism;

/// Everything that can go wrong in synthesis, in reading or writing a mechanism file.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Malformed JSON.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column (1-based).
        column: usize,
        /// What the parser said.
        message: String,
    },
    /// Well-formed JSON with a bad value.
    #[error("{path}: field `{field}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// JSON path of the field.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A request that cannot be served (bad option values).
    #[error("bad synthesis request: {0}")]
    BadRequest(String),
    /// No tried K/d_x gave an accepted mechanism.
    #[error("{message}")]
    Infeasible {
        /// Best E_valiTime reached, worst samples and what to try.
        message: String,
        /// The best combination found (not accepted), for inspection.
        best: Option<Box<Mechanism>>,
    },
    /// The optimizer produced non-finite numbers for every candidate of a band.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// Stopped by the user (Ctrl-C); carries the best so far, marked partial.
    #[error("synthesis cancelled{}", if .partial.is_some() { " (best design so far kept, marked partial)" } else { " before any design was found" })]
    Cancelled {
        /// Best so far.
        partial: Option<Box<Mechanism>>,
    },
    /// Writing a report plot failed.
    #[error("report plot: {0}")]
    Plot(#[from] crate::plot::PlotError),
}
