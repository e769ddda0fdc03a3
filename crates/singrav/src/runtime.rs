//! The process-wide settings under which volgen trains and renders fast, as one call.
//!
//! Training runs thousands of short parallel loops and allocates the same multi-megabyte
//! tensors every iteration; four settings of the process, none of which a library can make
//! for one call alone, decide how much of the machine that gets (as the project measured them,
//! docs/journal/): the allocator keeps freed tensors (a generator step 1.7x faster), candle's
//! element-wise pool parks at once (`tiny`'s scale-3 iterations 11% faster) and runs on the
//! calling thread (`tiny` 1.07x faster), and the calling thread is one of rayon's threads
//! (4-9% of a GAN step). The `volgen` binary calls [`init`] first thing; a program that trains
//! or renders with these crates should too.
//!
//! ```
//! let runtime = singrav::runtime::init(&singrav::runtime::RuntimeOptions::default())?;
//! assert!(runtime.threads >= 1);
//! assert_eq!(rayon::current_thread_index(), Some(0)); // this thread works in the pool
//! # Ok::<(), singrav::Error>(())
//! ```

use crate::error::{invalid, Result};

/// What [`init`] may set.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RuntimeOptions {
    /// rayon's thread count (None: the `RAYON_NUM_THREADS` variable, or else the number of
    /// CPUs).
    pub threads: Option<usize>,
}

/// What [`init`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Runtime {
    /// The size of rayon's global pool, the calling thread included.
    pub threads: usize,
    /// Whether the allocator was tuned to keep freed memory (glibc on Linux only).
    pub malloc_tuned: bool,
}

/// Sets the process up for training and rendering: call it once, first thing in `main`, on
/// the thread that will run the work, before any other thread exists (it sets environment
/// variables, which is only sound while the process has one thread, and builds rayon's global
/// pool, which can be built once).
///
/// - glibc's allocator keeps freed memory instead of unmapping and faulting it in anew each
///   iteration ([`volrender::tune_malloc`]);
/// - `CANDLE_BARRIER_POOL_SPIN_LIMIT=1`: candle's element-wise pool parks at once after each op
///   instead of spinning 25 000 times on a core the convolutions that follow need;
/// - `CANDLE_NUM_THREADS=1`: that pool runs on the calling thread alone; the work it gets
///   between volgen's own threaded kernels is gradient bookkeeping and small ops, where handing
///   each op to a parked worker costs more than a second core gives back (the convolutions,
///   the renderer and candle's matmul keep rayon's threads);
/// - with the `cuda` feature, `CANDLE_GRAD_DO_NOT_DETACH=1`: on a GPU the critics' gradient
///   penalty is candle's double backward, which needs it before the first backward pass;
/// - rayon's global pool with the calling thread as its thread 0
///   ([`volrender::join_global_pool`]).
///
/// A variable the user set is kept. Errors when rayon's pool was already built (by an earlier
/// call, or by parallel work run before it).
pub fn init(options: &RuntimeOptions) -> Result<Runtime> {
    let malloc_tuned = volrender::tune_malloc();
    #[cfg(feature = "cuda")]
    set_unless_present("CANDLE_GRAD_DO_NOT_DETACH", "1");
    set_unless_present("CANDLE_BARRIER_POOL_SPIN_LIMIT", "1");
    set_unless_present("CANDLE_NUM_THREADS", "1");
    // After the variables: the pool's threads are the program's first.
    let threads = volrender::join_global_pool(options.threads).map_err(|e| {
        invalid(
            "runtime",
            format!("could not start the worker threads (call init once, first): {e}"),
        )
    })?;
    Ok(Runtime {
        threads,
        malloc_tuned,
    })
}

/// Sets `key` to `value` unless the user set it.
fn set_unless_present(key: &str, value: &str) {
    if std::env::var_os(key).is_none() {
        std::env::set_var(key, value);
    }
}
