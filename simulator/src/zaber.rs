//! A simulated Zaber ASCII single-axis device, written from Zaber's ASCII protocol
//! description with its own parser.
//!
//! Emulates: `/dev axis [id] command[:CC]` (message ids echoed, checksums verified), replies
//! `@dd a [id] OK|RJ BUSY|IDLE flag data`; `move abs`, `move rel`, `home`, `stop`, `get pos`,
//! `get deviceid`, `get maxspeed`/`accel`/`limit.min`/`limit.max` (in Zaber's data units),
//! `warnings clear`, the empty poll; trapezoidal motion at a configured speed
//! and acceleration × a time-scale factor; travel limits (`RJ … BADDATA`); a backlash dead
//! band; injected faults (`RJ`, stall `FS`, power cycle, silence, vanishing).
//!
//! Reference as a real axis has it: powered up (or power-cycled) it reads position 0 where
//! it stands and carries `WR` on every reply, status polls included, until a `home` has
//! completed: the home retracts to the home sensor at physical 0, comes back onto it from
//! below (taking out the backlash) and only then sets the reference and clears `WR`. A stall
//! stops the carriage where it happens (`IDLE FS` from then on; `BUSY --` before it).
//!
//! Depends on tokio, [`crate::motion`] and [`crate::grbl::StageShared`] (the shared handle and
//! fault list).

use crate::grbl::{StageFault, StageShared};
use crate::motion::Profile;
use std::future::Future;
use std::sync::atomic::Ordering;
use std::sync::Arc;
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
    /// Acceleration, microsteps per second².
    pub accel_per_s2: f64,
    /// Speed-up of simulated time.
    pub time_scale: f64,
    /// Backlash, microsteps.
    pub backlash: i64,
    /// Where the axis stands at start, microsteps from the home sensor.
    pub start: i64,
    /// The axis was homed before the link opened (position = `start`, no `WR`); otherwise it
    /// has just powered up: position 0 where it stands, `WR` until homed.
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
            accel_per_s2: 1_000_000.0,
            time_scale: 1.0,
            backlash: 0,
            start: 0,
            homed_at_start: false,
        }
    }
}

/// What a motion is for.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Purpose {
    Move,
    /// First leg of a home: retract past the sensor.
    HomeRetract,
    /// Second leg: onto the sensor from below; the reference is set when it ends.
    HomeApproach,
}

#[derive(Debug, Clone, Copy)]
struct Motion {
    /// Simulated start time, s.
    start: f64,
    /// Physical position at the start, microsteps.
    from: i64,
    sign: i64,
    prof: Profile,
    /// A stall stops the motion after this distance (microsteps along the profile).
    stall_at: Option<f64>,
    purpose: Purpose,
}

impl Motion {
    fn end_dist(&self) -> f64 {
        self.stall_at
            .map_or(self.prof.distance(), |s| s.min(self.prof.distance()))
    }

    fn end(&self) -> f64 {
        self.start + self.prof.time_at(self.end_dist())
    }

    fn phys_at(&self, t: f64) -> i64 {
        let d = self.prof.position(t - self.start).min(self.end_dist());
        self.from + self.sign * d.round() as i64
    }
}

struct Dev {
    cfg: ZaberSimConfig,
    shared: Arc<StageShared>,
    t0: Instant,
    scale: f64,
    /// Physical motor position, microsteps (0 = the home sensor).
    phys: i64,
    /// Physical minus reported position (changes when the reference is lost or set).
    offset: i64,
    carriage: i64,
    mv: Option<Motion>,
    referenced: bool,
    stalled: bool,
    interrupted: bool,
    reject_next: bool,
    stall_next: bool,
}

/// Zaber's speed unit: one microstep per second is 1.6384 data units (acceleration: one
/// microstep per s² is 0.16384).
const SPEED_DATA_PER_MICROSTEP_S: f64 = 1.6384;

fn lrc(body: &str) -> u8 {
    let mut s: u32 = 0;
    for b in body.bytes() {
        s += u32::from(b);
    }
    ((256 - (s % 256)) % 256) as u8
}

impl Dev {
    fn now(&self) -> f64 {
        Instant::now()
            .saturating_duration_since(self.t0)
            .as_secs_f64()
            * self.scale
    }

    fn pos(&self) -> i64 {
        self.phys - self.offset
    }

    fn set_phys(&mut self, p: i64) {
        self.phys = p;
        self.carriage = self.carriage.clamp(p, p + self.cfg.backlash);
        let nm = (self.carriage as f64 * self.cfg.nm_per_microstep).round() as i64;
        self.shared.publish_position_nm(nm);
    }

    /// Advances the motion to now: ends, stalls and the legs of a home.
    fn update(&mut self) {
        let now = self.now();
        while let Some(m) = self.mv {
            let end = m.end();
            if end > now {
                self.set_phys(m.phys_at(now));
                return;
            }
            self.set_phys(m.phys_at(end));
            self.mv = None;
            if m.stall_at.is_some_and(|s| s < m.prof.distance()) {
                self.stalled = true;
                return;
            }
            match m.purpose {
                Purpose::Move => {}
                Purpose::HomeRetract => self.start_motion(end, 0, Purpose::HomeApproach),
                Purpose::HomeApproach => {
                    // At the sensor: this is position 0 from now on.
                    self.offset = self.phys;
                    self.referenced = true;
                }
            }
        }
    }

    fn start_motion(&mut self, t: f64, to_phys: i64, purpose: Purpose) {
        let d = to_phys - self.phys;
        let prof = Profile::new(
            d.unsigned_abs() as f64,
            0.0,
            self.cfg.speed_per_s,
            self.cfg.accel_per_s2,
        );
        let stall_at = if purpose == Purpose::Move && std::mem::take(&mut self.stall_next) {
            Some((prof.distance() / 2.0).floor())
        } else {
            None
        };
        self.mv = Some(Motion {
            start: t,
            from: self.phys,
            sign: d.signum(),
            prof,
            stall_at,
            purpose,
        });
    }

    fn start_move(&mut self, to: i64) {
        let now = self.now();
        self.start_motion(now, to + self.offset, Purpose::Move);
        self.shared
            .note_move_started((to as f64 * self.cfg.nm_per_microstep).round() as i64);
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

    /// A power cycle: motion stops, the position reads 0 where the axis stands, `WR`.
    fn power_cycle(&mut self) {
        self.update();
        self.mv = None;
        self.offset = self.phys;
        self.referenced = false;
        self.stalled = false;
        self.interrupted = false;
    }

    /// Handles one command; returns (accepted, data).
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
            ["get", "pos"] if axis <= 1 => (true, self.pos().to_string()),
            // Speed and acceleration in Zaber's data units: microsteps/s × 1.6384 and
            // microsteps/s² × 1.6384 / 10.
            ["get", "maxspeed"] if axis <= 1 => (
                true,
                format!("{:.0}", self.cfg.speed_per_s * SPEED_DATA_PER_MICROSTEP_S),
            ),
            ["get", "accel"] if axis <= 1 => (
                true,
                format!(
                    "{:.0}",
                    self.cfg.accel_per_s2 * SPEED_DATA_PER_MICROSTEP_S / 10.0
                ),
            ),
            ["get", "limit.min"] if axis <= 1 => (true, "0".into()),
            ["get", "limit.max"] if axis <= 1 => (true, self.cfg.limit_max.to_string()),
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
                self.referenced = false;
                // Retract past the sensor (by the backlash and a margin), then back onto it.
                let now = self.now();
                let past = -(self.cfg.backlash + 10);
                self.start_motion(now, past.min(self.phys), Purpose::HomeRetract);
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
                Some(d) if (0..=self.cfg.limit_max).contains(&(self.pos() + d)) => {
                    self.start_move(self.pos() + d);
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
///
/// The device is built, and its start position published through `shared`, when this is
/// called, not when the returned future is first polled.
pub fn serve<T: AsyncRead + AsyncWrite + Unpin>(
    io: T,
    config: ZaberSimConfig,
    shared: Arc<StageShared>,
) -> impl Future<Output = std::io::Result<()>> {
    let scale = if config.time_scale.is_finite() && config.time_scale > 0.0 {
        config.time_scale
    } else {
        1.0
    };
    let mut d = Dev {
        t0: Instant::now(),
        scale,
        phys: config.start,
        offset: if config.homed_at_start {
            0
        } else {
            config.start
        },
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
    d.set_phys(d.phys);
    serve_device(io, d)
}

async fn serve_device<T: AsyncRead + AsyncWrite + Unpin>(
    mut io: T,
    mut d: Dev,
) -> std::io::Result<()> {
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
                StageFault::PositionLostWr => d.power_cycle(),
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
