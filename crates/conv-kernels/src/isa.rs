//! Which instruction set the kernels run, chosen at run time.
//!
//! The crate is compiled for baseline x86-64 (SSE2), so its vectorised loops run 4 f32 or 2 f64
//! lanes wide unless a function is compiled with `#[target_feature(enable = ...)]` and called
//! after the check here. Each kernel with such builds asks [`Isa::current`] once per call, on
//! the calling thread, and hands the answer to its parallel tasks, so one call runs one build.
//!
//! The choice can be lowered (never raised above what the CPU has): for measurements, by the
//! `CONV_KERNELS_ISA` environment variable (`portable`, `avx2` or `avx512`, read once); in this
//! crate's tests, per thread, by `with_isa`, so that every build is tested on a CPU that has
//! the widest.

use std::sync::OnceLock;

/// An instruction set the kernels have builds for, from the narrowest to the widest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// Baseline x86-64 (SSE2), or any other architecture.
    Portable,
    /// AVX2 and FMA (8 f32 lanes): the transforms' 8-lane build and the Winograd products'
    /// own kernels.
    Avx2,
    /// AVX-512 F on top of AVX2 and FMA (16 f32 lanes): the transforms' 16-lane kernels and
    /// `gemm`'s AVX-512 products.
    Avx512,
}

impl Isa {
    /// The widest instruction set this CPU runs (detected once per process).
    pub fn detected() -> Isa {
        static DETECTED: OnceLock<Isa> = OnceLock::new();
        *DETECTED.get_or_init(detect)
    }

    /// What the kernels run now: [`Isa::detected`], lowered by `CONV_KERNELS_ISA` if that is
    /// set (and, in this crate's tests, by `with_isa`).
    ///
    /// ```
    /// use conv_kernels::Isa;
    /// assert!(Isa::current() <= Isa::detected());
    /// ```
    pub fn current() -> Isa {
        static CAPPED: OnceLock<Isa> = OnceLock::new();
        let capped = *CAPPED.get_or_init(|| {
            let cap = std::env::var("CONV_KERNELS_ISA")
                .ok()
                .and_then(|name| Isa::from_name(&name));
            cap.map_or(Isa::detected(), |cap| cap.min(Isa::detected()))
        });
        #[cfg(test)]
        let capped = tests::limit().map_or(capped, |limit| limit.min(capped));
        capped
    }

    /// The instruction set a name of `CONV_KERNELS_ISA` stands for.
    fn from_name(name: &str) -> Option<Isa> {
        match name.trim().to_ascii_lowercase().as_str() {
            "portable" => Some(Isa::Portable),
            "avx2" => Some(Isa::Avx2),
            "avx512" => Some(Isa::Avx512),
            _ => None,
        }
    }
}

/// The widest instruction set of this CPU.
fn detect() -> Isa {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
        if avx2 && std::is_x86_feature_detected!("avx512f") {
            return Isa::Avx512;
        }
        if avx2 {
            return Isa::Avx2;
        }
    }
    Isa::Portable
}

/// Every instruction set this CPU runs, narrowest first: what a test runs each path on.
#[cfg(test)]
pub(crate) fn available() -> Vec<Isa> {
    [Isa::Portable, Isa::Avx2, Isa::Avx512]
        .into_iter()
        .filter(|&isa| isa <= Isa::detected())
        .collect()
}

/// Runs `f` with the kernels it calls from this thread lowered to `limit`.
#[cfg(test)]
pub(crate) fn with_isa<R>(limit: Isa, f: impl FnOnce() -> R) -> R {
    tests::LIMIT.with(|l| {
        let before = l.replace(Some(limit));
        let result = f();
        l.set(before);
        result
    })
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;

    thread_local! {
        pub(super) static LIMIT: Cell<Option<Isa>> = const { Cell::new(None) };
    }

    pub(super) fn limit() -> Option<Isa> {
        LIMIT.with(Cell::get)
    }

    #[test]
    fn a_limit_lowers_the_choice_on_its_thread_only() {
        let widest = Isa::current();
        with_isa(Isa::Portable, || {
            assert_eq!(Isa::current(), Isa::Portable);
            let elsewhere = std::thread::spawn(Isa::current).join().unwrap();
            assert_eq!(elsewhere, widest);
        });
        assert_eq!(Isa::current(), widest);
        // Never above the CPU's.
        with_isa(Isa::Avx512, || assert_eq!(Isa::current(), widest));
    }

    #[test]
    fn names_parse_in_any_case() {
        assert_eq!(Isa::from_name(" AVX512 "), Some(Isa::Avx512));
        assert_eq!(Isa::from_name("avx2"), Some(Isa::Avx2));
        assert_eq!(Isa::from_name("portable"), Some(Isa::Portable));
        assert_eq!(Isa::from_name("sse"), None);
    }
}
