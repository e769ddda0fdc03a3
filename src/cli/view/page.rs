//! The page, built into the binary: HTML, its script (plain WebGL2, no library) and its style.
//! Its content security policy lets it load nothing but this server's own files, so the page
//! works without a network and talks to no one else.

use axum::http::header;
use axum::response::{IntoResponse, Response};

const HTML: &str = include_str!("page/index.html");
const SCRIPT: &str = include_str!("page/view.js");
const STYLE: &str = include_str!("page/view.css");

/// Only this server's files; downloads of the camera are `blob:` links the script makes.
const POLICY: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; \
                      connect-src 'self'; base-uri 'none'; form-action 'none'; \
                      frame-ancestors 'none'";

/// `/`: the page.
pub fn html() -> Response {
    own("text/html; charset=utf-8", HTML)
}

/// `/view.js`: the viewer.
pub fn script() -> Response {
    own("text/javascript; charset=utf-8", SCRIPT)
}

/// `/view.css`: the layout.
pub fn style() -> Response {
    own("text/css; charset=utf-8", STYLE)
}

fn own(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CONTENT_SECURITY_POLICY, POLICY),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}
