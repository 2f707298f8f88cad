//! One traced line: heights along x with the metadata that makes it traceable.
//!
//! A [`Profile`] is what the instrument driver produces, what the scan stores per line,
//! what the fitter consumes and what the metrology characterises; its [`ProfileHeader`]
//! (the same struct without the heights) is the profile part of a stored line's metadata. Heights are µm exactly as
//! received; x is implied by the pitch (x_i = i × pitch_x_mm, first point at x = 0).
//!
//! Layer 0 (vocabulary): depends only on [`crate::units`]; no I/O.

use serde::{Deserialize, Serialize};

/// The kind of profile the instrument exported (ISO 4287 / JIS naming on the SJ series).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum ProfileKind {
    /// Primary profile (only λs applied): needs the λc filter before R parameters.
    #[default]
    P,
    /// Roughness profile (already λc-filtered).
    R,
    /// Waviness profile.
    W,
    /// DIN 4776 / motif or other profile types reported by the instrument.
    Other,
}

/// The profile filter the instrument applied or was set to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum FilterKind {
    /// ISO 16610-21 Gaussian.
    #[default]
    Gaussian,
    /// 2RC (2CR75) analogue filter.
    TwoRc,
    /// Phase-corrected 2RC (PC75).
    Pc75,
    /// No filter.
    None,
}

/// Measurement and evaluation conditions of a trace, as read from the instrument (`RDCON`)
/// or given in a data file. Every field is optional: unknown is stated, never guessed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Conditions {
    /// Standard the instrument evaluates to, e.g. "ISO1997", "JIS2001".
    pub standard: Option<String>,
    /// Profile kind the parameters are computed on.
    pub profile_kind: Option<ProfileKind>,
    /// Filter type.
    pub filter: Option<FilterKind>,
    /// Cut-off λc in mm (0.08 / 0.25 / 0.8 / 2.5 / 8).
    pub lambda_c_mm: Option<f64>,
    /// Short-wave cut-off λs in µm (2.5 / 8 / 25), `None` when absent or unknown.
    pub lambda_s_um: Option<f64>,
    /// Number of sampling lengths N.
    pub sampling_lengths: Option<u32>,
    /// Evaluation length in mm (N × λc, or the arbitrary length).
    pub evaluation_length_mm: Option<f64>,
    /// Traverse speed in mm/s, when known.
    pub speed_mm_s: Option<f64>,
    /// The raw condition record as received, for the record.
    pub raw: Option<String>,
}

/// One result parameter as the instrument computed and printed it (`RDRES…02`: name, value,
/// unit). A traced line carries one per parameter the instrument reports — `RDPAR` says how
/// many are customised, each is read with one `RDRES` — in the instrument's order, whatever
/// the parameter (Ra, Rq, Rz, Rp, Rv, Rt, Rsk, Rku, Rz1max, RSm, Rc, RPc, Rδc, Rmr, …).
///
/// JSON field names (in a line's `NNNN.json`, under `results`): `name`, `value`, `unit`,
/// `printed`, `ng_code`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct InstrumentResult {
    /// Parameter name as the instrument printed it, trimmed: "Ra", "Rz1max", "Rmr". A
    /// parameter the instrument could not calculate (an NG code, see `ng_code`) is named by
    /// its number, "#05".
    pub name: String,
    /// The printed value as a number, in `unit`; `None` when it printed no number (`Err110`)
    /// or answered an NG code.
    pub value: Option<f64>,
    /// Unit as printed, trimmed: "um" (ASCII, as the SJ series sends it), "µm", "%", or ""
    /// for ratios (Rsk, Rku).
    pub unit: String,
    /// The value field exactly as printed, trimmed ("3.308", "-0.144", "Err110"): its
    /// decimals are the instrument's printed resolution. `None` when the parameter answered
    /// an NG code, or for results not read from an instrument.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub printed: Option<String>,
    /// The NG code the instrument answered for this parameter instead of a value (a
    /// calculation error, 102–199: too few peaks, no profile element, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ng_code: Option<u16>,
}

/// A traced line of heights at a constant x pitch, with its kind and conditions.
///
/// `H` is where the heights are. By default they are in memory (`Vec<f64>`): what the
/// instrument driver produces, the fitter consumes and the metrology characterises. A
/// [`ProfileHeader`] (`Profile<NoHeights>`) is the same description with the heights kept
/// elsewhere: a stored line's metadata file, whose heights are in the CSV beside it. Both are
/// this one struct, so a field added here is in both; in JSON a header has no `heights_um`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "H: Serialize + Heights",
    deserialize = "H: Deserialize<'de> + Default"
))]
pub struct Profile<H = Vec<f64>> {
    /// Distance between consecutive points along x, in mm.
    pub pitch_x_mm: f64,
    /// Heights in µm, exactly as received, first point at x = 0.
    #[serde(default, skip_serializing_if = "Heights::elsewhere")]
    pub heights_um: H,
    /// Profile kind (P, R, …).
    pub kind: ProfileKind,
    /// Conditions of the trace when known.
    pub conditions: Conditions,
}

/// Where a [`Profile`]'s heights are: in memory, or elsewhere ([`NoHeights`]).
pub trait Heights {
    /// True when the heights are not held here (they are left out of the JSON form).
    fn elsewhere(&self) -> bool;
}

impl Heights for Vec<f64> {
    fn elsewhere(&self) -> bool {
        false
    }
}

/// The heights of a [`ProfileHeader`]: kept elsewhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct NoHeights;

impl Heights for NoHeights {
    fn elsewhere(&self) -> bool {
        true
    }
}

/// A profile's pitch, kind and conditions without its heights.
pub type ProfileHeader = Profile<NoHeights>;

impl<H> Profile<H> {
    /// The profile's description without its heights.
    pub fn header(&self) -> ProfileHeader {
        Profile {
            pitch_x_mm: self.pitch_x_mm,
            heights_um: NoHeights,
            kind: self.kind,
            conditions: self.conditions.clone(),
        }
    }
}

impl ProfileHeader {
    /// The profile these heights make with this description.
    pub fn with_heights(self, heights_um: Vec<f64>) -> Profile {
        Profile {
            pitch_x_mm: self.pitch_x_mm,
            heights_um,
            kind: self.kind,
            conditions: self.conditions,
        }
    }
}

impl Profile {
    /// A profile without metadata (primary profile, unknown conditions).
    pub fn new(pitch_x_mm: f64, heights_um: Vec<f64>) -> Profile {
        Profile {
            pitch_x_mm,
            heights_um,
            kind: ProfileKind::P,
            conditions: Conditions::default(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.heights_um.len()
    }

    /// True when the profile holds no point.
    pub fn is_empty(&self) -> bool {
        self.heights_um.is_empty()
    }

    /// x of point `i` in mm.
    pub fn x_mm(&self, i: usize) -> f64 {
        i as f64 * self.pitch_x_mm
    }

    /// Length covered by the points, (n − 1) × pitch, in mm.
    pub fn length_mm(&self) -> f64 {
        self.heights_um.len().saturating_sub(1) as f64 * self.pitch_x_mm
    }
}
