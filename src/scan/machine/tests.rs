//! The session core driven through its promises without a runtime, a disk or a clock: each
//! test feeds events at chosen times and reads the actions back.

use super::*;
use crate::devices::FaultClass;
use crate::scan::command::StartMode;
use crate::scan::ending::{FailKind, StopStatus};
use crate::scan::policy::StorageClass;
use crate::scan::reasons::mb;

const LINES: u32 = 3;

fn plan() -> Plan {
    Plan {
        lines: LINES,
        y_start_nm: Nm(-20_000_000),
        y_step_nm: Nm(10_000),
        degree_u: 3,
        degree_v: 2,
        max_line_attempts: 3,
        v_method: Default::default(),
        replace_spikes: None,
        analysis: None,
    }
}

fn policy() -> Policy {
    Policy {
        backoff: Backoff {
            initial: Duration::from_secs(1),
            max: Duration::from_secs(8),
        },
        transient_budget: Duration::from_secs(60),
        home_on_start: false,
    }
}

fn peer() -> Peer {
    Peer {
        uid: 1000,
        gid: 100,
        pid: Some(4242),
        web: None,
        mqtt: None,
    }
}

fn fault(device: Device, class: FaultClass, message: &str) -> Fault {
    Fault {
        device,
        class,
        ng_code: None,
        message: message.to_owned(),
    }
}

fn good_line() -> TracedSummary {
    TracedSummary {
        points: 100,
        pitch_x_mm: 0.0005,
        first_non_finite: None,
        conditions: Conditions::default(),
        ra_um: Some(0.2),
    }
}

/// A machine and a clock the test moves by hand.
struct Rig {
    m: Machine,
    t0: Instant,
    wall0: DateTime<Utc>,
    elapsed: Duration,
    /// Every action returned so far.
    log: Vec<Action>,
}

impl Rig {
    /// A new scan whose devices opened and whose directory exists: the first line's
    /// `EnsureIdle` is the last action.
    fn started() -> Rig {
        let mut r = Rig::fresh();
        let a = r.start();
        assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)));
        r.feed(opened(Device::Instrument));
        let a = r.feed(opened(Device::Stage));
        assert_eq!(effect(&a), Some(&Action::CreateScan));
        let a = r.feed(Event::Created {
            scan_id: "S".into(),
            dir: "/out/S".into(),
            conditions: Conditions::default(),
            points_per_line: 100,
        });
        assert_eq!(effect(&a), Some(&Action::EnsureIdle));
        r
    }

    fn fresh() -> Rig {
        Rig::with(Machine::new_scan(plan(), policy(), Status::idle()))
    }

    fn with(m: Machine) -> Rig {
        Rig {
            m,
            t0: Instant::now(),
            wall0: DateTime::parse_from_rfc3339("2026-12-02T01:00:00Z")
                .expect("time")
                .with_timezone(&Utc),
            elapsed: Duration::ZERO,
            log: Vec::new(),
        }
    }

    fn now(&self) -> Now {
        Now {
            mono: self.t0 + self.elapsed,
            wall: self.wall0 + chrono::Duration::from_std(self.elapsed).expect("duration"),
        }
    }

    fn start(&mut self) -> Vec<Action> {
        let a = self.m.start(self.now());
        self.log.extend(a.iter().cloned());
        a
    }

    fn feed(&mut self, ev: Event) -> Vec<Action> {
        let a = self.m.handle(ev, self.now());
        self.log.extend(a.iter().cloned());
        a
    }

    fn wait(&mut self, d: Duration) {
        self.elapsed += d;
    }

    /// Drives the current line from `EnsureIdle` to its commit and push.
    fn line_ok(&mut self) -> Vec<Action> {
        self.feed(Event::Idle);
        self.feed(Event::Arrived);
        let a = self.feed(Event::Traced(good_line()));
        assert!(matches!(effect(&a), Some(Action::Commit { .. })), "{a:?}");
        self.feed(Event::Committed);
        self.feed(Event::Pushed)
    }

    /// Drives the machine to the trace of the current line (after `EnsureIdle`).
    fn up_to_trace(&mut self) {
        self.feed(Event::Idle);
        let a = self.feed(Event::Arrived);
        assert_eq!(effect(&a), Some(&Action::Trace));
    }

    fn records(&self) -> Vec<String> {
        self.log
            .iter()
            .filter_map(|a| match a {
                Action::Record(n) => Some(n.reason.clone()),
                _ => None,
            })
            .collect()
    }
}

fn opened(device: Device) -> Event {
    Event::Opened {
        device,
        position_trusted: true,
    }
}

fn fault_event(device: Device, class: FaultClass, message: &str, trace_started: bool) -> Event {
    Event::Fault {
        fault: fault(device, class, message),
        trace_started,
    }
}

/// A fault of the instrument; `trace_started`: it broke off a trace.
fn instrument_fault(class: FaultClass, message: &str, trace_started: bool) -> Event {
    fault_event(Device::Instrument, class, message, trace_started)
}

/// The effect of a batch (its last action, when it is one).
fn effect(actions: &[Action]) -> Option<&Action> {
    actions.last().filter(|a| a.is_effect())
}

fn stop_of(actions: &[Action]) -> Option<&End> {
    actions.iter().find_map(|a| match a {
        Action::Stop(e) => Some(e),
        _ => None,
    })
}

fn last_status(actions: &[Action]) -> Option<&Status> {
    actions.iter().rev().find_map(|a| match a {
        Action::Publish(s) => Some(s),
        _ => None,
    })
}

/// The wait of the last timer the machine set.
fn last_timer(r: &Rig) -> Duration {
    r.log
        .iter()
        .rev()
        .find_map(|a| match a {
            Action::SetTimer(d) => Some(*d),
            _ => None,
        })
        .expect("a timer was set")
}

/// How the machine reacts to a fault.
#[derive(Debug, PartialEq)]
enum Reaction {
    /// Closes the device and reopens it at once (suspension costs no attempt).
    Reopen(Device),
    /// Waits (backoff) and tries the line again; the scan is suspended meanwhile.
    RetryAfter(Duration),
    /// Homes the stage before the line is tried again, once the drive is at rest: the
    /// machine asks for idle first, and its `Idle` leads to the home.
    Rehome,
    /// The scan fails.
    Fails,
}

fn reaction(actions: &[Action]) -> Reaction {
    if stop_of(actions).is_some() {
        return Reaction::Fails;
    }
    match effect(actions) {
        Some(Action::Open(d)) => {
            assert!(actions.contains(&Action::Close(*d)), "{actions:?}");
            Reaction::Reopen(*d)
        }
        Some(Action::SetTimer(d)) => Reaction::RetryAfter(*d),
        Some(Action::EnsureIdle) => Reaction::Rehome,
        other => panic!("unexpected reaction {other:?} in {actions:?}"),
    }
}

/// Brings a started scan to one step of its first line.
type ToStep = fn(&mut Rig);

/// The README's fault table, per fault class and per step of a line: every class in every
/// state it can arise in.
/// A resumed scan of the test plan: `committed` lines on disk without a gap, `ahead` after
/// the first gap, paused or not when its process stopped.
fn resumed_scan(committed: u32, ahead: &[u32], paused: bool) -> Machine {
    Machine::resumed(
        plan(),
        policy(),
        Status::idle(),
        Resumed {
            scan_id: "S".into(),
            dir: "/out/S".into(),
            committed,
            ahead: ahead.iter().copied().collect(),
            columns: Some(100),
            pitch_x_mm: Some(0.0005),
            conditions: Conditions::default(),
            points_per_line: 100,
            paused,
        },
    )
}

#[test]
fn every_fault_class_in_every_step_of_a_line_gets_its_reaction() {
    use FaultClass::*;
    let steps: [(&str, ToStep); 4] = [
        ("homing", |r| {
            // A stage that needs homing (its position is not trusted after a reopen).
            r.feed(fault_event(Device::Stage, Absent, "EOF", false));
            let a = r.feed(Event::Opened {
                device: Device::Stage,
                position_trusted: false,
            });
            // Not before the drive is at rest.
            assert_eq!(effect(&a), Some(&Action::EnsureIdle));
            let a = r.feed(Event::Idle);
            assert_eq!(effect(&a), Some(&Action::Home));
        }),
        ("ensuring idle", |_| {}),
        ("moving", |r| {
            let a = r.feed(Event::Idle);
            assert_eq!(effect(&a), Some(&Action::Move(plan().target(0))));
        }),
        ("tracing", |r| r.up_to_trace()),
    ];
    let table = [
        (Absent, Reaction::Reopen(Device::Instrument)),
        (Silent, Reaction::Reopen(Device::Instrument)),
        (Transient, Reaction::RetryAfter(Duration::from_secs(1))),
        (PositionLost, Reaction::Rehome),
        (Fatal, Reaction::Fails),
    ];
    for (step, to_step) in steps {
        for (class, want) in &table {
            let mut r = Rig::started();
            to_step(&mut r);
            let a = r.feed(instrument_fault(*class, "boom", false));
            assert_eq!(&reaction(&a), want, "{class:?} while {step}");
            if *want == Reaction::Rehome {
                let a = r.feed(Event::Idle);
                assert_eq!(effect(&a), Some(&Action::Home), "{step}");
            }
            if *class == Fatal {
                assert_eq!(
                    stop_of(&a),
                    Some(&End::Fail(FailReason::Fatal {
                        line: Some(0),
                        fault: fault(Device::Instrument, Fatal, "boom"),
                    })),
                    "{step}"
                );
            }
            if *class == Transient {
                let s = last_status(&a).expect("status");
                assert_eq!(s.state, State::Suspended, "{step}");
                assert!(
                    s.reason.as_deref().unwrap_or_default().starts_with(
                        "instrument answering wrongly or not in time since 2026-12-02T01:00:00Z"
                    ),
                    "{step}: {:?}",
                    s.reason
                );
                assert!(
                    r.records().iter().any(|n| n.starts_with(
                        "suspended: instrument answering wrongly or not in time since"
                    )),
                    "{step}: {:?}",
                    r.records()
                );
            }
        }
    }
}

/// An instrument that says nothing (no reply, or a link that takes no bytes) is waited for
/// like an unplugged one: closed, reopened with backoff, suspended "not answering", for far
/// longer than the transient budget, and the scan goes on when it answers; the time it was
/// waited for is not spent from the budget.
#[test]
fn a_silent_instrument_is_waited_for_past_the_budget_and_the_scan_goes_on() {
    let mut r = Rig::started();
    r.up_to_trace();
    let a = r.feed(instrument_fault(
        FaultClass::Silent,
        "\"CTSTA\": no reply within 2000 ms",
        true,
    ));
    assert_eq!(stop_of(&a), None);
    assert!(a.contains(&Action::Close(Device::Instrument)), "{a:?}");
    assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)));
    // Reopening finds it silent again and again, for ten budgets.
    let budget = policy().transient_budget;
    let mut waits = Vec::new();
    while r.elapsed < budget * 10 {
        let a = r.feed(instrument_fault(
            FaultClass::Silent,
            "\"RDSJ 01\": no reply within 2000 ms",
            false,
        ));
        assert_eq!(stop_of(&a), None, "a silent device never ends the scan");
        let Some(Action::SetTimer(d)) = effect(&a) else {
            panic!("{a:?}")
        };
        waits.push(*d);
        let s = r.m.status();
        assert_eq!(s.state, State::Suspended);
        assert!(
            s.reason
                .as_deref()
                .is_some_and(|m| m.starts_with("instrument not answering")),
            "{:?}",
            s.reason
        );
        r.wait(*d);
        let a = r.feed(Event::TimerFired);
        assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)));
    }
    assert_eq!(&waits[..4], &[1, 2, 4, 8].map(Duration::from_secs));
    // One suspension, not one per try.
    let suspended = r
        .log
        .iter()
        .filter(|a| matches!(a, Action::Notify(ScanEventKind::Suspended, _)))
        .count();
    assert_eq!(suspended, 1);
    // It answers: the line is traced again, and a transient fault now has the whole budget.
    r.feed(opened(Device::Instrument));
    r.up_to_trace();
    let a = r.feed(instrument_fault(FaultClass::Transient, "NG011", true));
    assert_eq!(
        effect(&a),
        Some(&Action::SetTimer(Duration::from_secs(1))),
        "{a:?}"
    );
    assert!(
        r.records()
            .iter()
            .any(|n| n.starts_with("instrument back after")),
        "{:?}",
        r.records()
    );
}

#[test]
fn a_scan_traces_idle_move_trace_commit_push_per_line_then_writes_its_outputs() {
    let mut r = Rig::started();
    for k in 0..LINES {
        let a = r.feed(Event::Idle);
        assert_eq!(effect(&a), Some(&Action::Move(plan().target(k))));
        let a = r.feed(Event::Arrived);
        assert_eq!(effect(&a), Some(&Action::Trace));
        let a = r.feed(Event::Traced(good_line()));
        assert_eq!(
            effect(&a),
            Some(&Action::Commit {
                line: k,
                attempt: 1
            })
        );
        let a = r.feed(Event::Committed);
        assert_eq!(effect(&a), Some(&Action::Push { line: k }));
        r.wait(Duration::from_secs(10));
        let a = r.feed(Event::Pushed);
        let s = last_status(&a).expect("status");
        assert_eq!(s.lines_done, k + 1);
        assert_eq!(s.last_ra_um, Some(0.2));
        if k + 1 < LINES {
            assert_eq!(effect(&a), Some(&Action::EnsureIdle));
        } else {
            assert_eq!(effect(&a), Some(&Action::WriteOutputs));
        }
    }
    let a = r.feed(Event::OutputsWritten {
        summary: "3 lines".into(),
    });
    assert_eq!(
        stop_of(&a),
        Some(&End::Success {
            summary: "3 lines".into()
        })
    );
    assert!(a.contains(&Action::Notify(ScanEventKind::Success, "3 lines".into())));
    // The scan's events: started when its directory was created, then its ending.
    let told: Vec<ScanEventKind> = r
        .log
        .iter()
        .filter_map(|a| match a {
            Action::Notify(k, _) => Some(*k),
            _ => None,
        })
        .collect();
    assert_eq!(told, [ScanEventKind::Started, ScanEventKind::Success]);
    let s = last_status(&a).expect("status");
    assert_eq!(s.state, State::Idle);
    assert_eq!(
        s.last_stop.as_ref().map(|l| (l.status, l.scan_id.as_str())),
        Some((StopStatus::Success, "S"))
    );
    assert!(r.m.ended());
    // No move was ever asked for before its line's idle.
    let mut idle = false;
    for a in &r.log {
        match a {
            Action::EnsureIdle => idle = true,
            Action::Move(_) => {
                assert!(idle, "a move without an idle before it");
                idle = false;
            }
            _ => {}
        }
    }
}

#[test]
fn transient_faults_are_retried_with_backoff_until_the_budget_is_spent() {
    let mut r = Rig::started();
    r.up_to_trace();
    let mut waits = Vec::new();
    loop {
        let a = r.feed(instrument_fault(FaultClass::Transient, "NG011 busy", false));
        if let Some(end) = stop_of(&a) {
            match end {
                End::Fail(FailReason::BudgetExhausted {
                    line,
                    budget_s,
                    last,
                    traces,
                    ..
                }) => {
                    assert_eq!((*line, *budget_s, *traces), (0, 60, 0));
                    assert_eq!(last, "line 1: instrument: NG011 busy");
                }
                other => panic!("{other:?}"),
            }
            break;
        }
        let Some(Action::SetTimer(d)) = effect(&a) else {
            panic!("{a:?}")
        };
        waits.push(d.as_secs());
        r.wait(*d);
        let a = r.feed(Event::TimerFired);
        assert_eq!(
            effect(&a),
            Some(&Action::EnsureIdle),
            "the line is tried again"
        );
        r.up_to_trace();
    }
    // 1, 2, 4, 8, 8, … capped at the budget's remainder; 60 s in all.
    assert_eq!(waits, vec![1, 2, 4, 8, 8, 8, 8, 8, 8, 5]);
    assert_eq!(waits.iter().sum::<u64>(), 60);
}

#[test]
fn the_budget_starts_again_when_a_line_commits() {
    let mut r = Rig::started();
    r.up_to_trace();
    r.feed(instrument_fault(FaultClass::Transient, "timeout", true));
    r.wait(Duration::from_secs(50));
    r.feed(Event::TimerFired);
    let a = r.line_ok();
    let s = last_status(&a).expect("status");
    assert_eq!(
        s.state,
        State::Scanning,
        "back to scanning once the line is on disk"
    );
    assert_eq!(s.reason, None);
    assert!(r
        .records()
        .iter()
        .any(|n| n.starts_with("line 1 on disk after 50 s of faults")));
    // Line 2: 50 s already went by, yet a fault now opens a fresh 60 s budget.
    r.up_to_trace();
    let a = r.feed(instrument_fault(FaultClass::Transient, "timeout", true));
    assert_eq!(reaction(&a), Reaction::RetryAfter(Duration::from_secs(1)));
    r.wait(Duration::from_secs(59));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    let a = r.feed(instrument_fault(FaultClass::Transient, "timeout", true));
    assert_eq!(reaction(&a), Reaction::RetryAfter(Duration::from_secs(1)));
    r.wait(Duration::from_secs(1));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    let a = r.feed(instrument_fault(FaultClass::Transient, "timeout", true));
    assert!(matches!(
        stop_of(&a),
        Some(End::Fail(FailReason::BudgetExhausted {
            line: 1,
            traces: 3,
            ..
        }))
    ));
}

/// A device unplugged for longer than the budget, after a transient fault on the same line:
/// the absence has no time limit, so the first transient fault after the reconnection is
/// retried with what was left of the budget, not taken as the budget spent.
#[test]
fn time_a_device_was_absent_is_not_spent_from_the_transient_budget() {
    let mut r = Rig::started();
    r.up_to_trace();
    let a = r.feed(instrument_fault(
        FaultClass::Transient,
        "NG007 over-range",
        false,
    ));
    assert_eq!(reaction(&a), Reaction::RetryAfter(Duration::from_secs(1)));
    r.wait(Duration::from_secs(1));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    // Unplugged mid-trace, back after two hours (the budget is 60 s).
    let a = r.feed(instrument_fault(FaultClass::Absent, "EOF", true));
    assert_eq!(reaction(&a), Reaction::Reopen(Device::Instrument));
    r.feed(instrument_fault(FaultClass::Absent, "no such port", false));
    r.wait(Duration::from_secs(7200));
    r.feed(Event::TimerFired);
    let a = r.feed(opened(Device::Instrument));
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    r.up_to_trace();
    let a = r.feed(instrument_fault(
        FaultClass::Transient,
        "NG007 over-range",
        false,
    ));
    assert!(stop_of(&a).is_none(), "the scan goes on: {a:?}");
    assert!(matches!(reaction(&a), Reaction::RetryAfter(_)), "{a:?}");
    let s = last_status(&a).expect("status");
    assert!(
        s.reason
            .as_deref()
            .is_some_and(|r| r.contains("budget left 59 s")),
        "{s:?}"
    );
}

#[test]
fn an_attempt_counts_only_when_a_trace_was_really_started() {
    let mut r = Rig::started();
    // Refused before it began (busy), then a fault outside the trace: no attempt.
    r.up_to_trace();
    r.feed(instrument_fault(FaultClass::Transient, "NG011", false));
    r.feed(Event::TimerFired);
    r.feed(instrument_fault(FaultClass::Transient, "not idle", false));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    let a = r.feed(Event::Traced(good_line()));
    assert_eq!(
        effect(&a),
        Some(&Action::Commit {
            line: 0,
            attempt: 1
        })
    );
    r.feed(Event::Committed);
    r.feed(Event::Pushed);
    // A trace that started and broke off counts.
    r.up_to_trace();
    r.feed(instrument_fault(FaultClass::Transient, "timeout", true));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    let a = r.feed(Event::Traced(good_line()));
    assert_eq!(
        effect(&a),
        Some(&Action::Commit {
            line: 1,
            attempt: 2
        })
    );
}

#[test]
fn a_vanished_device_is_reopened_with_backoff_and_costs_no_attempt() {
    let mut r = Rig::started();
    r.up_to_trace();
    let a = r.feed(instrument_fault(FaultClass::Absent, "EOF", true));
    assert_eq!(reaction(&a), Reaction::Reopen(Device::Instrument));
    let mut waits = Vec::new();
    for _ in 0..4 {
        let a = r.feed(instrument_fault(FaultClass::Absent, "no such port", false));
        let s = r.m.status();
        assert_eq!(s.state, State::Suspended);
        assert_eq!(s.instrument, DeviceState::Reconnecting);
        let Some(Action::SetTimer(d)) = effect(&a) else {
            panic!("{a:?}")
        };
        waits.push(d.as_secs());
        r.wait(*d);
        let a = r.feed(Event::TimerFired);
        assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)));
    }
    assert_eq!(waits, vec![1, 2, 4, 8]);
    let a = r.feed(opened(Device::Instrument));
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    let s = last_status(&a).expect("status");
    assert_eq!(
        (s.state, s.instrument),
        (State::Scanning, DeviceState::Connected)
    );
    assert!(r
        .records()
        .iter()
        .any(|n| n == "instrument back after 15 s; scan continues"));
    // One suspension was announced, not one per try.
    let notices = r
        .log
        .iter()
        .filter(|a| matches!(a, Action::Notify(ScanEventKind::Suspended, _)))
        .count();
    assert_eq!(notices, 1);
    // And its end once, with the reason the journal records.
    let resumed: Vec<&String> = r
        .log
        .iter()
        .filter_map(|a| match a {
            Action::Notify(ScanEventKind::Resumed, why) => Some(why),
            _ => None,
        })
        .collect();
    assert_eq!(resumed, ["instrument back after 15 s; scan continues"]);
    r.up_to_trace();
    let a = r.feed(Event::Traced(good_line()));
    assert_eq!(
        effect(&a),
        Some(&Action::Commit {
            line: 0,
            attempt: 1
        }),
        "a suspension uses up no attempt, not even the trace the unplug cut off"
    );
}

#[test]
fn a_different_instrument_after_a_reconnect_fails_the_scan() {
    let mut r = Rig::started();
    r.feed(instrument_fault(FaultClass::Absent, "EOF", false));
    let a = r.feed(instrument_fault(
        FaultClass::Fatal,
        "a different instrument answered",
        false,
    ));
    assert!(matches!(
        stop_of(&a),
        Some(End::Fail(FailReason::Fatal { line: Some(0), .. }))
    ));
}

#[test]
fn a_lost_position_rehomes_within_the_attempt_bound() {
    let mut r = Rig::started();
    let a = r.feed(Event::Idle);
    assert_eq!(effect(&a), Some(&Action::Move(plan().target(0))));
    for n in 1..3 {
        let a = r.feed(fault_event(
            Device::Stage,
            FaultClass::PositionLost,
            "reset",
            false,
        ));
        assert_eq!(reaction(&a), Reaction::Rehome, "loss {n}");
        // The drive is at rest before the stage homes; then the stage goes to the line.
        let a = r.feed(Event::Idle);
        assert_eq!(effect(&a), Some(&Action::Home), "loss {n}");
        let a = r.feed(Event::Homed);
        assert_eq!(effect(&a), Some(&Action::Move(plan().target(0))));
    }
    let a = r.feed(fault_event(
        Device::Stage,
        FaultClass::PositionLost,
        "reset",
        false,
    ));
    assert!(matches!(
        stop_of(&a),
        Some(End::Fail(FailReason::PositionLostRepeatedly {
            line: 0,
            times: 3,
            ..
        }))
    ));
}

#[test]
fn a_line_that_a_retrace_may_fix_is_retried_and_one_that_cannot_belong_fails() {
    let mut r = Rig::started();
    r.line_ok();
    r.up_to_trace();
    let short = TracedSummary {
        points: 99,
        ..good_line()
    };
    let a = r.feed(Event::Traced(short));
    assert_eq!(reaction(&a), Reaction::RetryAfter(Duration::from_secs(1)));
    r.feed(Event::TimerFired);
    r.up_to_trace();
    let other_pitch = TracedSummary {
        pitch_x_mm: 0.001,
        ..good_line()
    };
    let a = r.feed(Event::Traced(other_pitch));
    assert_eq!(
        stop_of(&a),
        Some(&End::Fail(FailReason::LineRefused {
            line: 1,
            problem: LineProblem::Pitch {
                pitch_x_mm: 0.001,
                scan: 0.0005
            }
        }))
    );
}

#[test]
fn changed_conditions_fail_the_scan_naming_what_changed() {
    let mut r = Rig::started();
    r.up_to_trace();
    let mut t = good_line();
    t.conditions.speed_mm_s = Some(0.25);
    let a = r.feed(Event::Traced(t));
    let Some(End::Fail(reason)) = stop_of(&a) else {
        panic!("{a:?}")
    };
    assert!(
        reason
            .to_string()
            .contains("speed mm/s was unknown at the start of the scan, now 0.25"),
        "{reason}"
    );
}

#[test]
fn a_full_disk_suspends_checks_space_with_backoff_and_commits_the_held_line() {
    let mut r = Rig::started();
    r.line_ok();
    r.up_to_trace();
    r.feed(Event::Traced(good_line()));
    let a = r.feed(Event::StorageFailed(StorageFailure::full(
        "write lines/0001.csv: No space left on device".into(),
    )));
    assert_eq!(stop_of(&a), None, "a full disk never ends the scan");
    let s = last_status(&a).expect("status");
    assert_eq!(s.state, State::Suspended);
    let need = remaining_scan_bytes(LINES, 1, 100);
    assert!(
        s.reason
            .as_deref()
            .unwrap_or_default()
            .contains(&format!("the remaining lines need about {} MB", mb(need))),
        "{:?}",
        s.reason
    );
    assert_eq!(effect(&a), Some(&Action::SetTimer(Duration::from_secs(1))));
    let a = r.feed(Event::TimerFired);
    assert_eq!(effect(&a), Some(&Action::CheckSpace));
    // Still too little: the next check waits longer.
    let a = r.feed(Event::SpaceChecked {
        free_bytes: need - 1,
        free_inodes: u64::MAX,
        outputs_bytes: 0,
    });
    assert_eq!(effect(&a), Some(&Action::SetTimer(Duration::from_secs(2))));
    r.feed(Event::TimerFired);
    let a = r.feed(Event::SpaceChecked {
        free_bytes: need,
        free_inodes: u64::MAX,
        outputs_bytes: 0,
    });
    assert_eq!(
        effect(&a),
        Some(&Action::Commit {
            line: 1,
            attempt: 1
        }),
        "the traced line is committed, not traced again"
    );
    r.feed(Event::Committed);
    let a = r.feed(Event::Pushed);
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    assert!(!r.log.iter().any(|a| matches!(a, Action::Stop(_))));
}

#[test]
fn a_full_disk_while_writing_the_outputs_waits_and_writes_them_again() {
    let mut r = Rig::started();
    for _ in 0..LINES {
        r.line_ok();
    }
    let a = r.feed(Event::StorageFailed(StorageFailure::full(
        "surface.igs: No space left on device".into(),
    )));
    assert_eq!(stop_of(&a), None);
    r.feed(Event::TimerFired);
    let a = r.feed(Event::SpaceChecked {
        free_bytes: u64::MAX,
        free_inodes: u64::MAX,
        outputs_bytes: 0,
    });
    assert_eq!(effect(&a), Some(&Action::WriteOutputs));
}

/// The outputs' estimate is the whole surface and report; an earlier try that filled the
/// disk already wrote part of them, and that space is theirs again when they are written
/// anew. Otherwise a disk that held the scan at its start could never hold enough again.
#[test]
fn the_space_an_earlier_try_at_the_outputs_took_counts_as_theirs() {
    let mut r = Rig::started();
    for _ in 0..LINES {
        r.line_ok();
    }
    r.feed(Event::StorageFailed(StorageFailure::full(
        "report.json: No space left on device".into(),
    )));
    let need = remaining_scan_bytes(LINES, LINES, 100);
    r.feed(Event::TimerFired);
    let a = r.feed(Event::SpaceChecked {
        free_bytes: need / 4,
        free_inodes: u64::MAX,
        outputs_bytes: need / 2,
    });
    assert!(
        matches!(effect(&a), Some(Action::SetTimer(_))),
        "still too little: {a:?}"
    );
    r.feed(Event::TimerFired);
    let a = r.feed(Event::SpaceChecked {
        free_bytes: need / 2,
        free_inodes: u64::MAX,
        outputs_bytes: need / 2,
    });
    assert_eq!(effect(&a), Some(&Action::WriteOutputs));
}

/// While lines are still to be traced there are no outputs to count.
#[test]
fn a_line_held_for_space_waits_for_the_free_space_alone() {
    let mut r = Rig::started();
    r.up_to_trace();
    r.feed(Event::Traced(good_line()));
    r.feed(Event::StorageFailed(StorageFailure::full(
        "write lines/0000.csv: No space left on device".into(),
    )));
    let need = remaining_scan_bytes(LINES, 0, 100);
    r.feed(Event::TimerFired);
    let a = r.feed(Event::SpaceChecked {
        free_bytes: need - 1,
        free_inodes: u64::MAX,
        outputs_bytes: need,
    });
    assert!(matches!(effect(&a), Some(Action::SetTimer(_))), "{a:?}");
}

/// A file system that refuses for another reason than space (read-only, an immutable
/// directory, a permission, an I/O error) suspends the scan like a full disk: the traced line
/// is kept in memory and written again with a growing backoff; one suspension is recorded
/// however often the write fails, and the scan goes on when it succeeds.
#[test]
fn a_refused_write_suspends_and_the_held_line_is_written_again_with_backoff() {
    let mut r = Rig::started();
    r.up_to_trace();
    r.feed(Event::Traced(good_line()));
    let refused = || {
        Event::StorageFailed(StorageFailure {
            class: Some(StorageClass::Refused),
            errno: Some(libc::EROFS),
            message: "write /out/S/lines/.0000.csv.tmp: Read-only file system (os error 30)".into(),
        })
    };
    let a = r.feed(refused());
    assert_eq!(stop_of(&a), None, "a storage error never ends the scan");
    let s = last_status(&a).expect("status");
    assert_eq!(s.state, State::Suspended);
    let reason = s.reason.clone().unwrap_or_default();
    assert!(
        reason.starts_with("the file system refused writing line 1 (EROFS: write /out/S/lines/")
            && reason.contains("remount"),
        "{reason}"
    );
    let mut waits = Vec::new();
    for _ in 0..5 {
        let d = last_timer(&r);
        waits.push(d);
        r.wait(d);
        let a = r.feed(Event::TimerFired);
        assert_eq!(
            effect(&a),
            Some(&Action::Commit {
                line: 0,
                attempt: 1
            }),
            "the held line is written again, not traced again"
        );
        r.feed(refused());
    }
    assert_eq!(waits, [1, 2, 4, 8, 8].map(Duration::from_secs));
    let suspended: Vec<String> = r
        .records()
        .into_iter()
        .filter(|n| n.starts_with("suspended:"))
        .collect();
    assert_eq!(suspended.len(), 1, "one suspension recorded: {suspended:?}");
    let d = last_timer(&r);
    r.wait(d);
    r.feed(Event::TimerFired);
    let a = r.feed(Event::Committed);
    assert!(
        a.iter().any(|a| matches!(a, Action::Record(n)
            if n.reason.starts_with("the output directory takes writes again after"))),
        "{a:?}"
    );
    assert_eq!(effect(&a), Some(&Action::Push { line: 0 }));
    let a = r.feed(Event::Pushed);
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    assert!(!r.log.iter().any(|a| matches!(a, Action::Stop(_))));
}

/// Out of inodes (the disk has bytes but no file can be made): the space check looks at
/// the free inodes too, so it keeps waiting instead of flapping; and when the first write
/// after the check fails again, the backoff is kept and nothing new is recorded.
#[test]
fn out_of_inodes_waits_without_flapping() {
    let mut r = Rig::started();
    r.up_to_trace();
    r.feed(Event::Traced(good_line()));
    r.feed(Event::StorageFailed(StorageFailure::full(
        "write lines/.0000.csv.tmp: No space left on device".into(),
    )));
    r.wait(Duration::from_secs(1));
    let a = r.feed(Event::TimerFired);
    assert_eq!(effect(&a), Some(&Action::CheckSpace));
    let a = r.feed(Event::SpaceChecked {
        free_bytes: u64::MAX,
        free_inodes: 3,
        outputs_bytes: 0,
    });
    assert_eq!(effect(&a), Some(&Action::SetTimer(Duration::from_secs(2))));
    let reason = r.m.status().reason.clone().unwrap_or_default();
    assert!(reason.contains("3 inodes (files) free"), "{reason}");
    r.wait(Duration::from_secs(2));
    r.feed(Event::TimerFired);
    // Inodes enough by the count, but the write fails again (a quota, a race): same
    // suspension, a longer wait.
    let a = r.feed(Event::SpaceChecked {
        free_bytes: u64::MAX,
        free_inodes: u64::MAX,
        outputs_bytes: 0,
    });
    assert!(
        matches!(effect(&a), Some(Action::Commit { line: 0, .. })),
        "{a:?}"
    );
    let a = r.feed(Event::StorageFailed(StorageFailure::full(
        "write lines/.0000.csv.tmp: Disk quota exceeded".into(),
    )));
    assert_eq!(effect(&a), Some(&Action::SetTimer(Duration::from_secs(4))));
    let notes = r.records();
    assert_eq!(
        notes.iter().filter(|n| n.starts_with("suspended:")).count(),
        1,
        "{notes:?}"
    );
    assert!(
        !notes.iter().any(|n| n.starts_with("space is back")),
        "{notes:?}"
    );
}

#[test]
fn a_scan_with_every_line_committed_writes_its_outputs_without_opening_devices() {
    let m = resumed_scan(LINES, &[], false);
    let mut r = Rig::with(m);
    let a = r.start();
    assert_eq!(effect(&a), Some(&Action::WriteOutputs));
    assert!(!a.iter().any(|a| matches!(a, Action::Open(_))));
}

/// A scan the operator paused, reopened after a restart: it stays paused, with no device
/// opened and nothing moved, until the operator resumes it; then it goes on at its first
/// missing line and the resumption is marked in the journal.
#[test]
fn a_scan_paused_when_its_process_stopped_is_reopened_paused() {
    let m = resumed_scan(2, &[], true);
    let mut r = Rig::with(resumed_scan(2, &[], true));
    r.start();
    // A shutdown while paused abandons no line, and says the pause stands.
    let a = r.feed(Event::Shutdown);
    let notes: Vec<&Note> = a
        .iter()
        .filter_map(|a| match a {
            Action::Record(n) => Some(n),
            _ => None,
        })
        .collect();
    assert_eq!(notes.len(), 1, "{a:?}");
    assert_eq!(notes[0].line, None);
    assert!(
        notes[0].reason.contains("while paused with 2 of")
            && notes[0].reason.contains("reopens it paused")
            && !notes[0].reason.contains("abandoned"),
        "{}",
        notes[0].reason
    );

    let mut r = Rig::with(m);
    let a = r.start();
    assert_eq!(effect(&a), None, "nothing is done while paused: {a:?}");
    assert!(!a.iter().any(|a| matches!(a, Action::Open(_))), "{a:?}");
    let s = last_status(&a).expect("status");
    assert_eq!(s.state, State::Paused);
    assert!(s
        .reason
        .as_deref()
        .is_some_and(|r| r.contains("surfscan resume")));
    let a = r.feed(Event::Command {
        command: OperatorCommand::Resume,
        peer: peer(),
    });
    assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)), "{a:?}");
    assert!(
        a.iter().any(|a| matches!(
            a,
            Action::Record(Note { pause: Some(PauseMark::Resumed), reason, .. })
                if reason.starts_with("resumed by the operator")
        )),
        "{a:?}"
    );
}

/// A start asked for while a scan is paused (the way the README tells an operator to go on
/// after a restart) resumes it; a start of a new scan is refused with what to do instead.
#[test]
fn a_start_while_paused_resumes_the_scan_and_a_new_one_is_refused_with_guidance() {
    let start = |mode: StartMode| Event::Command {
        command: OperatorCommand::Start {
            specimen: String::new(),
            operator: String::new(),
            notes: String::new(),
            mode,
            recipe: None,
        },
        peer: peer(),
    };
    let mut r = Rig::with(resumed_scan(2, &[], true));
    r.start();
    let a = r.feed(start(StartMode::New));
    assert_eq!(effect(&a), None, "a refused start moves nothing: {a:?}");
    match a.iter().find(|a| matches!(a, Action::Reply(_))) {
        Some(Action::Reply(Err(m))) => assert!(
            m.contains("is paused") && m.contains("surfscan resume") && m.contains("abort"),
            "{m}"
        ),
        other => panic!("{other:?}"),
    }
    for mode in [StartMode::Auto, StartMode::Resume] {
        let mut r = Rig::with(resumed_scan(2, &[], true));
        r.start();
        let a = r.feed(start(mode));
        assert!(
            matches!(a.iter().find(|a| matches!(a, Action::Reply(_))),
                Some(Action::Reply(Ok(m))) if m.contains("this start resumes it")),
            "{mode:?}: {a:?}"
        );
        assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)), "{a:?}");
        assert!(
            a.iter().any(|a| matches!(
                a,
                Action::Record(Note { pause: Some(PauseMark::Resumed), reason, .. })
                    if reason.starts_with("resumed by the operator's start")
            )),
            "{a:?}"
        );
        // Counted as a start, so `surfscan start` sees its outcome.
        let s = last_status(&a).expect("status");
        assert_eq!((s.starts, s.state), (1, State::Scanning), "{a:?}");
    }
}

#[test]
fn a_resumed_scan_reopens_its_devices_and_goes_on_at_its_first_missing_line() {
    let m = resumed_scan(2, &[], false);
    let mut r = Rig::with(m);
    let a = r.start();
    assert_eq!(effect(&a), Some(&Action::Open(Device::Instrument)));
    // Not there yet: a resumed scan waits for it like a suspended one.
    let a = r.feed(instrument_fault(FaultClass::Absent, "no port", false));
    assert_eq!(stop_of(&a), None);
    r.feed(Event::TimerFired);
    r.feed(opened(Device::Instrument));
    let a = r.feed(opened(Device::Stage));
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    let a = r.feed(Event::Idle);
    assert_eq!(effect(&a), Some(&Action::Move(plan().target(2))));
}

#[test]
fn pause_waits_for_the_line_on_disk_and_resume_goes_on() {
    let mut r = Rig::started();
    r.up_to_trace();
    let a = r.feed(Event::Command {
        command: OperatorCommand::Pause,
        peer: peer(),
    });
    assert!(!a.contains(&Action::Cancel), "the trace goes on");
    assert_eq!(
        a.first(),
        Some(&Action::Reply(Ok(
            "scan S pauses once the current line is on disk".into()
        )))
    );
    assert_eq!(last_status(&a).map(|s| s.state), Some(State::Pausing));
    r.feed(Event::Traced(good_line()));
    r.feed(Event::Committed);
    let a = r.feed(Event::Pushed);
    assert_eq!(effect(&a), None, "paused: nothing in flight");
    assert_eq!(last_status(&a).map(|s| s.state), Some(State::Paused));
    // The journal marks the pause, so that a restart reopens the scan paused.
    assert!(
        a.iter().any(|a| matches!(
            a,
            Action::Record(Note {
                pause: Some(PauseMark::Paused),
                ..
            })
        )),
        "{a:?}"
    );
    let a = r.feed(Event::Command {
        command: OperatorCommand::Pause,
        peer: peer(),
    });
    assert_eq!(
        a,
        vec![Action::Reply(Ok("scan S is already paused".into()))]
    );
    let a = r.feed(Event::Command {
        command: OperatorCommand::Resume,
        peer: peer(),
    });
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    let notes: Vec<&Note> = r
        .log
        .iter()
        .filter_map(|a| match a {
            Action::Record(n) if n.peer.is_some() => Some(n),
            _ => None,
        })
        .collect();
    assert_eq!(notes.len(), 2, "pause and resume, each with who asked");
    assert_eq!(
        notes[0].reason,
        "pause requested by uid 1000 gid 100 pid 4242"
    );
    assert!(notes[1].reason.starts_with("resumed by the operator"));
}

/// A pause asked for while the scan is being started (devices opening, no directory yet) is
/// shown as pausing once the scan exists, not as scanning, and takes effect after line 1.
#[test]
fn a_pause_asked_for_during_start_up_shows_as_pausing_until_it_takes_effect() {
    let mut r = Rig::fresh();
    r.start();
    let a = r.feed(Event::Command {
        command: OperatorCommand::Pause,
        peer: peer(),
    });
    assert!(
        a.iter()
            .any(|a| matches!(a, Action::Reply(Ok(m)) if m.contains("pauses once"))),
        "{a:?}"
    );
    r.feed(opened(Device::Instrument));
    r.feed(opened(Device::Stage));
    let a = r.feed(Event::Created {
        scan_id: "S".into(),
        dir: "/out/S".into(),
        conditions: Conditions::default(),
        points_per_line: 100,
    });
    assert_eq!(effect(&a), Some(&Action::EnsureIdle));
    assert_eq!(last_status(&a).map(|s| s.state), Some(State::Pausing));
    r.line_ok();
    assert_eq!(r.m.status().state, State::Paused);
}

#[test]
fn abort_cancels_the_trace_cleans_up_and_records_abort() {
    let mut r = Rig::started();
    r.line_ok();
    r.up_to_trace();
    let a = r.feed(Event::Command {
        command: OperatorCommand::Abort,
        peer: peer(),
    });
    assert!(a.contains(&Action::Cancel));
    assert_eq!(effect(&a), Some(&Action::Cleanup));
    // A late answer of the cancelled trace changes nothing.
    assert!(r.feed(Event::Traced(good_line())).is_empty());
    let a = r.feed(Event::CleanedUp);
    assert_eq!(stop_of(&a), Some(&End::Abort { peer: Some(peer()) }));
    assert_eq!(
        last_status(&a)
            .and_then(|s| s.last_stop.as_ref())
            .map(|l| l.status),
        Some(StopStatus::Abort)
    );
}

#[test]
fn shutdown_abandons_the_line_and_leaves_the_scan_resumable() {
    let mut r = Rig::started();
    r.line_ok();
    r.feed(Event::Idle);
    let a = r.feed(Event::Shutdown);
    assert!(a.contains(&Action::Cancel));
    assert_eq!(effect(&a), Some(&Action::Cleanup));
    let a = r.feed(Event::CleanedUp);
    assert_eq!(stop_of(&a), Some(&End::Shutdown));
    assert_eq!(last_status(&a).map(|s| s.state), Some(State::Stopping));
    let n = a
        .iter()
        .find_map(|a| match a {
            Action::Record(n) => Some(n),
            _ => None,
        })
        .expect("an interruption");
    assert_eq!(n.line, Some(1));
    assert!(n.reason.starts_with("shutdown"));
}

#[test]
fn a_device_missing_at_the_start_of_a_new_scan_is_unavailable_not_a_suspension() {
    let mut r = Rig::fresh();
    r.start();
    let a = r.feed(instrument_fault(FaultClass::Absent, "no such port", false));
    let Some(End::Fail(reason)) = stop_of(&a) else {
        panic!("{a:?}")
    };
    assert_eq!(reason.kind(), FailKind::Unavailable);
    assert!(
        !a.iter().any(|a| matches!(a, Action::Notify(..))),
        "no scan exists to notify about"
    );
}

#[test]
fn commands_answer_while_running_and_start_is_refused() {
    let mut r = Rig::started();
    let a = r.feed(Event::Command {
        command: OperatorCommand::Start {
            specimen: String::new(),
            operator: String::new(),
            notes: String::new(),
            mode: StartMode::Auto,
            recipe: None,
        },
        peer: peer(),
    });
    assert_eq!(
        a,
        vec![Action::Reply(Err(
            "scan S is running; abort it first or wait until it ends".into()
        ))]
    );
    let a = r.feed(Event::Command {
        command: OperatorCommand::Resume,
        peer: peer(),
    });
    assert_eq!(
        a,
        vec![Action::Reply(Ok(
            "scan S is not paused; it goes on scanning".into()
        ))]
    );
}

#[test]
fn a_line_moved_aside_at_resume_is_traced_again_and_the_lines_committed_after_it_are_not() {
    // Line 0 moved aside, line 1 committed after it, line 2 never traced.
    let mut r = Rig::with(resumed_scan(0, &[1], false));
    r.start();
    r.feed(opened(Device::Instrument));
    r.feed(opened(Device::Stage));
    let a = r.feed(Event::Idle);
    assert_eq!(effect(&a), Some(&Action::Move(plan().target(0))));
    assert_eq!(last_status(&r.log).map(|s| s.lines_done), Some(1));
    r.feed(Event::Arrived);
    r.feed(Event::Traced(good_line()));
    let a = r.feed(Event::Committed);
    assert_eq!(effect(&a), Some(&Action::Push { line: 0 }));
    r.feed(Event::Pushed);
    let a = r.feed(Event::Idle);
    assert_eq!(
        effect(&a),
        Some(&Action::Move(plan().target(2))),
        "line 1 is not traced again"
    );
    assert_eq!(last_status(&r.log).map(|s| s.lines_done), Some(2));

    // Line 1 moved aside, line 2 committed after it: once line 1 is back, the outputs.
    let mut r = Rig::with(resumed_scan(1, &[2], false));
    r.start();
    r.feed(opened(Device::Instrument));
    r.feed(opened(Device::Stage));
    let a = r.feed(Event::Idle);
    assert_eq!(effect(&a), Some(&Action::Move(plan().target(1))));
    r.feed(Event::Arrived);
    r.feed(Event::Traced(good_line()));
    r.feed(Event::Committed);
    let a = r.feed(Event::Pushed);
    assert_eq!(effect(&a), Some(&Action::WriteOutputs));
}

#[test]
fn a_new_scan_the_instrument_is_not_set_for_fails_before_its_directory_exists() {
    let mut r = Rig::fresh();
    r.start();
    r.feed(opened(Device::Instrument));
    let a = r.feed(opened(Device::Stage));
    assert_eq!(effect(&a), Some(&Action::CreateScan));
    let why = "the instrument is not set as recipe brass expects: λc: the recipe expects 0.8 mm, the instrument is set to 2.5 mm";
    let a = r.feed(Event::CreateRefused(why.into()));
    let Some(End::Fail(reason)) = stop_of(&a) else {
        panic!("{a:?}")
    };
    assert_eq!(reason.to_string(), why);
    assert!(r.m.ended());
    // No scan was created: nothing is recorded in a journal, no line is traced.
    assert!(r.records().is_empty(), "{:?}", r.records());
    assert!(!r
        .log
        .iter()
        .any(|a| matches!(a, Action::Trace | Action::Commit { .. })));
    let s = last_status(&a).expect("the end is published");
    let stop = s.last_stop.as_ref().expect("last stop");
    assert!(stop.reason.contains("λc"), "{stop:?}");
}

/// A line retried within the budget is labelled by what went wrong: "busy" only when the
/// device said so (NG011), never for a wrong answer or no answer in time.
#[test]
fn a_retried_line_names_busy_only_for_a_busy_device() {
    for (ng_code, label) in [
        (Some(11), "instrument busy since"),
        (Some(33), "instrument busy since"),
        (None, "instrument answering wrongly or not in time since"),
        (
            Some(12),
            "instrument answering wrongly or not in time since",
        ),
    ] {
        let mut r = Rig::started();
        r.up_to_trace();
        let a = r.feed(Event::Fault {
            fault: Fault {
                ng_code,
                ..fault(Device::Instrument, FaultClass::Transient, "refused")
            },
            trace_started: false,
        });
        let reason = last_status(&a)
            .and_then(|s| s.reason.clone())
            .unwrap_or_default();
        assert!(reason.starts_with(label), "{ng_code:?}: {reason}");
    }
}
