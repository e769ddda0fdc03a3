//! Large buffers kept for reuse across calls, so that a training loop does not page-fault its
//! temporaries in anew on every step.
//!
//! glibc's allocator maps every allocation above its threshold (128 KiB, rising up to 32 MiB
//! as mapped blocks are freed) afresh and unmaps it when freed, and it returns the top of its
//! heap to the system whenever more than twice that threshold is free there: a multi-megabyte
//! temporary made and dropped once per step is then faulted in page by page on every step,
//! zeroed by the kernel each time. Measured before this pool (`perf stat`, a critic step at
//! 108^2 with its penalty, on the Intel Xeon of docs/performance-patch-gan.md): 21,000 page
//! faults per step without process-wide allocator settings, 2,400 with them. The kernels take
//! their outputs and temporaries from here ([`recycled`]), and what they, or their callers, are
//! done with comes back through [`recycle`].

use std::any::Any;
use std::sync::Mutex;

use crate::element::Element;

/// Smallest buffer kept, in bytes: glibc's smallest mapping threshold; it serves smaller
/// blocks from its heap without faults.
const MIN_BYTES: usize = 128 << 10;

/// Most buffers kept: more than a training step of a five-layer network holds at once.
const MAX_BUFFERS: usize = 32;

/// Most bytes kept: beyond it the oldest buffers are freed.
const MAX_BYTES: usize = 1 << 30;

/// A kept buffer: its size in bytes and the `Vec<T>` itself.
struct Kept {
    bytes: usize,
    buffer: Box<dyn Any + Send>,
}

/// The kept buffers, oldest first.
static POOL: Mutex<Vec<Kept>> = Mutex::new(Vec::new());

/// Hands `buffer` back for a later kernel call to reuse (its values are not read again; a
/// buffer below 128 KiB is simply freed). For values a kernel returned and the caller no
/// longer needs, such as the intermediate results of a network's layers within one step.
///
/// ```
/// use conv_kernels::{fused, recycle};
/// let y = fused::leaky_relu(&vec![1f32; 1 << 16], 0.2);
/// recycle(y); // the next kernel call of this size reuses its memory
/// ```
pub fn recycle<T: Element>(mut buffer: Vec<T>) {
    let bytes = buffer.capacity() * std::mem::size_of::<T>();
    if bytes < MIN_BYTES {
        return;
    }
    buffer.clear();
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    pool.push(Kept {
        bytes,
        buffer: Box::new(buffer),
    });
    let mut total: usize = pool.iter().map(|k| k.bytes).sum();
    while pool.len() > MAX_BUFFERS || total > MAX_BYTES {
        total -= pool.remove(0).bytes;
    }
}

/// An empty vector with room for at least `len` values: a [recycled](recycle) buffer of `len`
/// to `2 len` values (the smallest such), or a new one. For temporaries that are handed back
/// when done.
///
/// ```
/// let mut v = conv_kernels::recycled::<f32>(1 << 16);
/// assert!(v.is_empty() && v.capacity() >= 1 << 16);
/// v.resize(1 << 16, 0.5);
/// conv_kernels::recycle(v);
/// ```
pub fn recycled<T: Element>(len: usize) -> Vec<T> {
    let bytes = len * std::mem::size_of::<T>();
    if bytes >= MIN_BYTES {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        let best = pool
            .iter()
            .enumerate()
            .filter(|(_, k)| k.bytes >= bytes && k.bytes <= 2 * bytes && k.buffer.is::<Vec<T>>())
            .min_by_key(|(_, k)| k.bytes)
            .map(|(i, _)| i);
        if let Some(i) = best {
            if let Ok(buffer) = pool.remove(i).buffer.downcast::<Vec<T>>() {
                return *buffer;
            }
        }
    }
    Vec::with_capacity(len)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recycled_buffer_serves_the_next_request_of_its_size_and_type() {
        // A size no other test of this crate uses, so that parallel tests do not take it.
        let len = 123_457;
        let mut first = recycled::<f32>(len);
        first.resize(len, 1.0);
        let ptr = first.as_ptr();
        recycle(first);
        // Another type and a far smaller size do not take it.
        assert!(recycled::<f64>(len / 2).capacity() >= len / 2);
        let small = recycled::<f32>(len / 3);
        assert_ne!(small.as_ptr(), ptr);
        let again = recycled::<f32>(len - 7);
        assert_eq!(again.as_ptr(), ptr);
        assert!(again.is_empty() && again.capacity() >= len);
    }

    #[test]
    fn small_buffers_are_not_kept() {
        let v = vec![0f32; 1000];
        recycle(v);
        let pool = POOL.lock().unwrap();
        assert!(pool.iter().all(|k| k.bytes >= MIN_BYTES));
    }
}
