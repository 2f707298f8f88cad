//! IGES 5.3 writer (entity 128, millimetres) and a strict reader of the files it writes.
//!
//! * [`format`](mod@format): reals (shortest round-trip, `.` and `E`), Hollerith strings, record packing.
//! * [`writer`]: [`write_iges_seekable`] (a file) and [`write_iges`] (any writer) stream
//!   surfaces into S/G/D/P/T sections; [`plan_parts`] groups the exact patches of a surface too
//!   large for one file into several files, planned from token counts.
//! * [`split`]: exact patches along v by knot insertion, for surfaces too large for one entity.
//! * [`reader`]: [`read_iges`] checks the structure and rebuilds the surfaces.
//!
//! Layer 1 (pure logic): depends on [`crate::nurbs`]; writes to any `io::Write` and reads
//! from byte slices, never opens files.

pub mod format;
pub mod reader;
#[cfg(test)]
mod reference;
pub mod split;
pub mod writer;

pub use reader::{read_iges, IgesFile};
pub use split::{split_v, split_v_middle, split_v_middle_side, split_v_side, Side};
pub use writer::{
    parameter_lines_bound, plan_files, plan_layout, plan_parts, write_iges, write_iges_seekable,
    IgesOptions, IgesStats, PartPlan, MAX_SECTION_LINES,
};

use thiserror::Error;

/// Why a file could not be written or read.
#[derive(Debug, Error)]
pub enum IgesError {
    /// Writing failed.
    #[error("writing IGES failed: {0}")]
    Io(#[from] std::io::Error),
    /// Nothing to write.
    #[error("no surface to write; pass at least one")]
    NoSurfaces,
    /// A value is NaN or infinite (IGES has no syntax for it; readers misbehave silently).
    #[error("patch {patch}: {what} {index} is {value}, not finite; refusing to write it")]
    NonFinite {
        /// Patch index.
        patch: usize,
        /// Which kind of value.
        what: &'static str,
        /// Its index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A surface without interior v knots needs more P lines than allowed.
    #[error("a {count_u}×{count_v} surface needs {lines} P lines (limit {max_lines}) and has no interior v knot to split at; raise the limit")]
    EntityTooLarge {
        /// Lines needed.
        lines: usize,
        /// The limit.
        max_lines: usize,
        /// Poles along u.
        count_u: usize,
        /// Poles along v.
        count_v: usize,
    },
    /// A section would exceed the per-file limit (at most 9,999,999 lines, the 7-digit
    /// sequence field).
    #[error("section {section} would need {lines} lines, more than the {max_lines} allowed per file; group the patches into several files with plan_files")]
    SectionTooLong {
        /// Section letter.
        section: char,
        /// Lines needed.
        lines: usize,
        /// The per-file limit.
        max_lines: usize,
    },
    /// The file's structure is invalid (line length, section letters, sequence numbers,
    /// terminate counts, directory entries, pointers).
    #[error("line {line}: {message}")]
    Structure {
        /// 1-based line number in the file.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// An entity's parameters are invalid.
    #[error("entity at DE {de}: {message}")]
    Parameter {
        /// DE sequence number of the entity.
        de: usize,
        /// What is wrong.
        message: String,
    },
}
