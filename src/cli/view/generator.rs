//! One generation at a time: the server's threads hand work (draw a scene, make a download)
//! to the generator through a bounded queue and wait for the answer; the generator runs it on
//! the thread that owns the model (rayon's thread 0, where volgen's kernels run fastest). A
//! request that finds the queue full is refused at once (the server answers 503) instead of
//! waiting without bound, so memory and waiting stay bounded however many requests come.

use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};

use axum::body::Bytes;
use tokio::sync::oneshot;

use super::cache::Cache;
use super::params::SceneKey;
use super::scene::{Format, Scene};
use super::source::Source;

/// How many jobs may wait for the generator, beside the one it runs.
pub const QUEUE: usize = 8;

/// Why a job gave no result, with the HTTP status the server answers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Failure {
    /// The queue is full: 503, try again.
    Busy,
    /// The scene has nothing to export in that format (an empty scene has no surface to
    /// mesh): 422.
    Unexportable(String),
    /// Generation or export failed, or the generator stopped: 500.
    Failed(String),
}

/// Work for the generator.
enum Job {
    Draw {
        key: SceneKey,
        reply: oneshot::Sender<Result<Arc<Scene>, Failure>>,
    },
    Export {
        scene: Arc<Scene>,
        format: Format,
        reply: oneshot::Sender<Result<Bytes, Failure>>,
    },
}

/// The server's handle on the generator: submits jobs and waits for their results.
#[derive(Clone)]
pub struct Generator {
    jobs: SyncSender<Job>,
    cache: Arc<Mutex<Cache>>,
}

/// The generator's end of the queue.
pub struct Jobs(Receiver<Job>);

/// A generator handle and its queue of at most `bound` waiting jobs, sharing `cache`.
pub fn channel(bound: usize, cache: Arc<Mutex<Cache>>) -> (Generator, Jobs) {
    let (jobs, receiver) = mpsc::sync_channel(bound);
    (Generator { jobs, cache }, Jobs(receiver))
}

impl Generator {
    /// The scene for `key`: from the cache, or drawn by the generator.
    pub async fn scene(&self, key: SceneKey) -> Result<Arc<Scene>, Failure> {
        if let Some(scene) = lock(&self.cache).find(&key) {
            return Ok(scene);
        }
        let (reply, answer) = oneshot::channel();
        self.submit(Job::Draw { key, reply })?;
        answer.await.map_err(|_| stopped())?
    }

    /// The scene numbered `id`, if the cache still holds it.
    pub fn cached(&self, id: u64) -> Option<Arc<Scene>> {
        lock(&self.cache).get(id)
    }

    /// `scene`'s download in `format`: made once by the generator, then kept with the scene.
    pub async fn export(&self, scene: Arc<Scene>, format: Format) -> Result<Bytes, Failure> {
        if let Some(bytes) = scene.export(format) {
            return Ok(bytes);
        }
        let (reply, answer) = oneshot::channel();
        self.submit(Job::Export {
            scene,
            format,
            reply,
        })?;
        answer.await.map_err(|_| stopped())?
    }

    fn submit(&self, job: Job) -> Result<(), Failure> {
        self.jobs.try_send(job).map_err(|e| match e {
            TrySendError::Full(_) => Failure::Busy,
            TrySendError::Disconnected(_) => stopped(),
        })
    }
}

/// Runs jobs from `jobs` with `source` one at a time until every [`Generator`] handle is gone.
pub fn serve(mut source: Source, jobs: Jobs, cache: Arc<Mutex<Cache>>) {
    for job in jobs.0 {
        match job {
            Job::Draw { key, reply } => {
                // Several requests for one scene may have queued before it was drawn.
                let found = lock(&cache).find(&key);
                let result = match found {
                    Some(scene) => Ok(scene),
                    None => source
                        .draw(&key)
                        .map(|scene| lock(&cache).insert(scene))
                        .map_err(|e| Failure::Failed(format!("drawing the scene: {e:#}"))),
                };
                // The requester may have gone; the scene stays cached for the next.
                let _ = reply.send(result);
            }
            Job::Export {
                scene,
                format,
                reply,
            } => {
                let result = match scene.export(format) {
                    Some(bytes) => Ok(bytes),
                    None => source
                        .export(&scene, format)
                        .map(|bytes| {
                            let bytes = Bytes::from(bytes);
                            scene.keep_export(format, bytes.clone());
                            // The scene grew: the cache's byte bound may now drop older ones.
                            lock(&cache).evict();
                            bytes
                        })
                        .map_err(|e| export_failure(&e, format)),
                };
                let _ = reply.send(result);
            }
        }
    }
}

/// An export error as the server reports it: no surface to mesh is the scene's, the rest ours.
fn export_failure(error: &anyhow::Error, format: Format) -> Failure {
    let text = format!("writing the .{} file: {error:#}", format.extension());
    let no_surface = error.chain().any(|cause| {
        matches!(
            cause.downcast_ref::<volume_mesh::Error>(),
            Some(volume_mesh::Error::NoSurface { .. })
        )
    });
    if no_surface {
        Failure::Unexportable(text)
    } else {
        Failure::Failed(text)
    }
}

fn stopped() -> Failure {
    Failure::Failed("the generator stopped".into())
}

/// The cache, also after a thread panicked while holding it (it stays consistent: every
/// change is one push or pop).
fn lock(cache: &Mutex<Cache>) -> std::sync::MutexGuard<'_, Cache> {
    cache.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_refuses_at_once() {
        let cache = Arc::new(Mutex::new(Cache::new(4, usize::MAX)));
        // Nobody runs the jobs: the first two wait, the third is refused.
        let (generator, _jobs) = channel(2, cache);
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let key = |seed| SceneKey::File { index: seed };
        let mut answers = Vec::new();
        for i in 0..2 {
            let (reply, answer) = oneshot::channel();
            generator.submit(Job::Draw { key: key(i), reply }).unwrap();
            answers.push(answer);
        }
        let refused = runtime.block_on(generator.scene(key(2)));
        assert_eq!(refused.err(), Some(Failure::Busy));
    }

    #[test]
    fn a_stopped_generator_fails_instead_of_waiting() {
        let cache = Arc::new(Mutex::new(Cache::new(4, usize::MAX)));
        let (generator, jobs) = channel(2, cache);
        drop(jobs);
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let result = runtime.block_on(generator.scene(SceneKey::File { index: 0 }));
        assert!(matches!(result, Err(Failure::Failed(_))));
    }
}
