//! The conversation with the instrument: one command in flight, a write deadline (the
//! first-byte timeout: a link that takes no bytes is as silent as one that gives none),
//! first-byte and inter-byte timeouts, recovery after a garbled or late reply (drain, re-read status), and bounded
//! retries of idempotent reads on "not now" codes. Never retries a `CT` command. For a probe
//! met with silence, the questions a stage controller answers (the ports swapped).
//!
//! Layer 2: part of [`super::Sj210Client`]; depends on [`crate::sj210::codec`] and
//! [`crate::sj210::error`].

use super::{io_err, millis, Sj210Client};
use crate::sj210::codec::{encode_command, escape_bytes, Reply};
use crate::sj210::error::{LinkError, Sj210Error};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite};
use tokio::time::{sleep, timeout, Instant};
use tokio_util::codec::Decoder;

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    /// Sends one command and reads one reply, without recovery or retry.
    async fn transact(&mut self, command: &str) -> Result<Reply, LinkError> {
        let bytes = encode_command(command)?;
        if self.in_flight {
            tracing::info!("the previous command was cancelled before its reply; draining the link before {command:?}");
            self.drain().await;
        }
        self.take_pending().await;
        if !self.buf.is_empty() {
            tracing::warn!(stale = %escape_bytes(&self.buf), "discarding unsolicited bytes before {command:?}");
            self.buf.clear();
            self.codec.reset();
        }
        tracing::debug!(tx = %escape_bytes(&bytes));
        self.in_flight = true;
        let reply = self.exchange(&bytes).await;
        self.in_flight = false;
        reply
    }

    /// Writes one encoded command (the link must take it within the first-byte timeout; see
    /// [`crate::transport::send`]) and reads its reply line.
    async fn exchange(&mut self, bytes: &[u8]) -> Result<Reply, LinkError> {
        crate::transport::send(&mut self.io, bytes, self.opts.first_byte)
            .await
            .map_err(|e| match e {
                crate::transport::SendError::Io(e) => io_err(e),
                stalled => LinkError::WriteStalled(stalled),
            })?;
        let mut got_any = false;
        loop {
            if let Some(reply) = self.codec.decode(&mut self.buf).map_err(io_err)? {
                tracing::debug!(rx = ?reply);
                return Ok(reply);
            }
            let wait = if got_any {
                self.opts.inter_byte
            } else {
                self.opts.first_byte
            };
            let mut chunk = [0u8; 512];
            match timeout(wait, self.io.read(&mut chunk)).await {
                Err(_) if got_any => {
                    return Err(LinkError::InterByteTimeout {
                        partial: escape_bytes(&self.buf),
                        waited_ms: millis(wait),
                    })
                }
                Err(_) => {
                    return Err(LinkError::FirstByteTimeout {
                        waited_ms: millis(wait),
                    })
                }
                Ok(Ok(0)) => {
                    return Err(LinkError::Vanished {
                        detail: "end of file on the port".into(),
                    })
                }
                Ok(Ok(n)) => {
                    got_any = true;
                    self.heard = true;
                    self.buf.extend_from_slice(chunk.get(..n).unwrap_or(&[]));
                }
                Ok(Err(e)) => return Err(io_err(e)),
            }
        }
    }

    /// Reads and discards input until the line is quiet for an inter-byte interval, but never
    /// longer than a first-byte timeout in total (a device that streams garbage must not hang
    /// us); forgets partial lines.
    async fn drain(&mut self) {
        let mut chunk = [0u8; 512];
        let drain_end = Instant::now() + self.opts.first_byte;
        while Instant::now() < drain_end {
            match timeout(self.opts.inter_byte, self.io.read(&mut chunk)).await {
                Ok(Ok(n)) if n > 0 => self.heard = true,
                _ => break,
            }
        }
        self.buf.clear();
        self.codec.reset();
    }

    /// Moves the bytes that arrived since the last exchange (a reply later than its timeout, a
    /// stray line) from the port into `buf` without waiting. They sit in the port's buffer, not
    /// yet read; left there, the next command would take the first of them for its own answer
    /// and every later answer on the link would be shifted by one.
    async fn take_pending(&mut self) {
        use futures::FutureExt;
        let mut chunk = [0u8; 512];
        // Bounded, so a device that never stops talking cannot hold the command back forever.
        for _ in 0..64 {
            match self.io.read(&mut chunk).now_or_never() {
                Some(Ok(n)) if n > 0 => {
                    self.heard = true;
                    self.buf.extend_from_slice(&chunk[..n]);
                }
                _ => break,
            }
        }
    }

    /// A stage controller's reply to the questions every one answers, when one is on this
    /// link: GRBL's status request `?` (a real-time byte) and a Zaber's empty command `/`.
    /// To an SJ-210 the bytes are one unknown command ending in CR (answered `NG`, drained
    /// here), so nothing is left in its buffer for the next command.
    pub(super) async fn stage_instead(&mut self) -> Option<String> {
        self.drain().await;
        if crate::transport::send(&mut self.io, b"?\n/\r", self.opts.first_byte)
            .await
            .is_err()
        {
            return None;
        }
        let mut heard = Vec::new();
        let end = Instant::now() + self.opts.first_byte;
        let mut chunk = [0u8; 512];
        while Instant::now() < end && heard.len() < 4096 {
            match timeout(end - Instant::now(), self.io.read(&mut chunk)).await {
                Ok(Ok(n)) if n > 0 => heard.extend_from_slice(&chunk[..n]),
                _ => break,
            }
            let text = String::from_utf8_lossy(&heard).into_owned();
            if let Some(line) = text
                .split(['\r', '\n'])
                .find(|l| crate::port_swap::is_stage_reply(l))
            {
                let line = line.trim().to_owned();
                self.drain().await;
                return Some(line);
            }
        }
        self.drain().await;
        None
    }

    /// After a timeout or malformed reply: drain what is still arriving, forget partial
    /// lines, and read the status once so the next command starts on a clean link.
    async fn recover(&mut self) {
        self.drain().await;
        let status = self.table.commands.status.plain();
        match self.transact(&status).await {
            Ok(r) => {
                tracing::info!(reply = ?r, "status after recovery");
                // A reply later than the drain window answers the status request instead,
                // and the real status reply follows it: swallow that one too, or every later
                // answer would be shifted by one.
                self.drain().await;
            }
            Err(e) => {
                tracing::warn!("status re-read after recovery failed: {e}");
                self.buf.clear();
                self.codec.reset();
            }
        }
    }

    /// One command, its `OK` payload, or a named error. `RD` commands are retried on
    /// NG011/NG033/NG101 within the retry budget when `retry` is true; `CT` commands never.
    pub async fn command(&mut self, command: &str, retry: bool) -> Result<String, Sj210Error> {
        let retry = retry && command.starts_with("RD");
        let started = Instant::now();
        loop {
            match self.transact(command).await {
                Ok(Reply::Ok(payload)) => {
                    for key in [mnemonic(command), command] {
                        if !self.answered.contains(key) {
                            self.answered.insert(key.to_owned());
                        }
                    }
                    return Ok(payload);
                }
                Ok(Reply::Ng { code, .. }) if self.contradicts(command, code.code()) => {
                    // The instrument understood this command before on this link: the
                    // conversation went wrong (a stray or late reply), the table is not wrong.
                    self.recover().await;
                    return Err(Sj210Error::UnexpectedReply {
                        command: command.to_string(),
                        payload: format!("NG{:03}", code.code()),
                        expected: "the reply this command was given earlier on this link (a stray or late reply was taken for the answer)",
                    });
                }
                Ok(Reply::Ng { code, byte_pos }) => {
                    if retry
                        && code.is_retryable_read()
                        && started.elapsed() + self.opts.poll_interval
                            <= self.opts.read_retry_budget
                    {
                        tracing::debug!("{command:?} answered {code}, retrying");
                        sleep(self.opts.poll_interval).await;
                        continue;
                    }
                    return Err(Sj210Error::Device {
                        command: command.to_string(),
                        code,
                        byte_pos,
                        meaning: code.meaning(),
                    });
                }
                Ok(Reply::Malformed(raw)) => {
                    self.recover().await;
                    return Err(Sj210Error::Link {
                        command: command.to_string(),
                        source: LinkError::Malformed {
                            raw: escape_bytes(&raw),
                        },
                    });
                }
                Err(source) => {
                    if !matches!(source, LinkError::Vanished { .. } | LinkError::Encode(_)) {
                        self.recover().await;
                    }
                    return Err(Sj210Error::Link {
                        command: command.to_string(),
                        source,
                    });
                }
            }
        }
    }

    /// Whether "not understood" (`NG0nn`) to `command` contradicts what the instrument said
    /// on this link: `NG030` (no such command) to a command whose mnemonic it answered, or
    /// `NG031`/`NG032` (a wrong data form) to this very command. Another data form of an
    /// answered mnemonic may well be wrong: the read-out forms `RDEVA100` and `RDEVA00` share
    /// `RDEVA`, and a firmware that reads one refuses the other with `NG031`.
    fn contradicts(&self, command: &str, code: u16) -> bool {
        match code {
            30 => self.answered.contains(mnemonic(command)),
            31 | 32 => self.answered.contains(command),
            _ => false,
        }
    }
}

/// The command's mnemonic: its first five characters (`RDEVA05` → `RDEVA`), all of it when
/// shorter.
fn mnemonic(command: &str) -> &str {
    command.get(..5).unwrap_or(command)
}
