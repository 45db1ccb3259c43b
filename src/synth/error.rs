//! Errors of the synthesis module: a request that cannot be served ([`SynthError`]), a
//! mechanism file that cannot be read, validated or written ([`MechanismFileError`]) and a
//! report that cannot be drawn ([`ReportError`]).
//!
//! A search that ends without an accepted design (infeasible or cancelled) is not an error:
//! it is an [`Outcome`](super::Outcome) carrying the best design reached. This module does
//! not know the mechanism type.

use std::path::PathBuf;

/// A synthesis request that cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// Bad option values.
    #[error("bad synthesis request: {0}")]
    BadRequest(String),
    /// The optimizer produced non-finite numbers for every candidate of a band.
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// A `mechanism.json` that cannot be read, is malformed or invalid, or cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum MechanismFileError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Malformed JSON, or a value of the wrong type.
    #[error(
        "{path}:{line}:{column}: {}{message}",
        field.as_ref().map_or(String::new(), |f| format!("field `{f}`: "))
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column (1-based).
        column: usize,
        /// The field whose value is wrong (`curve_pairs[0].samples.p[3]`), when the JSON is
        /// well formed.
        field: Option<String>,
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
}

/// The synthesis report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Creating the report directory failed.
    #[error("{path}: {source}")]
    Io {
        /// The directory.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Drawing a plot failed.
    #[error("report plot: {0}")]
    Plot(#[from] crate::plot::PlotError),
}
