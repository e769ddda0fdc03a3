//! The HTTP side: a fixed set of routes (the page, the source's description, scenes by number,
//! training views by number) and nothing else. No route maps a URL to a file path, so paths
//! like `/../../etc/passwd` reach nothing but the 404 fallback; numbers that do not parse are
//! 404 too. Bad query parameters are a 400 with one line saying why; a full generator queue
//! is a 503.

use std::sync::Arc;

use anyhow::{Context, Result};
use axum::body::Bytes;
use axum::extract::rejection::PathRejection;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

use super::generator::{Failure, Generator};
use super::page;
use super::params::{scene_key, Limits};
use super::scene::Format;

/// How many requests the server handles at once; more wait for a turn (each costs a
/// connection and a small buffer until then).
pub const MAX_CONCURRENT_REQUESTS: usize = 64;

/// What the handlers share.
#[derive(Clone)]
pub struct Shared {
    pub generator: Generator,
    pub limits: Limits,
    /// The page's description of the source, JSON.
    pub info: Bytes,
    /// The training views' PNG files.
    pub views: Arc<Vec<Bytes>>,
}

/// Serves `shared` on `listener` on a runtime of its own threads until the process ends.
pub fn spawn(
    listener: std::net::TcpListener,
    shared: Shared,
) -> Result<std::thread::JoinHandle<Result<()>>> {
    listener
        .set_nonblocking(true)
        .context("setting the socket non-blocking")?;
    // Two threads: the server only moves bytes; the generator has the cores.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("volgen-view-http")
        .enable_io()
        .build()
        .context("starting the server's runtime")?;
    Ok(std::thread::Builder::new()
        .name("volgen-view".into())
        .spawn(move || {
            runtime.block_on(async move {
                let listener = tokio::net::TcpListener::from_std(listener)?;
                axum::serve(listener, router(shared)).await?;
                Ok(())
            })
        })?)
}

/// The routes.
pub fn router(shared: Shared) -> Router {
    Router::new()
        .route("/", get(|| async { page::html() }))
        .route("/view.js", get(|| async { page::script() }))
        .route("/view.css", get(|| async { page::style() }))
        .route("/api/info", get(info))
        .route("/api/scene", get(scene))
        .route("/scenes/{id}/{file}", get(scene_file))
        .route("/views/{file}", get(view_image))
        .fallback(|| async { not_found() })
        .with_state(shared)
        .layer(tower::limit::ConcurrencyLimitLayer::new(
            MAX_CONCURRENT_REQUESTS,
        ))
}

async fn info(State(shared): State<Shared>) -> Response {
    typed("application/json", shared.info)
}

/// `/api/scene?seed=..&vary=..&walk=..&extent=..&outside=..` (or `?file=..`): draws the scene
/// (or finds it drawn) and describes it as JSON.
async fn scene(
    State(shared): State<Shared>,
    Query(query): Query<Vec<(String, String)>>,
) -> Response {
    let key = match scene_key(&query, &shared.limits) {
        Ok(key) => key,
        Err(why) => return text(StatusCode::BAD_REQUEST, why),
    };
    match shared.generator.scene(key).await {
        Ok(scene) => typed(
            "application/json",
            Bytes::from(scene.describe().to_string()),
        ),
        Err(failure) => failed(failure),
    }
}

/// `/scenes/{id}/volume` (the page's texture) and `/scenes/{id}/{stem}.{safetensors,vdb,glb}`
/// (downloads) of a scene the cache holds.
async fn scene_file(
    State(shared): State<Shared>,
    path: Result<Path<(String, String)>, PathRejection>,
) -> Response {
    // A path that does not decode names nothing served: 404 like any other.
    let Ok(Path((id, file))) = path else {
        return not_found();
    };
    let Some(scene) = id.parse().ok().and_then(|id| shared.generator.cached(id)) else {
        return not_found();
    };
    if file == "volume" {
        return typed("application/octet-stream", scene.texture.clone());
    }
    let Some(format) = file
        .strip_prefix(scene.stem.as_str())
        .and_then(|rest| rest.strip_prefix('.'))
        .and_then(Format::of_extension)
    else {
        return not_found();
    };
    match shared.generator.export(scene.clone(), format).await {
        Ok(bytes) => {
            let mut response = typed("application/octet-stream", bytes);
            let disposition = format!("attachment; filename=\"{}\"", scene.file_name(format));
            if let Ok(value) = HeaderValue::from_str(&disposition) {
                response
                    .headers_mut()
                    .insert(header::CONTENT_DISPOSITION, value);
            }
            response
        }
        Err(failure) => failed(failure),
    }
}

/// `/views/{i}.png`: training view `i`.
async fn view_image(
    State(shared): State<Shared>,
    path: Result<Path<String>, PathRejection>,
) -> Response {
    let Ok(Path(file)) = path else {
        return not_found();
    };
    let image = file
        .strip_suffix(".png")
        .and_then(|i| i.parse::<usize>().ok())
        .and_then(|i| shared.views.get(i));
    match image {
        Some(png) => typed("image/png", png.clone()),
        None => not_found(),
    }
}

/// A 200 response of `body` as `content_type`, never cached (a scene number means another
/// scene after a restart).
fn typed(content_type: &'static str, body: Bytes) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-store"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
        .into_response()
}

/// A plain-text response: one line saying why.
pub fn text(status: StatusCode, why: String) -> Response {
    (
        status,
        [
            (header::CONTENT_TYPE, "text/plain; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        why + "\n",
    )
        .into_response()
}

fn not_found() -> Response {
    text(StatusCode::NOT_FOUND, "not found".into())
}

fn failed(failure: Failure) -> Response {
    match failure {
        Failure::Busy => {
            let mut response = text(
                StatusCode::SERVICE_UNAVAILABLE,
                format!(
                    "busy: {} requests are waiting for the generator; try again",
                    super::generator::QUEUE
                ),
            );
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
            response
        }
        Failure::Unexportable(why) => text(StatusCode::UNPROCESSABLE_ENTITY, why),
        Failure::Failed(why) => text(StatusCode::INTERNAL_SERVER_ERROR, why),
    }
}
