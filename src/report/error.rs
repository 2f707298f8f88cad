//! Why a scan directory or grid cannot be characterised.
//!
//! Layer 4 (reporting): depends on [`crate::input`] and [`crate::metrology`].

use crate::input::InputError;
use crate::metrology::MetrologyError;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a scan directory or grid cannot be characterised.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The input cannot be read, or its lines cannot form one grid.
    #[error(transparent)]
    Input(#[from] InputError),
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
pub(crate) fn metrology(what: impl Into<String>) -> impl Fn(MetrologyError) -> ReportError {
    let what = what.into();
    move |source| ReportError::Metrology {
        what: what.clone(),
        source,
    }
}

/// Wraps an I/O error with the file it concerns.
pub(crate) fn io(path: &Path) -> impl Fn(std::io::Error) -> ReportError + '_ {
    |source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    }
}
