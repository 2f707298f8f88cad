//! Why a scan directory or grid cannot be characterised.
//!
//! Layer 4 (reporting): depends on [`crate::scan::store_error`] and [`crate::metrology`].

use crate::metrology::MetrologyError;
use crate::scan::store_error::StoreError;
use std::path::PathBuf;
use thiserror::Error;

/// Why a scan directory or grid cannot be characterised.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The scan directory or one of its line files cannot be read or is malformed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// No complete line to characterise.
    #[error("{dir}: no complete line to characterise (incomplete: {incomplete:?}); a scan needs at least one line with both NNNN.csv and NNNN.json")]
    NoLines {
        /// The scan directory.
        dir: PathBuf,
        /// Lines with one file only.
        incomplete: Vec<u32>,
    },
    /// The lines cannot form one grid.
    #[error("{path}: {reason}")]
    Lines {
        /// The offending line file.
        path: PathBuf,
        /// What differs, with both values.
        reason: String,
    },
    /// A line or the grid cannot be characterised.
    #[error("{what}: {source}")]
    Metrology {
        /// What was being characterised (file or line).
        what: String,
        /// The cause.
        #[source]
        source: MetrologyError,
    },
    /// An output cannot be written.
    #[error("cannot write {path}: {source}; {}", crate::atomic::write_hint(.path, .source))]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The report cannot be encoded (a value serde_json rejects).
    #[error("cannot encode the report: {0}")]
    Encode(#[from] serde_json::Error),
}

/// Wraps a metrology error with what was being characterised.
pub(crate) fn metrology(what: impl Into<String>) -> impl FnOnce(MetrologyError) -> ReportError {
    let what = what.into();
    move |source| ReportError::Metrology { what, source }
}
