//! The host side of a simulated stage in tests: the stage serves one end of an in-memory
//! duplex stream, the test writes bytes to the other end and reads CR LF terminated lines
//! with a deadline in (paused) tokio time.

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use surfscan_sim::grbl::StageShared;
use tokio::io::WriteHalf;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader, DuplexStream, Lines, ReadHalf};
use tokio::time::Instant;

pub struct Host {
    lines: Lines<BufReader<ReadHalf<DuplexStream>>>,
    w: WriteHalf<DuplexStream>,
    pub shared: Arc<StageShared>,
}

impl Host {
    /// Spawns `serve` on the device end.
    pub fn start<F, Fut>(serve: F) -> Host
    where
        F: FnOnce(DuplexStream, Arc<StageShared>) -> Fut,
        Fut: Future<Output = std::io::Result<()>> + Send + 'static,
    {
        let (host, dev) = tokio::io::duplex(1 << 16);
        let shared = StageShared::new();
        tokio::spawn(serve(dev, shared.clone()));
        let (r, w) = tokio::io::split(host);
        Host {
            lines: BufReader::new(r).lines(),
            w,
            shared,
        }
    }

    pub async fn send(&mut self, b: &[u8]) {
        self.w.write_all(b).await.unwrap();
    }

    /// The next non-empty line without its CR, within `secs` of simulated time.
    pub async fn line_within(&mut self, secs: f64) -> Option<String> {
        let deadline = Instant::now() + Duration::from_secs_f64(secs);
        loop {
            match tokio::time::timeout_at(deadline, self.lines.next_line()).await {
                Err(_) => return None,
                Ok(l) => {
                    let l = l.unwrap().expect("stream open");
                    let l = l.trim_end_matches('\r').to_string();
                    if !l.is_empty() {
                        return Some(l);
                    }
                }
            }
        }
    }

    pub async fn line(&mut self) -> String {
        self.line_within(60.0)
            .await
            .expect("a line within a minute")
    }
}
