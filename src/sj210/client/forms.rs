//! The read-out probe on the instrument: reads the conditions and the results of the trace
//! it holds, then tries each read-out form until one reads the profile, and checks what it
//! read; and, during a trace's return, whether reads are answered then. Read-only: nothing
//! moves the stylus. The judging is in [`crate::sj210::readout_probe`] and
//! [`crate::sj210::return_reads`].
//!
//! Layer 2: part of [`super::Sj210Client`].

use super::{status, Sj210Client};
use crate::profile::Profile;
use crate::sj210::error::Sj210Error;
use crate::sj210::models::CommandSpec;
use crate::sj210::ng::NgCode;
use crate::sj210::readout_probe::{FormResult, FormVerdict, ReadCheck, ReadoutForm, ReadoutProbe};
use crate::sj210::replies::leading_number;
use crate::sj210::return_reads::{ReadAnswer, ReturnProbe};
use crate::sj210::sampling::expected_points;
use crate::sj210::sanity::check_ra;
use tokio::io::{AsyncRead, AsyncWrite};

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Tries `forms` in order on the trace the instrument holds (status must be `000` or
    /// `005`) and stops after the first that reads the profile. Fails only when the status,
    /// the conditions or the link fail; a refused form is a verdict, not an error.
    pub async fn probe_readout_forms(
        &mut self,
        forms: &[ReadoutForm],
    ) -> Result<ReadoutProbe, Sj210Error> {
        let s = self.status().await?;
        if s != status::IDLE && s != status::INTERMEDIATE {
            return Err(Sj210Error::NotIdle {
                status: s,
                meaning: self.table.status_meaning(s),
            });
        }
        let conditions = self.conditions().await?;
        let pitch = self.pitch_um(&conditions).ok();
        let mut notes = Vec::new();
        // NG101 here means no trace is held; the forms will say so too.
        let results = match self.read_results(&mut notes).await {
            Ok(r) => r,
            Err(e) if e.code() == Some(NgCode::NoResults) => Vec::new(),
            Err(e) => return Err(e),
        };
        let mut out = Vec::new();
        for form in forms {
            let verdict = self
                .try_form(form, &conditions, pitch.as_ref(), &results)
                .await?;
            let read = matches!(verdict, FormVerdict::Read(_));
            tracing::info!(total = %form.total, "read-out form: {}", verdict.describe());
            out.push(FormResult {
                form: form.clone(),
                verdict,
            });
            if read {
                break;
            }
        }
        Ok(ReadoutProbe {
            results: out,
            pitch,
        })
    }

    async fn try_form(
        &mut self,
        form: &ReadoutForm,
        conditions: &crate::profile::Conditions,
        pitch: Option<&(f64, String)>,
        results: &[crate::profile::InstrumentResult],
    ) -> Result<FormVerdict, Sj210Error> {
        let (_, block_c) = form.specs();
        // The total first, alone: its answer says whether the form is known at all.
        let total = match self.command(&form.total, false).await {
            Ok(payload) => match leading_number(&payload) {
                Some(t) => t,
                None => return Ok(FormVerdict::NotACount(payload)),
            },
            Err(e) => return refusal(e),
        };
        let pass = match self.read_blocks(&block_c, total).await {
            Ok(p) => p,
            Err(e) => {
                return Ok(FormVerdict::ReadFailed {
                    total: Some(total),
                    error: e.to_string(),
                })
            }
        };
        let points = pass.heights_um.len() as u32;
        let (expected, ra) = match pitch {
            Some((p, _)) => {
                let profile = Profile {
                    pitch_x_mm: p / 1000.0,
                    heights_um: pass.heights_um,
                    kind: conditions.profile_kind.unwrap_or_default(),
                    conditions: conditions.clone(),
                };
                (expected_points(conditions, *p), check_ra(&profile, results))
            }
            None => (None, None),
        };
        Ok(FormVerdict::Read(ReadCheck {
            total: points,
            expected,
            ra,
            repeated_blocks: pass.repeated_blocks,
        }))
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Asks, while the drive returns from the trace just measured (right after
    /// [`Sj210Client::run_trace_until`] ended [`super::TraceEnd::Returning`]), one result, a
    /// read-out total and one block, then the status. The read-out form is the table's when it
    /// has one, else the first of `forms` the firmware understands. Nothing is retried: a busy
    /// answer is the finding. Read-only.
    pub async fn probe_reads_during_return(
        &mut self,
        forms: &[ReadoutForm],
    ) -> Result<ReturnProbe, Sj210Error> {
        let mut reads = Vec::new();
        let result = self.table.commands.result.render(1, 0, 0);
        let (answer, _) = self.ask_during_return(&result).await?;
        reads.push((result, answer));
        let candidates: Vec<(CommandSpec, CommandSpec)> = match (
            &self.table.commands.profile_total,
            &self.table.commands.profile_block,
        ) {
            (Some(t), Some(b)) => vec![(t.clone(), b.clone())],
            _ => forms.iter().map(ReadoutForm::specs).collect(),
        };
        for (total_c, block_c) in candidates {
            let total = total_c.plain();
            let (answer, payload) = self.ask_during_return(&total).await?;
            reads.push((total, answer.clone()));
            match answer {
                ReadAnswer::NotUnderstood(_) => continue,
                ReadAnswer::Answered => {
                    let n = leading_number(&payload)
                        .unwrap_or(1)
                        .clamp(1, super::MAX_BLOCK);
                    let block = block_c.render(0, 0, n);
                    let (answer, _) = self.ask_during_return(&block).await?;
                    reads.push((block, answer));
                }
                ReadAnswer::NotNow(_) | ReadAnswer::Failed(_) => {}
            }
            break;
        }
        let s = self.status().await?;
        Ok(ReturnProbe::Asked {
            reads,
            still_returning: s == status::RETURNING,
        })
    }

    /// One read during the return, not retried: its answer and payload; a vanished device is
    /// an error.
    async fn ask_during_return(&mut self, cmd: &str) -> Result<(ReadAnswer, String), Sj210Error> {
        use crate::devices::{DeviceFault, FaultClass};
        match self.command(cmd, false).await {
            Ok(payload) => Ok((ReadAnswer::Answered, payload)),
            Err(e) if e.class() == FaultClass::Absent => Err(e),
            Err(e) => Ok((
                e.code()
                    .map_or_else(|| ReadAnswer::Failed(e.to_string()), ReadAnswer::of_code),
                String::new(),
            )),
        }
    }
}

/// The verdict of a refused total command; a vanished device is an error, not a verdict.
fn refusal(e: Sj210Error) -> Result<FormVerdict, Sj210Error> {
    use crate::devices::{DeviceFault, FaultClass};
    if e.class() == FaultClass::Absent {
        return Err(e);
    }
    Ok(match e.code() {
        Some(NgCode::IllegalCommand) => FormVerdict::NoSuchCommand,
        Some(c @ (NgCode::InvalidFormat | NgCode::InvalidValue)) => FormVerdict::WrongForm(c),
        Some(NgCode::NoResults) => FormVerdict::NoProfileHeld,
        Some(c) => FormVerdict::Refused(c),
        None => FormVerdict::NoAnswer(e.to_string()),
    })
}
