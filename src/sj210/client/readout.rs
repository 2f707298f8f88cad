//! The profile read-out: the total, then blocks of at most [`super::MAX_BLOCK`] heights, in
//! one uninterrupted pass; a failed pass is restarted once from the total.
//!
//! Layer 2: part of [`super::Sj210Client`]; the blocks are read by
//! [`crate::sj210::replies::parse_block`].

use super::{Sj210Client, MAX_BLOCK};
use crate::sj210::error::{LinkError, Sj210Error};
use crate::sj210::replies::{leading_number, parse_block};
use tokio::io::{AsyncRead, AsyncWrite};

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Reads the profile once: total, then blocks; nothing else in between, no block retried.
    async fn read_profile_once(&mut self) -> Result<Vec<f64>, Sj210Error> {
        let (Some(total_c), Some(block_c)) = (
            self.table.commands.profile_total.clone(),
            self.table.commands.profile_block.clone(),
        ) else {
            return Err(Sj210Error::ProfileUnsupported {
                ng_code: None,
                advice: format!(
                    "the {} command table has no profile read-out command",
                    self.table.model
                ),
            });
        };
        let cmd = total_c.plain();
        let payload = self.command(&cmd, false).await?;
        let total = leading_number(&payload).ok_or(Sj210Error::UnexpectedReply {
            command: cmd,
            payload,
            expected: "a point count",
        })?;
        let mut heights = Vec::with_capacity(total as usize);
        while (heights.len() as u32) < total {
            let n = (total - heights.len() as u32).min(MAX_BLOCK);
            let cmd = block_c.render(0, 0, n);
            let payload = self.command(&cmd, false).await?;
            let values = parse_block(&payload).map_err(|what| Sj210Error::ProfileBlock {
                command: cmd.clone(),
                payload: payload.clone(),
                what,
            })?;
            if values.is_empty() {
                break;
            }
            if values.len() as u32 > n {
                return Err(Sj210Error::ProfileBlock {
                    command: cmd,
                    payload,
                    what: format!("{} values for a request of {n}", values.len()),
                });
            }
            heights.extend(values);
        }
        if heights.len() as u32 != total {
            return Err(Sj210Error::ProfileCountMismatch {
                announced: total,
                received: heights.len() as u32,
            });
        }
        Ok(heights)
    }

    /// Reads the profile; any failure restarts the whole read-out once from the total.
    pub async fn read_profile(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<f64>, Sj210Error> {
        match self.read_profile_once().await {
            Ok(h) => Ok(h),
            Err(e @ Sj210Error::ProfileUnsupported { .. }) => Err(e),
            Err(
                e @ Sj210Error::Link {
                    source: LinkError::Vanished { .. },
                    ..
                },
            ) => Err(e),
            Err(first) => {
                tracing::warn!("profile read-out failed ({first}); restarting it from the total");
                warnings.push(format!("profile read-out restarted after: {first}"));
                self.read_profile_once()
                    .await
                    .map_err(|second| Sj210Error::ProfileReadoutFailed {
                        first: first.to_string(),
                        second: Box::new(second),
                    })
            }
        }
    }
}
