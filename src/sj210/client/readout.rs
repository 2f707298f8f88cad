//! The profile read-out: the total, then blocks of at most [`super::MAX_BLOCK`] heights, in
//! one uninterrupted pass; a failed pass is restarted once from the total. Each pass notes
//! the blocks that repeated the one before ([`crate::sj210::sanity::is_repeated_block`]).
//!
//! Layer 2: part of [`super::Sj210Client`]; the blocks are read by
//! [`crate::sj210::replies::parse_block`].

use super::{Sj210Client, MAX_BLOCK};
use crate::sj210::error::{LinkError, Sj210Error};
use crate::sj210::models::CommandSpec;
use crate::sj210::replies::{leading_number, parse_block};
use crate::sj210::sanity::{is_repeated_block, RepeatedBlock};
use tokio::io::{AsyncRead, AsyncWrite};

/// The heights of one read-out pass and what was odd about it.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadoutPass {
    /// Heights in µm, as received.
    pub heights_um: Vec<f64>,
    /// Blocks that repeated the block before them.
    pub repeated_blocks: Vec<RepeatedBlock>,
}

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// One pass with the given commands: total, then blocks; nothing else in between, no
    /// block retried.
    pub async fn read_pass(
        &mut self,
        total_c: &CommandSpec,
        block_c: &CommandSpec,
    ) -> Result<ReadoutPass, Sj210Error> {
        let cmd = total_c.plain();
        let payload = self.command(&cmd, false).await?;
        let total = leading_number(&payload).ok_or(Sj210Error::UnexpectedReply {
            command: cmd,
            payload,
            expected: "a point count",
        })?;
        self.read_blocks(block_c, total).await
    }

    /// The blocks of a read-out whose total was just announced.
    pub(super) async fn read_blocks(
        &mut self,
        block_c: &CommandSpec,
        total: u32,
    ) -> Result<ReadoutPass, Sj210Error> {
        let mut heights = Vec::with_capacity(total as usize);
        let mut repeated_blocks = Vec::new();
        let mut previous: Vec<f64> = Vec::new();
        let mut block = 0u32;
        while (heights.len() as u32) < total {
            let n = (total - heights.len() as u32).min(MAX_BLOCK);
            let cmd = block_c.render(0, 0, n);
            let payload = self.command(&cmd, false).await?;
            block += 1;
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
            if is_repeated_block(&previous, &values) {
                tracing::warn!(block, "profile block {block} repeats the block before it");
                repeated_blocks.push(RepeatedBlock {
                    block,
                    first_point: heights.len() as u32,
                    values: values.len() as u32,
                });
            }
            heights.extend_from_slice(&values);
            previous = values;
        }
        if heights.len() as u32 != total {
            return Err(Sj210Error::ProfileCountMismatch {
                announced: total,
                received: heights.len() as u32,
            });
        }
        Ok(ReadoutPass {
            heights_um: heights,
            repeated_blocks,
        })
    }

    /// One pass with the model table's read-out commands.
    pub(super) async fn read_profile_once(&mut self) -> Result<ReadoutPass, Sj210Error> {
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
        self.read_pass(&total_c, &block_c).await
    }

    /// Reads the profile; any failure restarts the whole read-out once from the total.
    pub async fn read_profile(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<ReadoutPass, Sj210Error> {
        let first = self.read_profile_once().await;
        self.read_profile_after(first, warnings).await
    }

    /// The read-out after its first pass: kept when it worked, else restarted once from the
    /// total (not when the model has no read-out or the device vanished).
    pub(super) async fn read_profile_after(
        &mut self,
        first: Result<ReadoutPass, Sj210Error>,
        warnings: &mut Vec<String>,
    ) -> Result<ReadoutPass, Sj210Error> {
        match first {
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
