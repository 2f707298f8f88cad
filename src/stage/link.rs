//! The line-reading loop both stage drivers share: bytes from the stream go through a
//! [`LineFramer`], complete lines queue up, and the driver takes them one at a time with a
//! deadline. Garbled or over-long lines are logged and skipped here, so each driver only
//! parses text it can understand. Writes have a deadline too.
//!
//! Layer 2 (I/O adapter): generic over `AsyncRead + AsyncWrite + Unpin`; depends on
//! [`super::framer`], [`super::error`] and [`crate::transport::send`].

use super::framer::LineFramer;
use super::StageError;
use std::collections::VecDeque;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite};
use tokio::time::Instant;

/// A text-line link to a controller over any byte stream.
#[derive(Debug)]
pub struct LineLink<T> {
    io: T,
    framer: LineFramer,
    lines: VecDeque<String>,
    /// Who is on the other end, for the log ("GRBL", "Zaber").
    peer: &'static str,
    /// How long the link may take to accept one command's bytes.
    write_deadline: std::time::Duration,
}

impl<T: AsyncRead + AsyncWrite + Unpin> LineLink<T> {
    /// A link over `io` that refuses lines longer than `max_line` bytes and gives a command
    /// `write_deadline` to be taken.
    pub fn new(
        io: T,
        max_line: usize,
        peer: &'static str,
        write_deadline: std::time::Duration,
    ) -> Self {
        LineLink {
            io,
            framer: LineFramer::new(max_line),
            lines: VecDeque::new(),
            peer,
            write_deadline,
        }
    }

    /// Hands a command to the link within the write deadline ([`crate::transport::send`]:
    /// no flush, which would block a thread while the link takes no bytes). A link that
    /// stopped taking bytes is [`StageError::Stalled`]; a write error means the controller
    /// is gone.
    pub async fn write(&mut self, bytes: &[u8]) -> Result<(), StageError> {
        crate::transport::send(&mut self.io, bytes, self.write_deadline)
            .await
            .map_err(|e| match e {
                crate::transport::SendError::Io(e) => StageError::Vanished {
                    detail: format!("write failed: {e}"),
                },
                stalled => StageError::Stalled(stalled),
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
    use crate::devices::{DeviceFault, FaultClass};
    use std::time::Duration;
    use tokio::io::AsyncWriteExt;

    /// A controller whose link stops taking bytes: the write ends at its deadline as a
    /// stall (a fault the scan handles), not a hang and not a vanished controller.
    #[tokio::test(start_paused = true)]
    async fn a_write_the_link_does_not_take_ends_at_its_deadline() {
        let (host, _dev) = tokio::io::duplex(2);
        let mut link = LineLink::new(host, 16, "test", Duration::from_millis(300));
        let t0 = Instant::now();
        let e = link.write(b"$J=G90Y-1\n").await.unwrap_err();
        assert_eq!(t0.elapsed(), Duration::from_millis(300));
        assert!(matches!(e, StageError::Stalled(_)), "{e:?}");
        assert_eq!(e.class(), FaultClass::Silent);
        assert!(
            e.to_string().contains("took 2 of the command's 10 byte(s)"),
            "{e}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn lines_split_across_reads_garbage_skipped_timeout_and_eof() {
        let (host, mut dev) = tokio::io::duplex(1024);
        let mut link = LineLink::new(host, 16, "test", Duration::from_secs(1));
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
