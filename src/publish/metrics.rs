//! The station's metrics on `/metrics` (`[metrics] listen`), for a Prometheus server to
//! scrape: the scan's numbers as the textfile has them ([`ScanMetrics::render`]) and the
//! station's own (state, devices, links, scans started), in the text exposition format 0.0.4.
//!
//! Why the text is written by this crate and not by `prometheus-client`: that crate encodes
//! OpenMetrics only (a counter's samples carry `_total` under a `# TYPE` without it, and the
//! text ends in `# EOF`), which node_exporter's textfile collector reads as a different
//! metric and which `promtool check metrics` (Prometheus 2.42, Debian 12) rejects ("no help
//! text" for every counter). The textfile and the endpoint must be the same text, and both
//! must pass promtool, so the format is the 0.0.4 one, written by [`crate::scan::metrics`].
//! The HTTP side is axum's router on the station page's listener ([`crate::web::server`]:
//! at most a few connections, a deadline for a request's headers and for a stalled
//! connection), so no client can hold a connection open for ever.
//!
//! Layer 4 (process edge): depends on axum, tokio, the page's listener and the scan's status
//! and metrics types.

use crate::scan::metrics::{family, ScanMetrics};
use crate::scan::status::{DeviceState, State, Status};
use axum::extract::State as Extract;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;
use axum::Router;
use tokio::sync::watch;

/// The content type of the text exposition format.
pub const CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

const STATES: [(State, &str); 8] = [
    (State::Idle, "idle"),
    (State::Starting, "starting"),
    (State::Scanning, "scanning"),
    (State::Pausing, "pausing"),
    (State::Paused, "paused"),
    (State::Suspended, "suspended"),
    (State::Finishing, "finishing"),
    (State::Stopping, "stopping"),
];

const DEVICE_STATES: [(DeviceState, &str); 4] = [
    (DeviceState::Absent, "absent"),
    (DeviceState::Present, "present"),
    (DeviceState::Connected, "connected"),
    (DeviceState::Reconnecting, "reconnecting"),
];

/// The station's own families, from its status.
pub fn station_text(s: &Status) -> String {
    let mut out = String::new();
    let states: Vec<(String, f64)> = STATES
        .iter()
        .map(|(st, name)| {
            (
                format!("state=\"{name}\""),
                f64::from(u8::from(s.state == *st)),
            )
        })
        .collect();
    family(
        &mut out,
        "surfscan_state",
        "gauge",
        "1 for the state the station is in (idle, scanning, suspended, ...), 0 for the others.",
        &states,
    );
    let mut devices = Vec::new();
    for (device, d) in [("instrument", s.instrument), ("stage", s.stage)] {
        for (st, name) in DEVICE_STATES {
            devices.push((
                format!("device=\"{device}\",state=\"{name}\""),
                f64::from(u8::from(d == st)),
            ));
        }
    }
    family(
        &mut out,
        "surfscan_device_state",
        "gauge",
        "1 for the state each device is in, 0 for the others.",
        &devices,
    );
    if !s.links.is_empty() {
        let up: Vec<(String, f64)> = s
            .links
            .iter()
            .map(|(n, l)| (format!("link=\"{n}\""), f64::from(u8::from(l.ok))))
            .collect();
        family(
            &mut out,
            "surfscan_link_up",
            "gauge",
            "1 when the link to the lab's system (mqtt, ...) is connected and delivering.",
            &up,
        );
        let queued: Vec<(String, f64)> = s
            .links
            .iter()
            .map(|(n, l)| (format!("link=\"{n}\""), l.queued as f64))
            .collect();
        family(
            &mut out,
            "surfscan_link_queued_messages",
            "gauge",
            "Messages waiting on disk for the link.",
            &queued,
        );
    }
    family(
        &mut out,
        "surfscan_scans_started_total",
        "counter",
        "Scans this process has begun (resumptions included).",
        &[(String::new(), s.starts as f64)],
    );
    out
}

/// Everything `/metrics` serves: the scan's families, then the station's.
pub fn exposition(status: &Status, scan: &ScanMetrics) -> String {
    let mut text = scan.render();
    text.push_str(&station_text(status));
    text
}

#[derive(Clone)]
struct Sources {
    status: watch::Receiver<Status>,
    scan: watch::Receiver<ScanMetrics>,
}

async fn metrics(Extract(src): Extract<Sources>) -> impl IntoResponse {
    let text = exposition(&src.status.borrow(), &src.scan.borrow());
    ([(header::CONTENT_TYPE, CONTENT_TYPE)], text)
}

/// Connections served at once; a scraper needs one, a few people looking a few more.
const MAX_CONNECTIONS: usize = 16;

/// Serves `/metrics` on `listener` until `shutdown` becomes true, under the station page's
/// connection bound and deadlines ([`crate::web::server`]): a client that sends no request,
/// or drips its headers, is closed after `HEADER_TIMEOUT`.
pub async fn serve(
    listener: tokio::net::TcpListener,
    status: watch::Receiver<Status>,
    scan: watch::Receiver<ScanMetrics>,
    shutdown: watch::Receiver<bool>,
) {
    let app = Router::new()
        .route("/metrics", get(metrics))
        .with_state(Sources { status, scan });
    crate::web::server::serve(listener, None, app, MAX_CONNECTIONS, shutdown).await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_station_families_name_the_state_the_devices_and_the_links() {
        let mut s = Status::idle();
        s.state = State::Suspended;
        s.instrument = DeviceState::Reconnecting;
        s.starts = 3;
        s.links.insert(
            "mqtt".into(),
            crate::scan::status::LinkStatus {
                ok: false,
                message: "down".into(),
                queued: 4,
            },
        );
        let t = station_text(&s);
        assert!(t.contains("surfscan_state{state=\"suspended\"} 1\n"), "{t}");
        assert!(t.contains("surfscan_state{state=\"idle\"} 0\n"), "{t}");
        assert!(
            t.contains("surfscan_device_state{device=\"instrument\",state=\"reconnecting\"} 1\n")
        );
        assert!(t.contains("surfscan_link_up{link=\"mqtt\"} 0\n"));
        assert!(t.contains("surfscan_link_queued_messages{link=\"mqtt\"} 4\n"));
        assert!(t.contains("surfscan_scans_started_total 3\n"), "{t}");
    }
}
