//! The analysis error type.

use std::path::PathBuf;

/// Everything that can go wrong while analysing a recording or writing its report.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The measured arrays are inconsistent (lengths differ, non-finite values, time going
    /// backwards); `what` names the array and `index` the first offending sample.
    #[error("measured data: {what} (sample {index})")]
    BadSample {
        /// What is wrong, naming the column.
        what: String,
        /// Index of the first offending sample (0-based, after the header).
        index: usize,
    },
    /// There is not enough usable data for the requested figure.
    #[error("not enough data: {0}")]
    NotEnoughData(String),
    /// The recording does not measure what the target law needs (e.g. a 3R target with only
    /// an encoder), or the options ask for something this class has no meaning for.
    #[error("mismatch between recording and target: {0}")]
    Mismatch(String),
    /// An option given by the user is invalid.
    #[error("invalid option {option}: {message}")]
    BadOption {
        /// The option, as spelled on the command line.
        option: String,
        /// What is wrong with it.
        message: String,
    },
    /// The recording could not be loaded.
    #[error("cannot load recording {path}: {message}")]
    Recording {
        /// The recording directory.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// The target (mechanism or motion file) could not be loaded.
    #[error("cannot load target {path}: {message}")]
    Target {
        /// The mechanism or motion file.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The summary could not be serialized.
    #[error("cannot write summary {path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The serializer's error.
        #[source]
        source: serde_json::Error,
    },
}

impl AnalysisError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
