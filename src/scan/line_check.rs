//! Whether a traced line fits its scan: the problems a line can have (a height that is not a
//! number, another point count, pitch or conditions than the scan's), named for people.
//!
//! Layer 3 (session), pure: depends on [`crate::profile`]'s conditions.

use crate::profile::Conditions;
use std::fmt;

/// Why a traced line does not fit the scan.
#[derive(Debug, Clone, PartialEq)]
pub enum LineProblem {
    /// A height is not a finite number (a re-trace may give a good line).
    NotFinite {
        /// 0-based index of the point.
        point: usize,
        /// Points of the line.
        points: usize,
        /// The value.
        value: f64,
    },
    /// Another point count than the scan's lines (a re-trace may give a good line).
    PointCount {
        /// Points of this line.
        points: usize,
        /// Points of the scan's lines.
        scan: usize,
    },
    /// Another x pitch than the scan's.
    Pitch {
        /// This line's pitch, mm.
        pitch_x_mm: f64,
        /// The scan's, mm.
        scan: f64,
    },
    /// The measurement conditions changed on the instrument (what changed, named).
    ConditionsChanged(String),
}

impl LineProblem {
    /// True when tracing the line again may give an acceptable one.
    pub fn retry_may_help(&self) -> bool {
        matches!(
            self,
            LineProblem::NotFinite { .. } | LineProblem::PointCount { .. }
        )
    }
}

impl fmt::Display for LineProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LineProblem::NotFinite {
                point,
                points,
                value,
            } => write!(
                f,
                "point {} of {points} is {value} (not a finite height)",
                point + 1
            ),
            LineProblem::PointCount { points, scan } => {
                write!(f, "{points} points, but the scan's lines have {scan}")
            }
            LineProblem::Pitch { pitch_x_mm, scan } => {
                write!(f, "x pitch {pitch_x_mm} mm differs from the scan's {scan} mm")
            }
            LineProblem::ConditionsChanged(d) => write!(
                f,
                "measurement conditions changed on the instrument: {d}; restore them and continue the scan with --resume (the lines so far are kept)"
            ),
        }
    }
}

/// Compares the conditions a line was traced under with the scan's; the first difference,
/// named, when they differ.
pub fn conditions_difference(scan: &Conditions, line: &Conditions) -> Option<String> {
    fn differs<T: PartialEq + fmt::Debug>(
        name: &str,
        at_start: &Option<T>,
        now: &Option<T>,
    ) -> Option<String> {
        let show = |v: &Option<T>| {
            v.as_ref()
                .map_or("unknown".to_owned(), |x| format!("{x:?}"))
        };
        (at_start != now).then(|| {
            format!(
                "{name} was {} at the start of the scan, now {}",
                show(at_start),
                show(now)
            )
        })
    }
    let (a, b) = (scan, line);
    differs("standard", &a.standard, &b.standard)
        .or_else(|| differs("profile", &a.profile_kind, &b.profile_kind))
        .or_else(|| differs("filter", &a.filter, &b.filter))
        .or_else(|| differs("lambda-c mm", &a.lambda_c_mm, &b.lambda_c_mm))
        .or_else(|| differs("lambda-s um", &a.lambda_s_um, &b.lambda_s_um))
        .or_else(|| differs("sampling lengths", &a.sampling_lengths, &b.sampling_lengths))
        .or_else(|| {
            differs(
                "evaluation length mm",
                &a.evaluation_length_mm,
                &b.evaluation_length_mm,
            )
        })
        .or_else(|| differs("speed mm/s", &a.speed_mm_s, &b.speed_mm_s))
}
