//! The transcript recorder: an `AsyncRead + AsyncWrite` decorator that tees every frame of
//! a conversation into a transcript (format v1) the simulator can replay.
//!
//! ```text
//! # surfscan transcript v1
//! # instrument: <free text>
//! # model: sj210
//! # firmware: <as reported or unknown>
//! # date: <RFC 3339>
//! # notes: <free text>
//! <seconds since start, 6 decimals> <dir> <escaped bytes>
//! ```
//!
//! `dir` is `>` host→device or `<` device→host; one record per complete frame, terminator
//! (CR) included; escaping as [`super::codec::escape_bytes`]. Frames are kept in memory and
//! rendered at the end, so the header can carry the firmware read during the session.
//!
//! Layer 2 (I/O adapter): depends on [`super::codec`] only.

use super::codec::{escape_bytes, CR};
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Instant;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// Header of a transcript.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TranscriptHeader {
    /// Free text identifying the instrument (serial number, station).
    pub instrument: String,
    /// Model id ("sj210", …).
    pub model: String,
    /// Firmware as reported, `None` when unknown.
    pub firmware: Option<String>,
    /// Start of the recording, RFC 3339.
    pub date: String,
    /// Free text.
    pub notes: String,
}

/// Frames recorded so far.
#[derive(Debug)]
pub struct Transcript {
    start: Instant,
    records: Vec<String>,
    pending_tx: Vec<u8>,
    pending_rx: Vec<u8>,
}

impl Default for Transcript {
    fn default() -> Self {
        Transcript::new()
    }
}

impl Transcript {
    /// An empty transcript starting now.
    pub fn new() -> Transcript {
        Transcript {
            start: Instant::now(),
            records: Vec::new(),
            pending_tx: Vec::new(),
            pending_rx: Vec::new(),
        }
    }

    fn push(&mut self, dir: char, frame: &[u8]) {
        let t = self.start.elapsed().as_secs_f64();
        self.records
            .push(format!("{t:.6} {dir} {}", escape_bytes(frame)));
    }

    fn feed(&mut self, dir: char, bytes: &[u8]) {
        let mut pending = std::mem::take(if dir == '>' {
            &mut self.pending_tx
        } else {
            &mut self.pending_rx
        });
        for &b in bytes {
            pending.push(b);
            if b == CR {
                self.push(dir, &pending);
                pending.clear();
            }
        }
        if dir == '>' {
            self.pending_tx = pending;
        } else {
            self.pending_rx = pending;
        }
    }

    /// Records a host→device chunk.
    pub fn host_to_device(&mut self, bytes: &[u8]) {
        self.feed('>', bytes);
    }

    /// Records a device→host chunk.
    pub fn device_to_host(&mut self, bytes: &[u8]) {
        self.feed('<', bytes);
    }

    /// The complete-frame records so far (without header).
    pub fn records(&self) -> &[String] {
        &self.records
    }

    /// Renders the transcript; incomplete frames still pending are written as records
    /// without terminator so nothing received is lost.
    pub fn render(&self, header: &TranscriptHeader) -> String {
        let one_line = |s: &str| s.replace(['\r', '\n'], " ");
        let mut out = String::new();
        out.push_str("# surfscan transcript v1\n");
        out.push_str(&format!("# instrument: {}\n", one_line(&header.instrument)));
        out.push_str(&format!("# model: {}\n", one_line(&header.model)));
        out.push_str(&format!(
            "# firmware: {}\n",
            one_line(header.firmware.as_deref().unwrap_or("unknown"))
        ));
        out.push_str(&format!("# date: {}\n", one_line(&header.date)));
        out.push_str(&format!("# notes: {}\n", one_line(&header.notes)));
        for r in &self.records {
            out.push_str(r);
            out.push('\n');
        }
        let t = self.start.elapsed().as_secs_f64();
        for (dir, p) in [('>', &self.pending_tx), ('<', &self.pending_rx)] {
            if !p.is_empty() {
                out.push_str(&format!("{t:.6} {dir} {}\n", escape_bytes(p)));
            }
        }
        out
    }
}

/// A transcript shared between the recorder and whoever writes it out.
pub type SharedTranscript = Arc<Mutex<Transcript>>;

/// Wraps a byte stream and records every frame in both directions.
#[derive(Debug)]
pub struct Recorder<S> {
    inner: S,
    log: SharedTranscript,
}

impl<S> Recorder<S> {
    /// Wraps `inner`; frames go into `log`.
    pub fn new(inner: S, log: SharedTranscript) -> Recorder<S> {
        Recorder { inner, log }
    }

    /// The transcript.
    pub fn transcript(&self) -> SharedTranscript {
        Arc::clone(&self.log)
    }

    /// Gives the stream back.
    pub fn into_inner(self) -> S {
        self.inner
    }

    fn with_log(&self, f: impl FnOnce(&mut Transcript)) {
        // A poisoned lock only means another thread panicked mid-record; keep recording.
        let mut g = match self.log.lock() {
            Ok(g) => g,
            Err(p) => p.into_inner(),
        };
        f(&mut g);
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Recorder<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        let before = buf.filled().len();
        let r = Pin::new(&mut this.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = &r {
            let new = buf.filled().get(before..).unwrap_or(&[]).to_vec();
            if !new.is_empty() {
                this.with_log(|t| t.device_to_host(&new));
            }
        }
        r
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Recorder<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let r = Pin::new(&mut this.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = &r {
            let written = buf.get(..*n).unwrap_or(&[]).to_vec();
            this.with_log(|t| t.host_to_device(&written));
        }
        r
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    fn header() -> TranscriptHeader {
        TranscriptHeader {
            instrument: "bench\nunit 7".into(),
            model: "sj210".into(),
            firmware: None,
            date: "2026-11-22T07:00:00+00:00".into(),
            notes: "".into(),
        }
    }

    fn split_record(r: &str) -> (&str, &str, &str) {
        let mut it = r.splitn(3, ' ');
        (it.next().unwrap(), it.next().unwrap(), it.next().unwrap())
    }

    #[tokio::test]
    async fn records_one_line_per_frame_in_both_directions() {
        let (a, mut dev) = tokio::io::duplex(256);
        let log: SharedTranscript = Arc::new(Mutex::new(Transcript::new()));
        let mut rec = Recorder::new(a, Arc::clone(&log));
        rec.write_all(b"RDSJ 01\r").await.unwrap();
        let mut cmd = [0u8; 8];
        dev.read_exact(&mut cmd).await.unwrap();
        assert_eq!(&cmd, b"RDSJ 01\r");
        // The reply arrives in two chunks, with a stray LF and a µ and a backslash.
        dev.write_all(b"OKRa  \\ 1").await.unwrap();
        let mut got = vec![0u8; 9];
        rec.read_exact(&mut got).await.unwrap();
        dev.write_all(b".0 \xb5m\r\n").await.unwrap();
        let mut rest = vec![0u8; 7];
        rec.read_exact(&mut rest).await.unwrap();
        let t = log.lock().unwrap();
        let recs = t.records();
        assert_eq!(recs.len(), 2);
        let (ts, dir, bytes) = split_record(&recs[0]);
        assert_eq!((dir, bytes), (">", "RDSJ 01\\r"));
        assert_eq!(ts.split('.').nth(1).unwrap().len(), 6);
        assert!(ts.parse::<f64>().unwrap() >= 0.0);
        let (_, dir, bytes) = split_record(&recs[1]);
        assert_eq!((dir, bytes), ("<", "OKRa  \\\\ 1.0 \\xB5m\\r"));
        let text = t.render(&header());
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "# surfscan transcript v1");
        assert_eq!(lines[1], "# instrument: bench unit 7");
        assert_eq!(lines[2], "# model: sj210");
        assert_eq!(lines[3], "# firmware: unknown");
        assert_eq!(lines[4], "# date: 2026-11-22T07:00:00+00:00");
        assert_eq!(lines[5], "# notes: ");
        // The trailing LF is a pending, incomplete frame: written last, not lost.
        assert_eq!(split_record(lines[8]).1, "<");
        assert_eq!(split_record(lines[8]).2, "\\n");
        assert_eq!(lines.len(), 9);
    }
}
