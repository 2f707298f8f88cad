//! The instrument's NG codes: one table, from which the [`NgCode`] enum, its numbers, its
//! meanings and their sources are all generated, so a code cannot be named in one place and
//! explained differently in another.
//!
//! The list is the SJ-220 device table as carried by the public program C2
//! (`sj220_exceptions.py`), the best available for the SJ-210 family; 020 comes from the
//! SJ-410 program C3. Codes the driver reacts to get a variant; the others are
//! [`NgCode::Other`] and still have their meaning here.
//!
//! Pure (layer 1): depends on [`super::sources`] only.

use super::sources::{C2, C3};
use std::fmt;

/// One row of the NG code table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NgEntry {
    /// The number the instrument sends after `NG`.
    pub code: u16,
    /// What it means.
    pub meaning: &'static str,
    /// Where it was read.
    pub source: &'static str,
}

macro_rules! ng_table {
    ($( $code:literal $(as $variant:ident)? => $meaning:literal, $source:ident; )*) => {
        /// An NG code from the instrument: the codes the driver reacts to are named, every
        /// other is [`NgCode::Other`] (its meaning is still in [`NG_TABLE`]).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum NgCode {
            $($(
                #[doc = concat!("Code ", stringify!($code), ": ", $meaning, ".")]
                $variant,
            )?)*
            /// Any other code.
            Other(u16),
        }

        /// Every known NG code with its meaning and source, in code order.
        pub const NG_TABLE: &[NgEntry] = &[
            $( NgEntry { code: $code, meaning: $meaning, source: $source }, )*
        ];

        impl NgCode {
            /// The code from its number.
            pub fn from_code(code: u16) -> NgCode {
                match code {
                    $($( $code => NgCode::$variant, )?)*
                    other => NgCode::Other(other),
                }
            }

            /// The number as the instrument sent it.
            pub fn code(self) -> u16 {
                match self {
                    $($( NgCode::$variant => $code, )?)*
                    NgCode::Other(c) => c,
                }
            }
        }
    };
}

ng_table! {
    3 => "origin position not reached in time", C2;
    4 => "retraction position not reached in time", C2;
    5 => "origin limit remains active", C2;
    6 => "retraction limit remains active", C2;
    7 as OverRange => "detector over-range", C2;
    11 as Busy => "command sent while busy", C2;
    12 as ControlTimeout => "control timeout", C2;
    13 as BufferOverflow => "communication buffer overflow", C2;
    14 => "flash erase error", C2;
    15 => "flash write error", C2;
    16 => "program error", C2;
    17 => "system error", C2;
    18 as InvalidStartPosition => "invalid measurement start position", C2;
    19 as InvalidSetting => "invalid setting value", C2;
    20 as EndOfTravel => "stylus at the end of travel: return and re-measure (seen on the SJ-410)", C3;
    22 as DetectorDisconnected => "detector disconnected", C2;
    30 as IllegalCommand => "illegal command (not supported by this firmware)", C2;
    31 as InvalidFormat => "invalid command format", C2;
    32 as InvalidValue => "invalid command value", C2;
    33 as Processing => "command still being processed", C2;
    71 => "SPC communication error", C2;
    101 as NoResults => "no calculation results", C2;
    102 => "result out of range", C2;
    103 => "measurement interrupted by result over-range", C2;
    110 => "calculation error: too few peaks/valleys", C2;
    111 => "calculation error: too few data points", C2;
    112 => "calculation error: invalid region", C2;
    113 => "calculation error: no profile element", C2;
    114 => "calculation error: BAC/ADC", C2;
    115 => "calculation error: Rk", C2;
    116 => "calculation error: R-Motif", C2;
    117 => "calculation error: W-Motif", C2;
    118 => "calculation error: other", C2;
    121 => "calculation error", C2;
    130 => "calculation error", C2;
    184 => "printer access timeout", C2;
}

impl NgCode {
    /// The table row of this code, when it is a known one.
    pub fn entry(self) -> Option<&'static NgEntry> {
        let c = self.code();
        NG_TABLE.iter().find(|e| e.code == c)
    }

    /// What the code means, or "unknown error code".
    pub fn meaning(self) -> &'static str {
        self.entry().map_or("unknown error code", |e| e.meaning)
    }

    /// True for codes that mean "not now" on a read: busy, still processing, no results yet.
    pub fn is_retryable_read(self) -> bool {
        matches!(self, NgCode::Busy | NgCode::Processing | NgCode::NoResults)
    }

    /// True for codes that mean "this firmware does not understand the command".
    pub fn is_unsupported(self) -> bool {
        matches!(
            self,
            NgCode::IllegalCommand | NgCode::InvalidFormat | NgCode::InvalidValue
        )
    }

    /// True for the per-parameter calculation errors (102–199): the parameter has no
    /// value for this trace, the others may.
    pub fn is_calculation_error(self) -> bool {
        (102..=199).contains(&self.code())
    }
}

impl fmt::Display for NgCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "NG{:03}", self.code())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_round_trips_and_has_a_meaning_and_source() {
        for e in NG_TABLE {
            let c = NgCode::from_code(e.code);
            assert_eq!(c.code(), e.code);
            assert_eq!(c.meaning(), e.meaning);
            assert!(!e.source.is_empty() && !e.meaning.is_empty());
        }
        let codes: Vec<u16> = NG_TABLE.iter().map(|e| e.code).collect();
        let mut sorted = codes.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(codes, sorted, "one row per code, in order");
    }

    #[test]
    fn named_codes_and_others() {
        assert_eq!(NgCode::from_code(101), NgCode::NoResults);
        assert_eq!(NgCode::from_code(101).meaning(), "no calculation results");
        assert_eq!(NgCode::from_code(7), NgCode::OverRange);
        assert_eq!(NgCode::from_code(110), NgCode::Other(110));
        assert!(NgCode::from_code(110).meaning().contains("peaks"));
        assert_eq!(NgCode::Other(999).meaning(), "unknown error code");
        assert_eq!(NgCode::Other(999).to_string(), "NG999");
        assert_eq!(NgCode::Busy.to_string(), "NG011");
        assert!(NgCode::from_code(33).is_retryable_read());
        assert!(NgCode::from_code(31).is_unsupported());
        assert!(!NgCode::from_code(33).is_unsupported());
        assert!(NgCode::from_code(110).is_calculation_error());
        assert!(!NgCode::NoResults.is_calculation_error());
    }
}
