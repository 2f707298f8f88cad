//! Profiles the simulated instrument serves, loaded from three pinned CSV formats, and the rule
//! that picks which profile a trace serves.
//!
//! Formats (decimal point `.`, comma-separated):
//! * profile CSV, header `x_mm,z_um`: one profile; the pitch is the mean x spacing;
//! * long CSV, header `profile,y_mm,x_mm,z_um`: several profiles, rows grouped by profile index;
//! * grid CSV without header: one profile per row, heights in µm; the x pitch is given separately.
//!
//! Selection: with a simulated stage attached (a shared [`YPosition`] in nanometres that the
//! stage emulator updates), a trace serves the line at the stage's y,
//! `round((y − y_first)/step)` modulo the count, so re-traces see the same bytes; without a stage,
//! profiles are served in order of traces. Depends only on std.

use std::path::Path;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::Arc;

/// The bundled default data: 31 windows of a real Mitutoyo R profile (see `data/README.md`).
pub const BUNDLED_31_WINDOWS: &str =
    include_str!("../data/mitutoyo_R.31windows.profile_y_mm_x_mm_z_um.csv");

/// The whole bundled Mitutoyo R profile (see `data/README.md`): 6664 points at 1.5 µm, as the
/// instrument exported it under λc 2.5 mm, N 4, λs 8 µm.
pub const BUNDLED_MITUTOYO_R: &str = include_str!("../data/mitutoyo_surftest_R.x_mm_z_um.csv");

/// Errors while loading profile data; each names the line and what to fix.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The file could not be read.
    #[error("cannot read profile file {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A field is not a finite number.
    #[error("line {line}: field {field:?} is not a finite number; profile data must be plain decimals with '.'")]
    Number {
        /// 1-based line number.
        line: usize,
        /// The offending field.
        field: String,
    },
    /// A row has the wrong number of fields for its format.
    #[error("line {line}: expected {expected} comma-separated fields, found {found}")]
    Fields {
        /// 1-based line number.
        line: usize,
        /// Fields the format needs.
        expected: usize,
        /// Fields present.
        found: usize,
    },
    /// A grid CSV was given without an x pitch.
    #[error("grid CSV (no header) needs the x pitch: pass --pitch-x-mm")]
    NoPitch,
    /// The x pitch is not positive, or a profile has under two points.
    #[error("profile {profile}: {points} points with pitch {pitch_x_mm} mm; need ≥ 2 points and a positive pitch")]
    Degenerate {
        /// Profile index.
        profile: usize,
        /// Number of points.
        points: usize,
        /// The pitch found or given, mm.
        pitch_x_mm: f64,
    },
    /// The long CSV's profile indices are not 0, 1, 2, … in order.
    #[error("line {line}: profile index {found} out of order (expected {expected}); rows must be grouped by profile, indices ascending from 0")]
    Order {
        /// 1-based line number.
        line: usize,
        /// The index expected.
        expected: usize,
        /// The index found.
        found: String,
    },
    /// No data rows.
    #[error("profile data is empty")]
    Empty,
}

/// One profile as served.
#[derive(Debug, Clone, PartialEq)]
pub struct ServedProfile {
    /// The line's y position, mm (0 when the format has none).
    pub y_mm: f64,
    /// Sampling pitch along x, mm.
    pub pitch_x_mm: f64,
    /// Heights, µm.
    pub z_um: Vec<f64>,
}

impl ServedProfile {
    /// Evaluation length: points × pitch, mm.
    pub fn length_mm(&self) -> f64 {
        self.z_um.len() as f64 * self.pitch_x_mm
    }
}

/// The stage's y position in integer nanometres, shared between a stage emulator (writer) and
/// the instrument (reader).
#[derive(Debug, Clone, Default)]
pub struct YPosition(Arc<AtomicI64>);

impl YPosition {
    /// A new handle at y = 0.
    pub fn new() -> Self {
        Self::default()
    }
    /// Current y, nm.
    pub fn get_nm(&self) -> i64 {
        self.0.load(Ordering::SeqCst)
    }
    /// Sets y, nm.
    pub fn set_nm(&self, y_nm: i64) {
        self.0.store(y_nm, Ordering::SeqCst)
    }
}

/// A set of profiles plus the y grid used to map a stage position to a line.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileSet {
    profiles: Vec<ServedProfile>,
    /// y of line 0, mm.
    pub y_first_mm: f64,
    /// y spacing of lines, mm.
    pub y_step_mm: f64,
}

/// y step used when the data has no y information (the rig's usual 0.01 mm).
pub const DEFAULT_Y_STEP_MM: f64 = 0.01;

fn num(field: &str, line: usize) -> Result<f64, DataError> {
    field
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| DataError::Number {
            line,
            field: field.to_string(),
        })
}

fn fields(row: &str, expected: usize, line: usize) -> Result<Vec<&str>, DataError> {
    let f: Vec<&str> = row.split(',').collect();
    if f.len() != expected {
        return Err(DataError::Fields {
            line,
            expected,
            found: f.len(),
        });
    }
    Ok(f)
}

fn check(p: &ServedProfile, profile: usize) -> Result<(), DataError> {
    if p.z_um.len() < 2 || !(p.pitch_x_mm > 0.0 && p.pitch_x_mm.is_finite()) {
        return Err(DataError::Degenerate {
            profile,
            points: p.z_um.len(),
            pitch_x_mm: p.pitch_x_mm,
        });
    }
    Ok(())
}

fn mean_pitch(x: &[f64]) -> f64 {
    match (x.first(), x.last()) {
        (Some(a), Some(b)) if x.len() > 1 => (b - a) / (x.len() - 1) as f64,
        _ => 0.0,
    }
}

impl ProfileSet {
    /// Builds a set from profiles; y grid from the profiles' y (first and mean spacing), or
    /// 0 / [`DEFAULT_Y_STEP_MM`] when all y are equal.
    pub fn new(profiles: Vec<ServedProfile>) -> Result<Self, DataError> {
        for (i, p) in profiles.iter().enumerate() {
            check(p, i)?;
        }
        let (first, last) = match (profiles.first(), profiles.last()) {
            (Some(f), Some(l)) => (f.y_mm, l.y_mm),
            _ => return Err(DataError::Empty),
        };
        let step = if profiles.len() > 1 && last != first {
            (last - first) / (profiles.len() - 1) as f64
        } else {
            DEFAULT_Y_STEP_MM
        };
        Ok(Self {
            profiles,
            y_first_mm: first,
            y_step_mm: step,
        })
    }

    /// Loads a file in one of the three formats; `pitch_x_mm` is required for grid CSV and
    /// ignored otherwise.
    pub fn load(path: &Path, pitch_x_mm: Option<f64>) -> Result<Self, DataError> {
        let text = std::fs::read_to_string(path).map_err(|source| DataError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, pitch_x_mm)
    }

    /// Parses text in one of the three formats (chosen by the first line).
    pub fn parse(text: &str, pitch_x_mm: Option<f64>) -> Result<Self, DataError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty());
        let Some((_, head)) = lines.next() else {
            return Err(DataError::Empty);
        };
        match head {
            "x_mm,z_um" => {
                let (mut x, mut z) = (Vec::new(), Vec::new());
                for (n, l) in lines {
                    let f = fields(l, 2, n)?;
                    x.push(num(f[0], n)?);
                    z.push(num(f[1], n)?);
                }
                Self::new(vec![ServedProfile {
                    y_mm: 0.0,
                    pitch_x_mm: mean_pitch(&x),
                    z_um: z,
                }])
            }
            "profile,y_mm,x_mm,z_um" => {
                let mut profiles: Vec<ServedProfile> = Vec::new();
                let mut x: Vec<f64> = Vec::new();
                for (n, l) in lines {
                    let f = fields(l, 4, n)?;
                    let idx: usize = f[0].trim().parse().map_err(|_| DataError::Number {
                        line: n,
                        field: f[0].to_string(),
                    })?;
                    let current = profiles.len().checked_sub(1);
                    if Some(idx) != current {
                        if idx != profiles.len() {
                            return Err(DataError::Order {
                                line: n,
                                expected: profiles.len(),
                                found: f[0].to_string(),
                            });
                        }
                        if let Some(p) = profiles.last_mut() {
                            p.pitch_x_mm = mean_pitch(&x);
                        }
                        x.clear();
                        profiles.push(ServedProfile {
                            y_mm: num(f[1], n)?,
                            pitch_x_mm: 0.0,
                            z_um: Vec::new(),
                        });
                    }
                    x.push(num(f[2], n)?);
                    let z = num(f[3], n)?;
                    if let Some(p) = profiles.last_mut() {
                        p.z_um.push(z);
                    }
                }
                if let Some(p) = profiles.last_mut() {
                    p.pitch_x_mm = mean_pitch(&x);
                }
                Self::new(profiles)
            }
            _ => {
                let pitch = pitch_x_mm.ok_or(DataError::NoPitch)?;
                let mut profiles = Vec::new();
                let first_line = text.lines().position(|l| !l.trim().is_empty()).unwrap_or(0) + 1;
                for (n, l) in std::iter::once((first_line, head)).chain(lines) {
                    let z = l
                        .split(',')
                        .map(|f| num(f, n))
                        .collect::<Result<Vec<f64>, _>>()?;
                    profiles.push(ServedProfile {
                        y_mm: profiles.len() as f64 * DEFAULT_Y_STEP_MM,
                        pitch_x_mm: pitch,
                        z_um: z,
                    });
                }
                Self::new(profiles)
            }
        }
    }

    /// The bundled 31-window Mitutoyo R data.
    pub fn bundled() -> Result<Self, DataError> {
        Self::parse(BUNDLED_31_WINDOWS, None)
    }

    /// The whole bundled Mitutoyo R profile, one line of 6664 points at 1.5 µm: what a trace
    /// under λc 2.5 mm, N 4 (λs 8 µm) delivers.
    pub fn bundled_mitutoyo_r() -> Result<Self, DataError> {
        Self::parse(BUNDLED_MITUTOYO_R, None)
    }

    /// The profiles.
    pub fn profiles(&self) -> &[ServedProfile] {
        &self.profiles
    }

    /// Index of the line a trace serves: from the stage position when one is attached,
    /// otherwise the trace number (0-based) modulo the count.
    pub fn select(&self, trace_number: u64, stage: Option<&YPosition>) -> usize {
        let count = self.profiles.len().max(1) as i64;
        let line = match stage {
            Some(y) => {
                let y_mm = y.get_nm() as f64 / 1e6;
                let step = if self.y_step_mm != 0.0 {
                    self.y_step_mm
                } else {
                    DEFAULT_Y_STEP_MM
                };
                ((y_mm - self.y_first_mm) / step).round() as i64
            }
            None => (trace_number % count as u64) as i64,
        };
        line.rem_euclid(count) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_csv_pitch_is_mean_spacing() {
        let s = ProfileSet::parse("x_mm,z_um\n0,1\n0.5,2\n1.0,-3\n", None).unwrap();
        assert_eq!(s.profiles().len(), 1);
        assert_eq!(s.profiles()[0].z_um, vec![1.0, 2.0, -3.0]);
        assert!((s.profiles()[0].pitch_x_mm - 0.5).abs() < 1e-12);
    }

    #[test]
    fn long_csv_groups_profiles_and_y_grid() {
        let t = "profile,y_mm,x_mm,z_um\n0,1.0,0,1\n0,1.0,0.1,2\n1,1.5,0,3\n1,1.5,0.1,4\n2,2.0,0,5\n2,2.0,0.1,6\n";
        let s = ProfileSet::parse(t, None).unwrap();
        assert_eq!(s.profiles().len(), 3);
        assert_eq!(s.profiles()[2].z_um, vec![5.0, 6.0]);
        assert_eq!(s.y_first_mm, 1.0);
        assert!((s.y_step_mm - 0.5).abs() < 1e-12);
        let y = YPosition::new();
        y.set_nm(2_000_000);
        assert_eq!(s.select(0, Some(&y)), 2);
        y.set_nm(1_240_000); // 0.48 steps → line 0
        assert_eq!(s.select(7, Some(&y)), 0);
        y.set_nm(2_500_000); // line 3 → modulo 3 → 0
        assert_eq!(s.select(0, Some(&y)), 0);
        y.set_nm(500_000); // line -1 → 2
        assert_eq!(s.select(0, Some(&y)), 2);
        assert_eq!(s.select(4, None), 1);
    }

    #[test]
    fn grid_csv_needs_pitch_and_reports_bad_numbers() {
        assert!(matches!(
            ProfileSet::parse("1,2,3\n4,5,6\n", None),
            Err(DataError::NoPitch)
        ));
        let s = ProfileSet::parse("1,2,3\n4,5,6\n", Some(0.002)).unwrap();
        assert_eq!(s.profiles()[1].z_um, vec![4.0, 5.0, 6.0]);
        match ProfileSet::parse("1,2,3\n4,x,6\n", Some(0.002)) {
            Err(DataError::Number { line: 2, field }) => assert_eq!(field, "x"),
            other => panic!("expected a number error on line 2, got {other:?}"),
        }
        assert!(matches!(
            ProfileSet::parse("profile,y_mm,x_mm,z_um\n1,0,0,1\n", None),
            Err(DataError::Order { line: 2, .. })
        ));
    }

    #[test]
    fn bundled_mitutoyo_r_is_one_line_of_6664_points_at_1_5_um() {
        let s = ProfileSet::bundled_mitutoyo_r().unwrap();
        assert_eq!(s.profiles().len(), 1);
        let p = &s.profiles()[0];
        // 4 sampling lengths of floor(2.5 mm / 1.5 µm) = 1666 points.
        assert_eq!(p.z_um.len(), 4 * 1666);
        assert!((p.pitch_x_mm - 0.0015).abs() < 1e-12);
    }

    #[test]
    fn bundled_data_has_31_windows_of_1067_points() {
        let s = ProfileSet::bundled().unwrap();
        assert_eq!(s.profiles().len(), 31);
        assert!(s.profiles().iter().all(|p| p.z_um.len() == 1067));
        assert!((s.y_step_mm - 0.01).abs() < 1e-9);
        assert!((s.profiles()[0].pitch_x_mm - 0.0015).abs() < 1e-9);
        // Window 1 starts 186 points into the source: its first height is source row 187.
        assert_eq!(s.profiles()[0].z_um[186], s.profiles()[1].z_um[0]);
    }
}
