//! A simulated Zaber ASCII single-axis device, written from Zaber's ASCII protocol
//! description with its own parser.
//!
//! Emulates: `/dev axis [id] command[:CC]` (message ids echoed, checksums verified), replies
//! `@dd a [id] OK|RJ BUSY|IDLE flag data`; `move abs`, `move rel`, `home`, `stop`, `get pos`,
//! `get deviceid`, `warnings clear`, the empty poll; motion at a configured speed × a
//! time-scale factor; travel limits (`RJ … BADDATA`); `WR` until homed; a backlash dead band;
//! injected faults (`RJ`, stall `FS`, position lost `WR`, silence, vanishing).
//!
//! Depends on tokio and [`crate::grbl::StageShared`] (the shared handle and fault list).

use crate::grbl::{StageFault, StageShared};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::time::Instant;

/// Configuration of the simulated Zaber device.
#[derive(Debug, Clone)]
pub struct ZaberSimConfig {
    /// Device address.
    pub device: u8,
    /// Device id reported by `get deviceid`.
    pub device_id: u32,
    /// Size of one microstep, nm.
    pub nm_per_microstep: f64,
    /// Travel: positions in [0, limit_max].
    pub limit_max: i64,
    /// Speed, microsteps per second.
    pub speed_per_s: f64,
    /// Speed-up of simulated time.
    pub time_scale: f64,
    /// Backlash, microsteps.
    pub backlash: i64,
    /// Start position, microsteps.
    pub start: i64,
    /// Whether the device starts referenced (otherwise `WR` until homed).
    pub homed_at_start: bool,
}

impl Default for ZaberSimConfig {
    fn default() -> Self {
        ZaberSimConfig {
            device: 1,
            device_id: 50081,
            nm_per_microstep: 125.0,
            limit_max: 800_000,
            speed_per_s: 100_000.0,
            time_scale: 1.0,
            backlash: 0,
            start: 0,
            homed_at_start: false,
        }
    }
}

struct Move {
    from: i64,
    to: i64,
    start: Instant,
    dur: Duration,
}

struct Dev {
    cfg: ZaberSimConfig,
    shared: Arc<StageShared>,
    pos: i64,
    /// Physical motor minus reported position (changes when the reference is lost).
    offset: i64,
    carriage: i64,
    mv: Option<Move>,
    referenced: bool,
    stalled: bool,
    interrupted: bool,
    reject_next: bool,
    stall_next: bool,
}

fn lrc(body: &str) -> u8 {
    let mut s: u32 = 0;
    for b in body.bytes() {
        s += u32::from(b);
    }
    ((256 - (s % 256)) % 256) as u8
}

impl Dev {
    fn set_pos(&mut self, p: i64) {
        self.pos = p;
        let phys = p + self.offset;
        self.carriage = self.carriage.clamp(phys, phys + self.cfg.backlash);
        let nm = (self.carriage as f64 * self.cfg.nm_per_microstep).round() as i64;
        self.shared.publish_position_nm(nm);
    }

    fn update(&mut self) {
        if let Some(m) = &self.mv {
            let (from, to, start, dur) = (m.from, m.to, m.start, m.dur);
            let el = Instant::now().saturating_duration_since(start);
            if el >= dur {
                self.mv = None;
                self.set_pos(to);
            } else {
                let f = el.as_secs_f64() / dur.as_secs_f64().max(1e-9);
                self.set_pos(from + ((to - from) as f64 * f).round() as i64);
            }
        }
    }

    fn start_move(&mut self, to: i64) {
        let to = if self.stall_next {
            self.stall_next = false;
            self.stalled = true;
            self.pos + (to - self.pos) / 2
        } else {
            to
        };
        let secs =
            (to - self.pos).unsigned_abs() as f64 / self.cfg.speed_per_s / self.cfg.time_scale;
        self.mv = Some(Move {
            from: self.pos,
            to,
            start: Instant::now(),
            dur: Duration::from_secs_f64(secs),
        });
        self.shared.note_move_started();
    }

    fn flag(&self) -> &'static str {
        if self.stalled {
            "FS"
        } else if !self.referenced {
            "WR"
        } else if self.interrupted {
            "NI"
        } else {
            "--"
        }
    }

    /// Handles one command; returns (accepted, data) or `None` for no reply.
    fn command(&mut self, axis: u8, words: &[&str]) -> (bool, String) {
        self.update();
        if self.reject_next {
            self.reject_next = false;
            return (false, "AGAIN".into());
        }
        let num = |i: usize| words.get(i).and_then(|w| w.parse::<i64>().ok());
        match words {
            [] => (true, "0".into()),
            ["get", "deviceid"] => (true, self.cfg.device_id.to_string()),
            ["get", "pos"] if axis <= 1 => (true, self.pos.to_string()),
            ["warnings", "clear"] => {
                let f = self.flag().to_string();
                self.stalled = false;
                self.interrupted = false;
                (true, f)
            }
            ["home"] if axis <= 1 => {
                self.shared.note_homing_started();
                self.stalled = false;
                self.interrupted = false;
                // Retract to the home sensor, back off, reset the position.
                self.offset = 0;
                self.set_pos(self.pos.max(0) + self.cfg.backlash + 10);
                self.set_pos(-(self.cfg.backlash + 10));
                self.referenced = true;
                let secs = 0.5 / self.cfg.time_scale;
                self.mv = Some(Move {
                    from: -(self.cfg.backlash + 10),
                    to: 0,
                    start: Instant::now(),
                    dur: Duration::from_secs_f64(secs),
                });
                (true, "0".into())
            }
            ["stop"] if axis <= 1 => {
                if self.mv.take().is_some() {
                    self.interrupted = true;
                }
                (true, "0".into())
            }
            ["move", "abs", _] if axis <= 1 => match num(2) {
                Some(t) if (0..=self.cfg.limit_max).contains(&t) && !self.stalled => {
                    self.interrupted = false;
                    self.start_move(t);
                    (true, "0".into())
                }
                Some(_) if self.stalled => (false, "STATUSBUSY".into()),
                _ => (false, "BADDATA".into()),
            },
            ["move", "rel", _] if axis <= 1 => match num(2) {
                Some(d) if (0..=self.cfg.limit_max).contains(&(self.pos + d)) => {
                    self.start_move(self.pos + d);
                    (true, "0".into())
                }
                _ => (false, "BADDATA".into()),
            },
            _ => (false, "BADCOMMAND".into()),
        }
    }

    fn handle_line(&mut self, line: &str) -> Option<String> {
        let body = line.trim().strip_prefix('/')?;
        let body = match body.rsplit_once(':') {
            Some((b, cc)) if cc.len() == 2 => {
                let carried = u8::from_str_radix(cc, 16).ok()?;
                if carried != lrc(b) {
                    return None;
                }
                b
            }
            _ => body,
        };
        let toks: Vec<&str> = body.split_whitespace().collect();
        let (dev, rest) = match toks.first().and_then(|t| t.parse::<u8>().ok()) {
            Some(d) => (d, toks.get(1..).unwrap_or(&[])),
            None => (0, &toks[..]),
        };
        if dev != 0 && dev != self.cfg.device {
            return None;
        }
        let (axis, rest) = match rest.first().and_then(|t| t.parse::<u8>().ok()) {
            Some(a) => (a, rest.get(1..).unwrap_or(&[])),
            None => (0, rest),
        };
        let (id, rest) = match rest.first() {
            Some(t) if t.len() == 2 && t.bytes().all(|c| c.is_ascii_digit()) => {
                (Some(*t), rest.get(1..).unwrap_or(&[]))
            }
            _ => (None, rest),
        };
        let (ok, data) = if axis > 1 {
            (false, "BADAXIS".to_string())
        } else {
            self.command(axis, rest)
        };
        self.update();
        let busy = if self.mv.is_some() { "BUSY" } else { "IDLE" };
        let id = id.map(|i| format!(" {i}")).unwrap_or_default();
        Some(format!(
            "@{:02} {axis}{id} {} {busy} {} {data}\r\n",
            self.cfg.device,
            if ok { "OK" } else { "RJ" },
            self.flag()
        ))
    }
}

/// Serves the Zaber ASCII protocol on `io` until the host closes it or a `Vanish` fault.
pub async fn serve<T: AsyncRead + AsyncWrite + Unpin>(
    mut io: T,
    config: ZaberSimConfig,
    shared: Arc<StageShared>,
) -> std::io::Result<()> {
    let mut d = Dev {
        pos: config.start,
        offset: 0,
        carriage: config.start,
        mv: None,
        referenced: config.homed_at_start,
        stalled: false,
        interrupted: false,
        reject_next: false,
        stall_next: false,
        shared,
        cfg: config,
    };
    d.set_pos(d.pos);
    let mut silent = false;
    let mut line = Vec::new();
    let mut buf = [0u8; 256];
    loop {
        let n = io.read(&mut buf).await?;
        if n == 0 {
            return Ok(());
        }
        d.shared
            .bytes_received
            .fetch_add(n as u64, Ordering::SeqCst);
        while let Some(f) = d.shared.take_fault() {
            match f {
                StageFault::Reject => d.reject_next = true,
                StageFault::Stall => d.stall_next = true,
                StageFault::PositionLostWr => {
                    d.update();
                    d.mv = None;
                    d.offset += d.pos;
                    d.pos = 0;
                    d.referenced = false;
                }
                StageFault::Silence => silent = true,
                StageFault::Vanish => return Ok(()),
                StageFault::ResetBanner | StageFault::Alarm2 | StageFault::Error15 => {}
            }
        }
        let mut out = String::new();
        for &b in buf.get(..n).unwrap_or(&[]) {
            if b == b'\n' || b == b'\r' {
                if !line.is_empty() {
                    let l = String::from_utf8_lossy(&line).into_owned();
                    line.clear();
                    if let Some(r) = d.handle_line(&l) {
                        out.push_str(&r);
                    }
                }
            } else if line.len() < 200 {
                line.push(b);
            }
        }
        if !silent && !out.is_empty() {
            io.write_all(out.as_bytes()).await?;
        }
    }
}
