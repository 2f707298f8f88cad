//! A trace's timeline as the host sees it: how long the drive measures and returns under the
//! instrument's conditions, when the status is asked next while a phase runs, and the overall
//! deadline.
//!
//! The drive traverses the evaluation length plus the pre- and post-travel (half a cut-off
//! each side, so one λc in all: M3, and the traverse the simulator plays), at the measuring
//! speed, then back at the return speed. The status is asked on the configured poll interval
//! while a phase runs (it sees a fault such as a retract or an over-range), and at the
//! phase's **expected end** exactly, so a trace that ends on time is seen ending then, not up
//! to a poll interval later. A phase that outlasts its expected end is asked again after
//! 20 ms, then after twice as long each time up to the poll interval: a drive a little slower
//! than its nominal speed costs a few short polls, one much slower costs no more than the
//! plain interval.
//!
//! The times are offsets from one origin (the trace's start), so the schedule is pure and
//! tested without a clock.
//!
//! Pure (layer 1): depends on [`crate::profile::Conditions`] only.

use crate::profile::Conditions;
use std::time::Duration;

/// The first poll after a phase's expected end comes this long after it.
pub const FIRST_LATE_POLL: Duration = Duration::from_millis(20);

/// The drive's speeds (M1 records no speed in `RDCON`: they come from the configuration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveSpeeds {
    /// Measuring speed, mm/s.
    pub measuring_mm_s: f64,
    /// Return speed, mm/s.
    pub return_mm_s: f64,
}

/// How long the two motions of one trace take.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceTiming {
    /// Measuring: traverse ÷ measuring speed.
    pub measuring: Duration,
    /// Returning: traverse ÷ return speed.
    pub returning: Duration,
}

/// The traverse of one trace in mm: evaluation length + λc of pre- and post-travel, when the
/// conditions give both.
pub fn traverse_mm(c: &Conditions) -> Option<f64> {
    let l = c
        .evaluation_length_mm
        .filter(|l| l.is_finite() && *l > 0.0)?;
    let lc = c.lambda_c_mm.filter(|l| l.is_finite() && *l >= 0.0)?;
    Some(l + lc)
}

/// The timing of a trace under `c`: `None` when the conditions do not give the traverse or a
/// speed is not a positive number. The speed the instrument reports, when it does, goes before
/// the configured measuring speed.
pub fn trace_timing(c: &Conditions, speeds: DriveSpeeds) -> Option<TraceTiming> {
    let traverse = traverse_mm(c)?;
    let measuring = c
        .speed_mm_s
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or(speeds.measuring_mm_s);
    let secs = |speed: f64| {
        if speed.is_finite() && speed > 0.0 {
            Duration::try_from_secs_f64(traverse / speed).ok()
        } else {
            None
        }
    };
    Some(TraceTiming {
        measuring: secs(measuring)?,
        returning: secs(speeds.return_mm_s)?,
    })
}

/// The overall deadline of a trace: twice (measuring + returning + 10 s), within 1 s and 1 h.
/// Without the traverse, the SJ-210's whole drive range (17.5 mm) is assumed.
pub fn trace_deadline(c: &Conditions, speeds: DriveSpeeds) -> Duration {
    const DRIVE_RANGE_MM: f64 = 17.5;
    let t = trace_timing(c, speeds).or_else(|| {
        let with_range = Conditions {
            evaluation_length_mm: Some(DRIVE_RANGE_MM),
            lambda_c_mm: Some(0.0),
            ..c.clone()
        };
        trace_timing(&with_range, speeds)
    });
    let secs = t.map_or(3600.0, |t| {
        (t.measuring.as_secs_f64() + t.returning.as_secs_f64() + 10.0) * 2.0
    });
    Duration::from_secs_f64(secs.clamp(1.0, 3600.0))
}

/// Characters the instrument sends per height in a profile read-out (value, separator and
/// the block's share of its framing), as the read-out's duration is estimated.
pub const READOUT_CHARS_PER_POINT: u64 = 12;

/// How long reading `points` heights out takes at `baud` (10 bits a character).
pub fn readout_time(points: u64, baud: u32) -> Duration {
    let bits = points
        .saturating_mul(READOUT_CHARS_PER_POINT)
        .saturating_mul(10);
    Duration::from_secs_f64(bits as f64 / f64::from(baud.max(1)))
}

/// The longest one trace can take with its read-out: the deadline of a trace over the whole
/// drive range ([`trace_deadline`] without conditions) and the read-out of `points` heights
/// four times (the driver reads a profile again once when the first read-out fails or is in
/// doubt, and a line whose Ra is far from its neighbours' is read out a second time, which
/// may be read again the same way).
pub fn longest_trace(speeds: DriveSpeeds, baud: u32, points: u64) -> Duration {
    trace_deadline(&Conditions::default(), speeds) + readout_time(points, baud) * 4
}

/// How long to wait before asking the status again, at `now`, while a phase expected to end
/// at `expected_end` runs (both from the same origin); `late_polls` is how many polls were
/// already made after that end. Without an expected end, the plain interval.
pub fn next_poll(
    now: Duration,
    expected_end: Option<Duration>,
    late_polls: u32,
    interval: Duration,
) -> Duration {
    match expected_end {
        Some(end) if now < end => (end - now).min(interval),
        Some(_) => FIRST_LATE_POLL
            .saturating_mul(1u32 << late_polls.min(16))
            .min(interval),
        None => interval,
    }
}

/// What the status has shown of one trace so far, and when each phase is expected to end.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseWatch {
    timing: Option<TraceTiming>,
    phase: Phase,
    /// When the previous poll was answered.
    last_poll: Duration,
    late_polls: u32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Started; "measuring" not seen yet.
    Starting,
    /// Measuring, expected to end at this offset.
    Measuring(Option<Duration>),
    /// Returning, expected back at this offset.
    Returning(Option<Duration>),
}

impl PhaseWatch {
    /// A trace started at offset 0.
    pub fn started(timing: Option<TraceTiming>) -> PhaseWatch {
        PhaseWatch {
            timing,
            phase: Phase::Starting,
            last_poll: Duration::ZERO,
            late_polls: 0,
        }
    }

    /// A drive already returning (seen at `at`), expected back at `back_at` when known.
    pub fn returning(at: Duration, back_at: Option<Duration>) -> PhaseWatch {
        PhaseWatch {
            timing: None,
            phase: Phase::Returning(back_at),
            last_poll: at,
            late_polls: 0,
        }
    }

    /// The status read "measuring" at `at`.
    pub fn saw_measuring(&mut self, at: Duration) {
        if self.phase == Phase::Starting {
            // Measuring began when the start was accepted (offset 0).
            self.phase = Phase::Measuring(self.timing.map(|t| t.measuring));
            self.late_polls = 0;
        }
        self.polled(at);
    }

    /// The status read "returning" at `at`. The measuring ended between the previous poll and
    /// this one: at its expected end if that lies in between, else as soon as it can have (the
    /// previous poll), so the drive is never expected back later than it can be.
    pub fn saw_returning(&mut self, at: Duration) {
        if !matches!(self.phase, Phase::Returning(_)) {
            let earliest = self.last_poll.min(at);
            let ended = match self.phase {
                Phase::Measuring(Some(end)) if end <= at => end.max(earliest),
                _ => earliest,
            };
            let back = self.timing.map(|t| ended.saturating_add(t.returning));
            self.phase = Phase::Returning(back);
            self.late_polls = 0;
        }
        self.polled(at);
    }

    /// Any other answer at `at`.
    pub fn saw_other(&mut self, at: Duration) {
        self.polled(at);
    }

    fn polled(&mut self, at: Duration) {
        if matches!(self.expected_end(), Some(end) if at >= end) {
            self.late_polls = self.late_polls.saturating_add(1);
        }
        self.last_poll = at;
    }

    /// When the phase running now is expected to end.
    pub fn expected_end(&self) -> Option<Duration> {
        match self.phase {
            Phase::Starting => None,
            Phase::Measuring(e) | Phase::Returning(e) => e,
        }
    }

    /// When the drive is expected back, once it was seen returning.
    pub fn back_at(&self) -> Option<Duration> {
        match self.phase {
            Phase::Returning(e) => e,
            _ => None,
        }
    }

    /// How long to wait at `now` before the next status poll.
    pub fn next_poll(&self, now: Duration, interval: Duration) -> Duration {
        // Polls at or after the end that found the phase still running count toward the
        // back-off; the first one after the end is the poll at the end itself.
        let late = self.late_polls.saturating_sub(1);
        next_poll(now, self.expected_end(), late, interval)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn cond(l: f64, lc: f64) -> Conditions {
        Conditions {
            evaluation_length_mm: Some(l),
            lambda_c_mm: Some(lc),
            ..Conditions::default()
        }
    }

    const SJ210: DriveSpeeds = DriveSpeeds {
        measuring_mm_s: 0.5,
        return_mm_s: 1.0,
    };

    #[test]
    fn a_trace_takes_its_traverse_at_each_speed() {
        // λc 0.8 mm × 5 = 4 mm + 0.8 mm of pre/post travel = 4.8 mm: 9.6 s out, 4.8 s back.
        let t = trace_timing(&cond(4.0, 0.8), SJ210).unwrap();
        assert_eq!(t.measuring, ms(9600));
        assert_eq!(t.returning, ms(4800));
        // A speed the instrument reports goes before the configured one.
        let mut c = cond(4.0, 0.8);
        c.speed_mm_s = Some(0.25);
        assert_eq!(trace_timing(&c, SJ210).unwrap().measuring, ms(19_200));
        // Without the evaluation length or λc, or with a speed that is no speed: unknown.
        assert!(trace_timing(&Conditions::default(), SJ210).is_none());
        let stopped = DriveSpeeds {
            measuring_mm_s: 0.0,
            ..SJ210
        };
        assert!(trace_timing(&cond(4.0, 0.8), stopped).is_none());
        // The deadline: 2 × (9.6 + 4.8 + 10) s; without conditions the 17.5 mm drive range.
        assert_eq!(trace_deadline(&cond(4.0, 0.8), SJ210), ms(48_800));
        // 8000 heights at 9600 baud: 8000 × 12 × 10 bits = 100 s; four times, plus the
        // whole drive range's deadline: 2 × (17.5 / 0.5 + 17.5 / 1 + 10) = 125 s.
        assert_eq!(readout_time(8000, 9600), ms(100_000));
        assert_eq!(longest_trace(SJ210, 9600, 8000), ms(525_000));
        assert_eq!(
            trace_deadline(&Conditions::default(), SJ210),
            ms(2 * (35_000 + 17_500 + 10_000))
        );
    }

    #[test]
    fn the_poll_lands_on_the_expected_end_then_backs_off_to_the_interval() {
        let i = ms(250);
        // Far from the end: the interval; close to it: exactly the time left.
        assert_eq!(next_poll(ms(0), Some(ms(9600)), 0, i), i);
        assert_eq!(next_poll(ms(9500), Some(ms(9600)), 0, i), ms(100));
        // After the end: 20, 40, 80, 160 ms, then the interval.
        let late: Vec<Duration> = (0..6)
            .map(|k| next_poll(ms(9600), Some(ms(9600)), k, i))
            .collect();
        assert_eq!(late, [ms(20), ms(40), ms(80), ms(160), i, i]);
        // A poll interval shorter than the first late poll is kept.
        assert_eq!(next_poll(ms(9700), Some(ms(9600)), 0, ms(10)), ms(10));
        assert_eq!(next_poll(ms(0), None, 0, i), i);
        assert_eq!(next_poll(ms(0), Some(ms(9600)), 40, i), i, "no overflow");
    }

    /// Polls as the client makes them against a drive whose phases end at `measure_end` and
    /// `back`; returns the offsets at which "returning" and "idle" were first seen.
    fn run(timing: Option<TraceTiming>, measure_end: u64, back: u64) -> (u64, u64, usize) {
        let i = ms(250);
        let mut w = PhaseWatch::started(timing);
        let mut now = ms(0);
        let mut seen_returning = None;
        let mut polls = 0;
        loop {
            now += w.next_poll(now, i);
            polls += 1;
            let t = now.as_millis() as u64;
            if t >= back {
                return (seen_returning.unwrap_or(t), t, polls);
            } else if t >= measure_end {
                seen_returning.get_or_insert(t);
                w.saw_returning(now);
            } else {
                w.saw_measuring(now);
            }
        }
    }

    #[test]
    fn a_drive_on_time_is_seen_at_its_ends_a_late_one_within_the_back_off() {
        let t = TraceTiming {
            measuring: ms(9600),
            returning: ms(4800),
        };
        // On time: each end is seen the moment it comes.
        assert_eq!(run(Some(t), 9600, 14_400).0, 9600);
        assert_eq!(run(Some(t), 9600, 14_400).1, 14_400);
        // On a 250 ms grid without the timing: 9750 and 14 500 (up to 250 ms late).
        let (r, b, _) = run(None, 9600, 14_400);
        assert_eq!((r, b), (9750, 14_500));
        // A drive 30 ms slower: polls at 9600 and 9620 still see it measuring, the one at
        // 9660 sees it returning; the return is reckoned from 9620 (the last poll that saw it
        // measuring): expected back at 14 420, seen at 14 440, 10 ms after it came.
        let (r, b, _) = run(Some(t), 9630, 14_430);
        assert_eq!(r, 9660);
        assert_eq!(b, 14_440);
        // A drive much slower than configured: seen no later than on the plain interval, with
        // a few more polls than the grid's 120 (each phase's end and its back-off: 5 each).
        let (r, b, polls) = run(Some(t), 20_000, 30_000);
        assert!(r - 20_000 <= 250, "{r}");
        assert!(b - 30_000 <= 250, "{b}");
        assert!(polls <= 30_000 / 250 + 10, "{polls} polls");
        // Faster than configured: the interval still sees it, as without the timing.
        assert_eq!(run(Some(t), 5000, 7000).0, 5000);
    }

    #[test]
    fn the_return_is_reckoned_from_when_measuring_ended_between_two_polls() {
        let t = TraceTiming {
            measuring: ms(9600),
            returning: ms(4800),
        };
        let mut w = PhaseWatch::started(Some(t));
        w.saw_measuring(ms(9500));
        // Measuring ended at its expected 9600 (between the polls at 9500 and 9700).
        w.saw_returning(ms(9700));
        assert_eq!(w.back_at(), Some(ms(14_400)));
        // Seen returning before its expected end (a faster drive): reckoned from the earlier
        // poll, the soonest it can be back.
        let mut w = PhaseWatch::started(Some(t));
        w.saw_measuring(ms(2000));
        w.saw_returning(ms(2250));
        assert_eq!(w.back_at(), Some(ms(2000 + 4800)));
        // A watch taken over by the next line's wait for idle keeps the same expectation.
        let again = PhaseWatch::returning(ms(9700), w.back_at());
        assert_eq!(again.next_poll(ms(6700), ms(250)), ms(100));
    }
}
