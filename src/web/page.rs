//! The page itself: one HTML file, its script and its style sheet, compiled into the binary
//! (no framework, nothing fetched from elsewhere). They hold no station data: the script signs
//! in and asks the API for everything it shows.
//!
//! Layer 4 (process edge): depends on axum's response types only.

use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};

const INDEX: &str = include_str!("page/index.html");
const SCRIPT: &str = include_str!("page/app.js");
const STYLE: &str = include_str!("page/app.css");

/// The content security policy of the page: its own script and style only.
const POLICY: &str = "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; img-src 'self' data:; form-action 'self'; frame-ancestors 'none'; base-uri 'none'";

fn asset(media: &'static str, body: &'static str) -> Response {
    let mut r = ([(header::CONTENT_TYPE, media)], body).into_response();
    r.headers_mut()
        .insert("content-security-policy", HeaderValue::from_static(POLICY));
    r
}

/// `GET /`.
pub fn index() -> Response {
    asset("text/html; charset=utf-8", INDEX)
}

/// `GET /app.js`.
pub fn script() -> Response {
    asset("text/javascript; charset=utf-8", SCRIPT)
}

/// `GET /app.css`.
pub fn style() -> Response {
    asset("text/css; charset=utf-8", STYLE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_loads_nothing_from_elsewhere_and_runs_no_inline_script() {
        for needle in ["http://", "https://", "<script>", "onclick", "onload="] {
            assert!(!INDEX.contains(needle), "{needle}");
        }
        // Text from the daemon is set as text, never parsed as markup.
        assert!(!SCRIPT.contains("innerHTML"));
        // The script names every element it uses, and the page has each.
        for id in SCRIPT
            .split("$(\"")
            .skip(1)
            .filter_map(|s| s.split('"').next())
        {
            assert!(
                INDEX.contains(&format!("id=\"{id}\"")),
                "#{id} is missing from the page"
            );
        }
    }
}
