//! The page's routes: the HTTP JSON API mirroring the control socket, the page's live stream,
//! the history and the scans' files, signing in and out, the page itself and `/healthz`.
//!
//! | Route | Who | What |
//! |---|---|---|
//! | `GET /healthz` | anyone | `ok`: the daemon is up (nothing else) |
//! | `GET /`, `/app.js`, `/app.css` | anyone | the page (no station data: it signs in, then asks the API) |
//! | `POST /login` | anyone with a token | `{"token": …}` → the session cookie and the CSRF token |
//! | `POST /logout` | a session | ends the session |
//! | `GET /api/session` | signed in | the user, role and (for a session) the CSRF token |
//! | `GET /api/live` | signed in | the page's stream (server-sent events, [`super::live`]) |
//! | `GET /api/watch` | signed in | the socket's `watch`: a `status` event per change |
//! | `GET /api/scans` | signed in | the history (`?limit=N`, default 200) |
//! | `GET /scans/ID/FILE` | signed in | a file of a scan |
//! | `GET /api/CLASS` | signed in | a request that changes nothing (`status`, …) |
//! | `POST /api/CLASS` | an operating user | any request of the socket, its members as the JSON body |
//!
//! `POST /api/CLASS` is the socket's request `{"class": CLASS, …body}`, parsed by the socket's
//! own parser (so unknown members, repeated members and unknown classes are refused just the
//! same) and carried out by the socket's own dispatcher ([`crate::control::dispatch`]); the
//! answer is the socket's message, with status 200 (`ack`, `status`, …), 400 (malformed), 401
//! (no valid token or session), 403 (not allowed, or a forged cross-site request) or 409 (the
//! daemon refused or could not carry it out). A request the socket grows is served here without
//! a change.
//!
//! Layer 4 (process edge): depends on [`crate::control`] (parser, dispatcher, channels),
//! [`super::auth`], [`super::live`], [`super::history`] and axum.

use super::auth::{self, Provenance, Role, Sessions, User, Users};
use super::history;
use super::live::{Cursor, View, MIN_INTERVAL};
use super::page;
use super::server::ClientAddr;
use crate::control::dispatch::dispatch;
use crate::control::protocol::{ControlChannels, Message};
use crate::control::server::parse_request;
use crate::scan::command::Peer;
use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, Path, Query, State};
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Extension, Router};
use serde_json::json;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// How often a stream sends a comment when nothing else moves.
pub const KEEP_ALIVE: Duration = Duration::from_secs(15);

/// Longest request body, bytes.
pub const MAX_BODY: usize = 64 * 1024;

/// Default number of scans of the history.
const HISTORY_LIMIT: usize = 200;

/// What the routes share.
pub struct App {
    /// The users of the token file.
    pub users: Users,
    /// The signed-out sessions, and the random source of new ones.
    pub sessions: Sessions,
    /// The runner's status and command channel.
    pub channels: ControlChannels,
    /// The live view.
    pub view: watch::Receiver<Arc<View>>,
    /// The output directory.
    pub out: PathBuf,
    /// Whether the page is served over HTTPS (the cookie is then `Secure`).
    pub tls: bool,
    /// How long a session lasts, hours.
    pub session_hours: u32,
    /// How long a command waits for the runner.
    pub reply_timeout: Duration,
    /// One history refresh at a time; the last answer and when it was made.
    pub history: tokio::sync::Mutex<Option<(tokio::time::Instant, usize, Arc<str>)>>,
}

/// The router of every route.
pub fn router(app: Arc<App>) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/", get(|| async { page::index() }))
        .route("/app.js", get(|| async { page::script() }))
        .route("/app.css", get(|| async { page::style() }))
        .route("/login", post(login))
        .route("/logout", post(logout))
        .route("/api/session", get(session))
        .route("/api/live", get(live))
        .route("/api/watch", get(watch_status))
        .route("/api/scans", get(scans))
        .route("/api/{class}", get(api_get).post(api_post))
        .route("/scans/{scan}/{file}", get(scan_file))
        .fallback(|| async {
            answer(
                StatusCode::NOT_FOUND,
                &error(
                    "no such page or request; the API is under /api/ (see the integration guide)",
                ),
            )
        })
        .layer(DefaultBodyLimit::max(MAX_BODY))
        .layer(axum::middleware::map_response(secure))
        .with_state(app)
}

/// Headers every answer carries.
async fn secure(mut r: Response) -> Response {
    let h = r.headers_mut();
    h.insert(
        "x-content-type-options",
        HeaderValue::from_static("nosniff"),
    );
    h.insert("x-frame-options", HeaderValue::from_static("DENY"));
    h.insert("referrer-policy", HeaderValue::from_static("no-referrer"));
    h.entry(header::CACHE_CONTROL)
        .or_insert(HeaderValue::from_static("no-store"));
    h.entry("content-security-policy").or_insert(HeaderValue::from_static(
        "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'; form-action 'self'; base-uri 'none'",
    ));
    r
}

fn error(message: &str) -> Message {
    Message::Error {
        message: message.to_owned(),
    }
}

/// A message as a JSON answer.
fn answer(status: StatusCode, m: &Message) -> Response {
    let body = serde_json::to_string(m).unwrap_or_else(|_| "{}".into());
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

/// The status an answer of the socket gets: refusals 409, everything else 200.
fn status_of(m: &Message) -> StatusCode {
    let v = serde_json::to_value(m).unwrap_or_default();
    match v.get("class").and_then(|c| c.as_str()) {
        Some("error") | Some("refused") => StatusCode::CONFLICT,
        _ => StatusCode::OK,
    }
}

async fn healthz() -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        "ok\n",
    )
        .into_response()
}

/// Who is asking, as authenticated.
struct Caller {
    user: User,
    address: std::net::SocketAddr,
    /// The session, when signed in by cookie (a bearer token has none).
    session: Option<auth::Session>,
}

fn now_s() -> i64 {
    chrono::Utc::now().timestamp()
}

fn header_str(h: &HeaderMap, name: impl header::AsHeaderName) -> Option<&str> {
    h.get(name).and_then(|v| v.to_str().ok())
}

fn unauthorised(app: &App, addr: std::net::SocketAddr, what: &str, why: &str) -> Response {
    tracing::warn!("web: {what} from {addr} refused: {why}");
    let mut r = answer(
        StatusCode::UNAUTHORIZED,
        &error(&format!(
            "{why}: send `Authorization: Bearer TOKEN` with a token of [web] token-file, or sign in on the page"
        )),
    );
    r.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        HeaderValue::from_static("Bearer realm=\"surfscan\""),
    );
    let _ = app;
    r
}

/// The caller of a request: a bearer token (taken first) or a session cookie.
fn authenticate(
    app: &App,
    h: &HeaderMap,
    addr: std::net::SocketAddr,
    what: &str,
) -> Result<Caller, Response> {
    if let Some(v) = header_str(h, header::AUTHORIZATION) {
        return match auth::bearer(v).and_then(|t| app.users.by_token(t)) {
            Some(u) => Ok(Caller {
                user: u.clone(),
                address: addr,
                session: None,
            }),
            None => Err(unauthorised(
                app,
                addr,
                what,
                "the bearer token is not one of [web] token-file",
            )),
        };
    }
    let cookie = h
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .find_map(|v| auth::cookie_value(v, auth::COOKIE));
    match cookie.and_then(|c| app.sessions.check(&app.users, c, now_s())) {
        Some((u, s)) => Ok(Caller {
            user: u.clone(),
            address: addr,
            session: Some(s),
        }),
        None if cookie.is_some() => Err(unauthorised(
            app,
            addr,
            what,
            "the session has ended (signed out, expired, or its token changed)",
        )),
        None => Err(unauthorised(app, addr, what, "not signed in")),
    }
}

fn provenance<'a>(app: &App, h: &'a HeaderMap) -> Provenance<'a> {
    Provenance {
        origin: header_str(h, header::ORIGIN),
        fetch_site: header_str(h, "sec-fetch-site"),
        host: header_str(h, header::HOST),
        tls: app.tls,
    }
}

/// The CSRF check of a request that changes something: none for a bearer token; the
/// session's token and this server's origin for a session.
fn csrf(app: &App, h: &HeaderMap, caller: &Caller, what: &str) -> Result<(), Response> {
    let Some(session) = &caller.session else {
        return Ok(());
    };
    let expected = app.sessions.csrf_token(&caller.user, session);
    auth::csrf_check(
        &provenance(app, h),
        header_str(h, auth::CSRF_HEADER),
        &expected,
    )
    .map_err(|why| {
        tracing::warn!(
            "web: {what} with {}'s session from {} refused as a possible cross-site request: {why}",
            caller.user.name,
            caller.address
        );
        answer(
            StatusCode::FORBIDDEN,
            &error(&format!("{what} refused: {why}; nothing was carried out")),
        )
    })
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LoginBody {
    token: String,
}

fn session_cookie(app: &App, value: &str, max_age_s: i64) -> HeaderValue {
    let secure = if app.tls { "; Secure" } else { "" };
    HeaderValue::from_str(&format!(
        "{}={value}; Max-Age={max_age_s}; Path=/; HttpOnly; SameSite=Strict{secure}",
        auth::COOKIE
    ))
    .unwrap_or(HeaderValue::from_static(""))
}

async fn login(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    h: HeaderMap,
    body: Bytes,
) -> Response {
    if let Err(why) = auth::same_origin(&provenance(&app, &h)) {
        tracing::warn!("web: sign-in from {addr} refused: {why}");
        return answer(
            StatusCode::FORBIDDEN,
            &error(&format!("sign-in refused: {why}")),
        );
    }
    let Ok(LoginBody { token }) = serde_json::from_slice(&body) else {
        return answer(
            StatusCode::BAD_REQUEST,
            &error("sign in with a JSON body {\"token\": \"…\"}"),
        );
    };
    let Some(user) = app.users.by_token(token.trim()) else {
        // A guess costs a little time.
        tokio::time::sleep(Duration::from_millis(300)).await;
        return unauthorised(
            &app,
            addr,
            "sign-in",
            "the token is not one of [web] token-file",
        );
    };
    let max_age = i64::from(app.session_hours) * 3600;
    let (cookie, session) = match app.sessions.issue(user, now_s() + max_age) {
        Ok(c) => c,
        Err(e) => return answer(StatusCode::INTERNAL_SERVER_ERROR, &error(&e)),
    };
    tracing::info!("web: {} signed in from {addr}", user.name);
    let body = json!({
        "user": user.name,
        "role": user.role,
        "csrf": app.sessions.csrf_token(user, &session),
        "expires": session.expires,
    });
    let mut r = (
        [(header::CONTENT_TYPE, "application/json")],
        body.to_string(),
    )
        .into_response();
    r.headers_mut()
        .insert(header::SET_COOKIE, session_cookie(&app, &cookie, max_age));
    r
}

async fn logout(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    h: HeaderMap,
) -> Response {
    let caller = match authenticate(&app, &h, addr, "sign-out") {
        Ok(c) => c,
        Err(r) => return r,
    };
    if let Err(r) = csrf(&app, &h, &caller, "sign-out") {
        return r;
    }
    if let Some(s) = &caller.session {
        app.sessions.revoke(s, now_s());
        tracing::info!("web: {} signed out from {addr}", caller.user.name);
    }
    let mut r = answer(
        StatusCode::OK,
        &Message::Ack {
            command: "logout".into(),
            detail: "signed out".into(),
        },
    );
    r.headers_mut()
        .insert(header::SET_COOKIE, session_cookie(&app, "", 0));
    r
}

async fn session(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    h: HeaderMap,
) -> Response {
    let caller = match authenticate(&app, &h, addr, "session") {
        Ok(c) => c,
        Err(r) => return r,
    };
    let csrf = caller
        .session
        .as_ref()
        .map(|s| app.sessions.csrf_token(&caller.user, s));
    let body = json!({
        "user": caller.user.name,
        "role": caller.user.role,
        "csrf": csrf,
        "expires": caller.session.as_ref().map(|s| s.expires),
    });
    (
        [(header::CONTENT_TYPE, "application/json")],
        body.to_string(),
    )
        .into_response()
}

/// The socket's request line for `POST /api/CLASS` with `body`: the class spliced in front
/// of the body's members, so the socket's parser sees exactly what was sent (a `class` in the
/// body is a member named twice, refused).
pub fn request_line(class: &str, body: &[u8]) -> Result<String, String> {
    if class.is_empty() || !class.bytes().all(|b| b.is_ascii_lowercase() || b == b'-') {
        return Err(format!(
            "{class:?} is not a request class; classes are lowercase words joined by -, e.g. pause"
        ));
    }
    let text = std::str::from_utf8(body).map_err(|_| "the body is not UTF-8 text".to_owned())?;
    let text = text.trim();
    if text.is_empty() {
        return Ok(format!("{{\"class\":\"{class}\"}}"));
    }
    let Some(rest) = text.strip_prefix('{') else {
        return Err("the body must be a JSON object of the request's members, e.g. {\"specimen\":\"B12\"}, or empty".into());
    };
    let sep = if rest.trim_start().starts_with('}') {
        ""
    } else {
        ","
    };
    Ok(format!("{{\"class\":\"{class}\"{sep}{rest}"))
}

async fn api_get(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    Path(class): Path<String>,
    h: HeaderMap,
) -> Response {
    if let Err(r) = authenticate(&app, &h, addr, &format!("GET /api/{class}")) {
        return r;
    }
    run_request(&app, &class, b"", None, Method::GET).await
}

async fn api_post(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    Path(class): Path<String>,
    h: HeaderMap,
    body: Bytes,
) -> Response {
    let what = format!("POST /api/{class}");
    let caller = match authenticate(&app, &h, addr, &what) {
        Ok(c) => c,
        Err(r) => return r,
    };
    if let Err(r) = csrf(&app, &h, &caller, &what) {
        return r;
    }
    run_request(&app, &class, &body, Some(&caller), Method::POST).await
}

/// Parses and carries out one request of the socket for `caller` (`None`: a `GET`, which
/// may not command).
async fn run_request(
    app: &App,
    class: &str,
    body: &[u8],
    caller: Option<&Caller>,
    method: Method,
) -> Response {
    let line = match request_line(class, body) {
        Ok(l) => l,
        Err(e) => {
            return answer(
                StatusCode::BAD_REQUEST,
                &error(&format!("{e}; nothing is carried out")),
            )
        }
    };
    let request = match parse_request(&line) {
        Ok(r) => r,
        Err(m) => return answer(StatusCode::BAD_REQUEST, &m),
    };
    let mut forbidden = false;
    let who = |name: &'static str| -> Result<Peer, Message> {
        let Some(c) = caller else {
            forbidden = true;
            return Err(error(&format!(
                "{name} changes the station: send it as POST /api/{name}"
            )));
        };
        if c.user.role != Role::Operate {
            forbidden = true;
            tracing::warn!(
                "web: {name} from {} ({}) refused: the user may only look",
                c.user.name,
                c.address
            );
            return Err(error(&format!(
                "{name} refused: {} may only look ([web] token-file gives the user the role view)",
                c.user.name
            )));
        }
        Ok(Peer::on_behalf_of(&c.user.name, &c.address.to_string()))
    };
    let reply = dispatch(request, &app.channels, who, app.reply_timeout).await;
    if forbidden {
        let status = if method == Method::GET {
            StatusCode::METHOD_NOT_ALLOWED
        } else {
            StatusCode::FORBIDDEN
        };
        return answer(status, &reply);
    }
    let status = status_of(&reply);
    if let Some(c) = caller {
        let outcome = match &reply {
            Message::Ack { detail, .. } => format!("accepted: {detail}"),
            Message::Error { message } => format!("refused: {message}"),
            _ => "answered".to_owned(),
        };
        tracing::info!(
            "web: {class} from {} ({}) {outcome}",
            c.user.name,
            c.address
        );
    }
    answer(status, &reply)
}

fn sse_response<S>(stream: S) -> Response
where
    S: futures::Stream<Item = Result<Event, Infallible>> + Send + 'static,
{
    let mut r = Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(KEEP_ALIVE))
        .into_response();
    r.headers_mut()
        .insert("x-accel-buffering", HeaderValue::from_static("no"));
    r
}

async fn live(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    h: HeaderMap,
) -> Response {
    if let Err(r) = authenticate(&app, &h, addr, "GET /api/live") {
        return r;
    }
    struct St {
        rx: watch::Receiver<Arc<View>>,
        cursor: Cursor,
        pending: VecDeque<Event>,
        first: bool,
    }
    let st = St {
        rx: app.view.clone(),
        cursor: Cursor::default(),
        pending: VecDeque::new(),
        first: true,
    };
    let stream = futures::stream::unfold(st, |mut st| async move {
        loop {
            if let Some(e) = st.pending.pop_front() {
                return Some((Ok(e), st));
            }
            if !st.first && st.rx.changed().await.is_err() {
                return None;
            }
            st.first = false;
            let view = st.rx.borrow_and_update().clone();
            st.pending.extend(
                st.cursor
                    .next_events(&view)
                    .into_iter()
                    .map(|(name, data)| Event::default().event(name).data(&*data)),
            );
        }
    });
    sse_response(stream)
}

async fn watch_status(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    h: HeaderMap,
) -> Response {
    if let Err(r) = authenticate(&app, &h, addr, "GET /api/watch") {
        return r;
    }
    let rx = app.channels.status.clone();
    let stream = futures::stream::unfold((rx, true), |(mut rx, first)| async move {
        if !first {
            // At most a few a second: what changes meanwhile is taken together.
            tokio::time::sleep(MIN_INTERVAL).await;
            rx.changed().await.ok()?;
        }
        let m = crate::control::dispatch::snapshot(&mut rx, true);
        let data = serde_json::to_string(&m).unwrap_or_default();
        Some((Ok(Event::default().event("status").data(data)), (rx, false)))
    });
    sse_response(stream)
}

#[derive(serde::Deserialize)]
struct ScansQuery {
    limit: Option<usize>,
}

async fn scans(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    Query(q): Query<ScansQuery>,
    h: HeaderMap,
) -> Response {
    if let Err(r) = authenticate(&app, &h, addr, "GET /api/scans") {
        return r;
    }
    let limit = q
        .limit
        .unwrap_or(HISTORY_LIMIT)
        .clamp(1, history::MAX_SCANS);
    let mut cache = app.history.lock().await;
    if let Some((at, l, body)) = cache.as_ref() {
        if *l == limit && at.elapsed() < Duration::from_secs(2) {
            return (
                [(header::CONTENT_TYPE, "application/json")],
                body.to_string(),
            )
                .into_response();
        }
    }
    let out = app.out.clone();
    let made = tokio::task::spawn_blocking(move || history::history(&out, limit)).await;
    match made {
        Ok(Ok(h)) => {
            let body: Arc<str> = serde_json::to_string(&h).unwrap_or_default().into();
            *cache = Some((tokio::time::Instant::now(), limit, body.clone()));
            (
                [(header::CONTENT_TYPE, "application/json")],
                body.to_string(),
            )
                .into_response()
        }
        Ok(Err(e)) => answer(StatusCode::INTERNAL_SERVER_ERROR, &error(&e)),
        Err(e) => answer(StatusCode::INTERNAL_SERVER_ERROR, &error(&e.to_string())),
    }
}

async fn scan_file(
    State(app): State<Arc<App>>,
    Extension(ClientAddr(addr)): Extension<ClientAddr>,
    Path((scan, file)): Path<(String, String)>,
    h: HeaderMap,
) -> Response {
    if let Err(r) = authenticate(&app, &h, addr, "GET /scans/…") {
        return r;
    }
    let not_found = || {
        answer(
            StatusCode::NOT_FOUND,
            &error("no such file of a scan; the history lists each scan's files"),
        )
    };
    let Some(path) = history::scan_file(&app.out, &scan, &file) else {
        return not_found();
    };
    let Ok(f) = tokio::fs::File::open(&path).await else {
        return not_found();
    };
    let len = f.metadata().await.map(|m| m.len()).ok();
    let (media, save) = history::media_type(&file);
    let mut r = Response::new(Body::from_stream(tokio_util::io::ReaderStream::new(f)));
    let hs = r.headers_mut();
    hs.insert(header::CONTENT_TYPE, HeaderValue::from_static(media));
    if let Some(len) = len {
        hs.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    }
    // A scan's page or figure runs nothing and reaches nothing of the station's page.
    hs.insert(
        "content-security-policy",
        HeaderValue::from_static(
            "sandbox; default-src 'none'; img-src data:; style-src 'unsafe-inline'",
        ),
    );
    hs.insert(
        header::CACHE_CONTROL,
        HeaderValue::from_static("private, max-age=60"),
    );
    if save {
        if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{file}\"")) {
            hs.insert(header::CONTENT_DISPOSITION, v);
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_class_is_spliced_in_front_of_the_body() {
        assert_eq!(request_line("pause", b"").unwrap(), r#"{"class":"pause"}"#);
        assert_eq!(
            request_line("pause", b" {} ").unwrap(),
            r#"{"class":"pause"}"#
        );
        assert_eq!(
            request_line("start", br#"{"specimen":"B12"}"#).unwrap(),
            r#"{"class":"start","specimen":"B12"}"#
        );
        // A class in the body is a member named twice: the socket's parser refuses it.
        let line = request_line("status", br#"{"class":"abort"}"#).unwrap();
        assert!(parse_request(&line).is_err());
        assert!(request_line("Pause", b"").is_err());
        assert!(request_line("../x", b"").is_err());
        assert!(request_line("start", b"[1]").is_err());
        assert!(request_line("start", &[0xff]).is_err());
    }

    #[test]
    fn the_spliced_line_is_parsed_as_the_socket_parses_it() {
        let line = request_line("start", br#"{"specimen":"B12","mode":"new"}"#).unwrap();
        assert_eq!(
            parse_request(&line).unwrap(),
            crate::control::protocol::Request::Start {
                specimen: "B12".into(),
                operator: String::new(),
                notes: String::new(),
                mode: crate::scan::command::StartMode::New,
                recipe: None,
                y_start_mm: None,
            }
        );
        let line = request_line("pause", br#"{"force":true}"#).unwrap();
        let Err(Message::Error { message }) = parse_request(&line) else {
            panic!("an unknown member was accepted")
        };
        assert!(message.contains("unknown field \"force\""), "{message}");
        let line = request_line("bogus", b"").unwrap();
        assert!(parse_request(&line).is_err());
    }
}
