//! One complete line: conditions (and whether they changed), the pitch, the trace, the
//! results and the profile (read while the drive returns where the model table says the
//! instrument answers then, else once it is back), its point count checked against the conditions
//! ([`crate::sj210::sampling::check_point_count`]) and its length against the evaluation
//! length, and its read-out checked for sanity ([`crate::sj210::sanity`]: a repeated block,
//! the instrument's Ra against ours, the heights' span against the detector's range). A
//! read-out in doubt is read again once; a doubt the re-read does not clear stays with the
//! line as a [`ReadoutWarning`], as does an Ra in a unit not known here.
//!
//! Layer 2: part of [`super::Sj210Client`].

use super::readout::ReadoutPass;
use super::trace::{TraceEnd, TraceUntil};
use super::Sj210Client;
use crate::devices::{Battery, ReadoutWarning, TracedLine};
use crate::profile::{Conditions, InstrumentResult, Profile};
use crate::sj210::error::Sj210Error;
use crate::sj210::ng::NgCode;
use crate::sj210::sampling::check_point_count;
use crate::sj210::sanity::{check_ra, ra_unit_unknown, span_beyond_range};
use tokio::io::{AsyncRead, AsyncWrite};

/// What a line needs before its trace: the conditions it is traced under, the pitch and
/// where it comes from, and the warnings so far.
pub(super) struct LinePrep {
    conditions: Conditions,
    pitch_um: f64,
    pitch_source: String,
    warnings: Vec<String>,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// One complete line: trace, results, profile with pitch and conditions. Where the model
    /// table says the instrument answers reads while its drive returns, they are made then,
    /// and the next wait for idle waits for the return.
    pub async fn trace_line(&mut self) -> Result<TracedLine, Sj210Error> {
        let mut prep = self.prepare_line().await?;
        let until = if self.table.reads_during_return {
            TraceUntil::Measured
        } else {
            TraceUntil::Back
        };
        let end = self.run_trace_until(until).await?;
        let (results, pass) = if end == TraceEnd::Returning {
            self.read_during_return(&mut prep.warnings).await?
        } else {
            self.read_line_data(&mut prep.warnings).await?
        };
        self.finish_line(prep, results, pass).await
    }

    /// The line of the trace the instrument holds, traced some other way (as the probe does):
    /// conditions, results and profile, checked as [`Sj210Client::trace_line`] checks them.
    pub async fn read_held_line(&mut self) -> Result<TracedLine, Sj210Error> {
        let mut prep = self.prepare_line().await?;
        let (results, pass) = self.read_line_data(&mut prep.warnings).await?;
        self.finish_line(prep, results, pass).await
    }

    /// Battery, conditions (and whether they changed since the last read), pitch.
    pub(super) async fn prepare_line(&mut self) -> Result<LinePrep, Sj210Error> {
        if self.battery == Some(Battery::Abnormal) {
            return Err(Sj210Error::BatteryAbnormal);
        }
        // Read the conditions for every line: they are recorded with its profile, and an
        // operator may have changed them on the instrument since the probe.
        let before = self.conditions.clone();
        let conditions = self.conditions().await?;
        let mut warnings = Vec::new();
        if let Some(b) = before.filter(|b| b.raw != conditions.raw) {
            let w = format!(
                "measurement conditions changed on the instrument: {:?} -> {:?}",
                b.raw.unwrap_or_default(),
                conditions.raw.clone().unwrap_or_default()
            );
            tracing::warn!("{w}");
            warnings.push(w);
        }
        let (pitch_um, pitch_source) = self.pitch_um(&conditions)?;
        Ok(LinePrep {
            conditions,
            pitch_um,
            pitch_source,
            warnings,
        })
    }

    /// The results and the profile of the trace the instrument holds, with busy reads retried
    /// and a failed read-out restarted once.
    pub(super) async fn read_line_data(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<(Vec<InstrumentResult>, ReadoutPass), Sj210Error> {
        let results = self.read_results(warnings).await?;
        let pass = self.read_profile(warnings).await?;
        Ok((results, pass))
    }

    /// The results and the profile while the drive returns. A busy answer means this
    /// firmware reads only when the drive is back: from then on this link reads after the
    /// return (said once, in the log and the line's warnings), and this line waits for it and
    /// reads again from the start. "No results yet" (`NG101`) only makes this line wait.
    /// Nothing read during the return is kept then.
    async fn read_during_return(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<(Vec<InstrumentResult>, ReadoutPass), Sj210Error> {
        let mut during = Vec::new();
        let not_now = match self.read_results_with(&mut during, false).await {
            Err(e) if is_not_now(&e) => e,
            Err(e) => return Err(e),
            Ok(results) => match self.read_profile_once().await {
                Err(e) if is_not_now(&e) => e,
                first => {
                    let pass = self.read_profile_after(first, &mut during).await?;
                    warnings.append(&mut during);
                    return Ok((results, pass));
                }
            },
        };
        if not_now.code() == Some(NgCode::NoResults) {
            tracing::info!(
                "no results yet while the drive returns ({not_now}); reading once it is back"
            );
        } else {
            self.table.reads_during_return = false;
            let w = format!(
                "the instrument refused a read while its drive returned ({not_now}): it reads only when the drive is back, so this link reads after the return from now on; remove reads-during-return from [instrument.commands]"
            );
            tracing::warn!("{w}");
            warnings.push(w);
        }
        self.wait_idle().await?;
        self.read_line_data(warnings).await
    }

    /// Checks the profile read against the conditions and the instrument's results (reading
    /// it once more when in doubt) and makes the line.
    pub(super) async fn finish_line(
        &mut self,
        prep: LinePrep,
        results: Vec<InstrumentResult>,
        mut pass: ReadoutPass,
    ) -> Result<TracedLine, Sj210Error> {
        let LinePrep {
            conditions,
            pitch_um,
            pitch_source,
            mut warnings,
        } = prep;
        let check = LineCheck {
            conditions: &conditions,
            pitch_um,
            pitch_source: &pitch_source,
            check_count: self.opts.check_point_count,
            detector_range_um: self.opts.detector_range_um,
            results: &results,
        };
        let mut doubts = check.doubts(&pass)?;
        if !doubts.is_empty() {
            let list: Vec<String> = doubts.iter().map(ToString::to_string).collect();
            tracing::warn!(
                "profile read-out in doubt ({}); reading it again",
                list.join("; ")
            );
            warnings.push(format!("profile read out again after: {}", list.join("; ")));
            match self.read_profile_once().await {
                Ok(again) => {
                    doubts = check.doubts(&again)?;
                    pass = again;
                    if doubts.is_empty() {
                        warnings.push("the second read-out was clean and is kept".into());
                    }
                }
                Err(e) => {
                    tracing::warn!("the second read-out failed ({e}); keeping the first");
                    warnings.push(format!(
                        "the second read-out failed ({e}); the first is kept"
                    ));
                }
            }
        }
        let heights_um = pass.heights_um;
        if let Some(l) = conditions.evaluation_length_mm {
            let covered = heights_um.len() as f64 * pitch_um / 1000.0;
            if l > 0.0 && ((covered - l) / l).abs() > 0.01 {
                let w = format!(
                    "{} points x {pitch_um} um = {covered:.4} mm differs from the evaluation length {l:.4} mm by more than 1 % (pitch from {pitch_source})",
                    heights_um.len()
                );
                tracing::warn!("{w}");
                warnings.push(w);
            }
        }
        // Not a doubt a re-read can clear, but said with the line all the same.
        if let Some(unit) = ra_unit_unknown(&results) {
            doubts.push(ReadoutWarning::RaUnitUnknown { unit });
        }
        for d in &doubts {
            tracing::warn!("line kept with a read-out warning: {d}");
        }
        let kind = conditions.profile_kind.unwrap_or_default();
        Ok(TracedLine {
            profile: Profile {
                pitch_x_mm: pitch_um / 1000.0,
                heights_um,
                kind,
                conditions,
            },
            results,
            pitch_source,
            warnings,
            readout_warnings: doubts,
        })
    }
}

/// A read refused for now: busy (`NG011`), still processing (`NG033`) or no results yet
/// (`NG101`), the answers a read retried when the drive is back can outgrow.
pub(super) fn is_not_now(e: &Sj210Error) -> bool {
    e.code().is_some_and(NgCode::is_retryable_read)
}

/// What a read-out pass is checked against.
struct LineCheck<'a> {
    conditions: &'a Conditions,
    pitch_um: f64,
    pitch_source: &'a str,
    check_count: bool,
    detector_range_um: f64,
    results: &'a [InstrumentResult],
}

impl LineCheck<'_> {
    /// A wrong point count is an error (the pitch or the conditions are not this profile's);
    /// a repeated block and an Ra disagreement are doubts.
    fn doubts(&self, pass: &ReadoutPass) -> Result<Vec<ReadoutWarning>, Sj210Error> {
        if self.check_count {
            check_point_count(self.conditions, self.pitch_um, pass.heights_um.len()).map_err(
                |mismatch| Sj210Error::PointCount {
                    mismatch,
                    pitch_source: self.pitch_source.to_string(),
                },
            )?;
        }
        let mut out = Vec::new();
        if !pass.repeated_blocks.is_empty() {
            out.push(ReadoutWarning::RepeatedBlock {
                blocks: pass.repeated_blocks.clone(),
            });
        }
        if let Some(span_um) = span_beyond_range(&pass.heights_um, self.detector_range_um) {
            out.push(ReadoutWarning::BeyondDetectorRange {
                span_um,
                range_um: self.detector_range_um,
            });
        }
        let profile = Profile {
            pitch_x_mm: self.pitch_um / 1000.0,
            heights_um: pass.heights_um.clone(),
            kind: self.conditions.profile_kind.unwrap_or_default(),
            conditions: self.conditions.clone(),
        };
        if let Some(ra) = check_ra(&profile, self.results).filter(|r| !r.agrees()) {
            out.push(ReadoutWarning::RaDisagrees {
                instrument_um: ra.instrument_um,
                ours_um: ra.ours_um,
                tolerance_um: ra.tolerance_um,
            });
        }
        Ok(out)
    }
}
