//! rayon's global thread pool with the program's main thread as one of its threads.

/// Builds rayon's global pool with `threads` threads (`None`: rayon's default, the
/// `RAYON_NUM_THREADS` variable or else the number of CPUs), the calling thread being thread 0,
/// and returns the pool's size. Call it once, first thing in `main`, on the thread that runs
/// the program's parallel work; the `volgen` binary does.
///
/// With rayon's own default the calling thread is not in the pool: every parallel loop it
/// starts is handed to the pool's threads while it sleeps, and woken again at the end, two
/// thread switches per loop. A training step runs many short loops (a 28^3 generator step
/// about 50, each a fraction of a millisecond), so on two cores those hand-overs cost 4-5%
/// of a generator step and 9% of a critic step (docs/performance-patch-gan.md). In the pool,
/// the calling thread runs its own share of each loop and the other threads steal the rest.
///
/// Work that threads outside the pool hand to it runs on the pool's other threads only; with
/// `threads` = 1 there are none, and such work waits until the calling thread enters rayon
/// (a caller that blocks on it meanwhile never returns): start parallel work from the calling
/// thread. Nothing in this workspace starts it from another.
///
/// ```
/// use rayon::prelude::*;
/// let threads = volrender::join_global_pool(Some(2))?;
/// assert_eq!(threads, 2);
/// assert_eq!(rayon::current_thread_index(), Some(0));
/// let sum: u64 = (1..=1000u64).into_par_iter().sum();
/// assert_eq!(sum, 500_500);
/// # Ok::<(), rayon::ThreadPoolBuildError>(())
/// ```
pub fn join_global_pool(threads: Option<usize>) -> Result<usize, rayon::ThreadPoolBuildError> {
    let builder = rayon::ThreadPoolBuilder::new().use_current_thread();
    let builder = match threads {
        Some(n) => builder.num_threads(n),
        None => builder,
    };
    builder.build_global()?;
    Ok(rayon::current_num_threads())
}
