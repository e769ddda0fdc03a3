//! Entering rayon's thread pool once per op rather than once per parallel loop.

/// Runs `f` on one of rayon's threads: where it is (the calling thread is one of the pool's,
/// as in a program that built rayon's global pool with `use_current_thread`), or else handed
/// to the global pool once, the calling thread waiting for it.
///
/// Each op's kernels run several parallel loops (a Winograd pass: the weights' transform, the
/// chunks, the partial sums), and a thread outside the pool hands each loop to the pool and
/// sleeps until it is done: two thread switches per loop, about 50 loops per generator step,
/// 4-9% of a step on two cores (docs/journal/2026-11-performance-patch-gan.md). Inside the
/// pool the loops need no hand-over, so the ops are as fast from any thread, with no
/// process-wide setting.
pub(crate) fn in_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        f()
    } else {
        rayon::scope(|_| f())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_runs_on_a_pool_thread_and_returns_its_value() {
        let outside = std::thread::spawn(|| {
            assert_eq!(rayon::current_thread_index(), None);
            in_pool(|| rayon::current_thread_index().map(|_| 7))
        });
        assert_eq!(outside.join().unwrap(), Some(7));
        let nested = rayon::scope(|_| in_pool(|| rayon::current_thread_index().is_some()));
        assert!(nested);
    }
}
