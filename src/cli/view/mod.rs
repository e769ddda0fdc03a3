//! `volgen view RUN [--host 127.0.0.1] [--port 8080] [--dataset DIR]`: a local web server
//! with one page that explores a trained model: scenes drawn on a click and rendered live in
//! the browser (WebGL2 ray marching of the volume as a 3D texture, with volrender's samples,
//! interpolation and density activation), orbiting, vary-from, the noise walk, extents, the
//! training views beside the scene from their cameras, and downloads. Also `volgen view DIR`
//! (the `.safetensors` volumes in it) and `volgen view VOLUME.safetensors`.
//!
//! The main thread, rayon's thread 0 where volgen's kernels run fastest, owns the model and
//! runs the generator; the HTTP server runs on threads of its own. Everything a source needs
//! is loaded and checked before the server listens, so a broken run is refused first.

use std::net::{TcpListener, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result};
use axum::body::Bytes;

mod cache;
mod generator;
mod page;
mod params;
mod scene;
mod server;
mod source;
mod views;

use cache::Cache;
use source::Source;

/// Arguments of `volgen view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// What to show: a trained run (its directory or checkpoint.safetensors), a directory of
    /// volumes (the .safetensors files `volgen sample` writes), or one volume.
    path: PathBuf,
    /// The address to listen on. The default, loopback, lets only this machine in; any other
    /// lets in everyone who can reach it (the viewer warns).
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// The port to listen on (0: a free one; the printed URL says which).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// The dataset whose views the page shows beside the scene, from their cameras. Default:
    /// the `dataset` directory beside the run's directory, where `volgen demo` writes it, when
    /// there is one.
    #[arg(long, value_name = "DIR")]
    dataset: Option<PathBuf>,
}

/// Loads the source, listens, prints the URL and serves until the process is stopped.
pub fn run(args: &ViewArgs) -> Result<()> {
    let source = Source::open(&args.path)?;
    let views = training_views(args, &source)?;
    let listener = listen(&args.host, args.port)?;
    let address = listener
        .local_addr()
        .context("reading the socket's address")?;
    let mut info = source.describe(&args.path.display().to_string());
    info["views"] = views::describe(&views);
    info["queue"] = serde_json::json!(generator::QUEUE);
    let cache = Arc::new(Mutex::new(Cache::new(cache::MAX_SCENES, cache::MAX_BYTES)));
    let (generator, jobs) = generator::channel(generator::QUEUE, cache.clone());
    let shared = server::Shared {
        generator,
        limits: source.limits(),
        info: Bytes::from(info.to_string()),
        views: Arc::new(views.into_iter().map(|v| v.png).collect()),
    };
    let server = server::spawn(listener, shared)?;
    if !address.ip().is_loopback() {
        eprintln!(
            "warning: listening on {address}, which is not the loopback: anyone who can reach \
             this machine can use the viewer and make it generate (--host 127.0.0.1 keeps it to \
             this machine)"
        );
    }
    println!(
        "volgen view: {} at http://{address}/ (Ctrl-C stops it)",
        args.path.display()
    );
    // Runs until the server stops (its handle on the generator goes with it).
    generator::serve(source, jobs, cache);
    match server.join() {
        Ok(result) => result.context("the server stopped"),
        Err(_) => anyhow::bail!("the server's thread panicked"),
    }
}

/// The training views for the strip: `--dataset`'s (an error if it cannot be loaded), or the
/// run's `dataset` beside it (a note if it cannot), or none.
fn training_views(args: &ViewArgs, source: &Source) -> Result<Vec<views::TrainingView>> {
    let run_like = matches!(source, Source::Model(_));
    let dataset = match &args.dataset {
        Some(given) => Some(given.clone()),
        None if run_like => views::dataset_beside(&args.path),
        None => None,
    };
    let Some(dataset) = dataset else {
        return Ok(Vec::new());
    };
    match views::load(&dataset, source.background()) {
        Ok(views) => {
            println!("training views: {} from {}", views.len(), dataset.display());
            Ok(views)
        }
        Err(e) if args.dataset.is_none() => {
            eprintln!("note: no training views ({e:#}); give --dataset DIR");
            Ok(Vec::new())
        }
        Err(e) => Err(e),
    }
}

/// Binds `host:port`, saying which address failed and why.
fn listen(host: &str, port: u16) -> Result<TcpListener> {
    let addresses: Vec<_> = (host, port)
        .to_socket_addrs()
        .with_context(|| format!("--host: cannot resolve {host:?}"))?
        .collect();
    let mut last = None;
    for address in &addresses {
        match TcpListener::bind(address) {
            Ok(listener) => return Ok(listener),
            Err(e) => last = Some((address, e)),
        }
    }
    match last {
        Some((address, e)) => Err(e).with_context(|| {
            format!("cannot listen on {address} (another program there? try --port 0 for any free port)")
        }),
        None => anyhow::bail!("--host: {host:?} resolves to no address"),
    }
}
