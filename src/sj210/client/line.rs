//! One complete line: conditions (and whether they changed), the pitch, the trace, the
//! results and the profile, its point count checked against the conditions
//! ([`crate::sj210::sampling::check_point_count`]) and its length against the evaluation
//! length, as a [`crate::devices::TracedLine`].
//!
//! Layer 2: part of [`super::Sj210Client`].

use super::Sj210Client;
use crate::devices::{Battery, TracedLine};
use crate::profile::Profile;
use crate::sj210::error::Sj210Error;
use crate::sj210::sampling::check_point_count;
use tokio::io::{AsyncRead, AsyncWrite};

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// One complete line: trace, results, profile with pitch and conditions.
    pub async fn trace_line(&mut self) -> Result<TracedLine, Sj210Error> {
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
        self.run_trace().await?;
        let results = self.read_results(&mut warnings).await?;
        let heights_um = self.read_profile(&mut warnings).await?.heights_um;
        if self.opts.check_point_count {
            check_point_count(&conditions, pitch_um, heights_um.len()).map_err(|mismatch| {
                Sj210Error::PointCount {
                    mismatch,
                    pitch_source: pitch_source.clone(),
                }
            })?;
        }
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
        })
    }
}
