//! The line-reading loop both stage drivers share: bytes from the stream go through a
//! [`LineFramer`], complete lines queue up, and the driver takes them one at a time with a
//! deadline. Garbled or over-long lines are logged and skipped here, so each driver only
//! parses text it can understand.
//!
//! Layer 2 (I/O adapter): generic over `AsyncRead + AsyncWrite + Unpin`; depends on
//! [`super::framer`] and [`super::error`].

use super::framer::LineFramer;
use super::StageError;
use std::collections::VecDeque;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

/// A text-line link to a controller over any byte stream.
#[derive(Debug)]
pub struct LineLink<T> {
    io: T,
    framer: LineFramer,
    lines: VecDeque<String>,
    /// Who is on the other end, for the log ("GRBL", "Zaber").
    peer: &'static str,
}

impl<T: AsyncRead + AsyncWrite + Unpin> LineLink<T> {
    /// A link over `io` that refuses lines longer than `max_line` bytes.
    pub fn new(io: T, max_line: usize, peer: &'static str) -> Self {
        LineLink {
            io,
            framer: LineFramer::new(max_line),
            lines: VecDeque::new(),
            peer,
        }
    }

    /// Writes and flushes; a failure means the controller is gone.
    pub async fn write(&mut self, bytes: &[u8]) -> Result<(), StageError> {
        let r = async {
            self.io.write_all(bytes).await?;
            self.io.flush().await
        }
        .await;
        r.map_err(|e| StageError::Vanished {
            detail: format!("write failed: {e}"),
        })
    }

    /// The next complete line, `Ok(None)` when none arrived by `deadline`. End of stream
    /// and read errors are [`StageError::Vanished`].
    pub async fn next_line(&mut self, deadline: Instant) -> Result<Option<String>, StageError> {
        loop {
            if let Some(l) = self.lines.pop_front() {
                return Ok(Some(l));
            }
            let mut buf = [0u8; 256];
            let n = match tokio::time::timeout_at(deadline, self.io.read(&mut buf)).await {
                Err(_) => return Ok(None),
                Ok(Err(e)) => {
                    return Err(StageError::Vanished {
                        detail: format!("read failed: {e}"),
                    })
                }
                Ok(Ok(0)) => {
                    return Err(StageError::Vanished {
                        detail: "end of stream".into(),
                    })
                }
                Ok(Ok(n)) => n,
            };
            for l in self.framer.push(buf.get(..n).unwrap_or(&[])) {
                match l {
                    Ok(line) => self.lines.push_back(line),
                    Err(e) => tracing::warn!(error = %e, "garbled {} line", self.peer),
                }
            }
        }
    }

    /// Forgets the complete lines not yet taken (the partial line is kept).
    pub fn discard_queued(&mut self) {
        self.lines.clear();
    }

    /// Forgets everything received and not yet taken, the partial line included.
    pub fn clear(&mut self) {
        self.lines.clear();
        self.framer.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[tokio::test(start_paused = true)]
    async fn lines_split_across_reads_garbage_skipped_timeout_and_eof() {
        let (host, mut dev) = tokio::io::duplex(1024);
        let mut link = LineLink::new(host, 16, "test");
        dev.write_all(b"o").await.unwrap();
        dev.write_all(b"k\r\n\xff\x01\r\nsecond\n").await.unwrap();
        let soon = || Instant::now() + Duration::from_millis(50);
        assert_eq!(link.next_line(soon()).await.unwrap().as_deref(), Some("ok"));
        // The binary line is skipped, not returned.
        assert_eq!(
            link.next_line(soon()).await.unwrap().as_deref(),
            Some("second")
        );
        assert_eq!(link.next_line(soon()).await.unwrap(), None);
        dev.write_all(b"partial").await.unwrap();
        assert_eq!(link.next_line(soon()).await.unwrap(), None);
        link.clear();
        dev.write_all(b" tail\nnext\n").await.unwrap();
        assert_eq!(
            link.next_line(soon()).await.unwrap().as_deref(),
            Some(" tail")
        );
        drop(dev);
        assert_eq!(
            link.next_line(soon()).await.unwrap().as_deref(),
            Some("next")
        );
        assert!(matches!(
            link.next_line(soon()).await,
            Err(StageError::Vanished { .. })
        ));
    }
}
