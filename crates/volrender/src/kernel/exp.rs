//! An inlinable `exp` for f32 on the attenuation's range `x <= 0`.
//!
//! The render kernels take one `exp` per sample, forward and backward; libm's `expf` is accurate
//! but a function call the compiler can neither inline nor interleave with the gathers around
//! it (17% of a dense forward+backward in a profile). This one is straight-line arithmetic:
//! Cody-Waite range reduction `x = n ln2 + r`, `|r| <= ln2 / 2`, a degree-7 Taylor polynomial
//! for `e^r` (truncation error `r^8 / 8! < 6e-9`, below f32's half ulp) evaluated with a short
//! dependency chain, and `2^n` built from the exponent bits. Measured against f64 `exp` it is within 2 ulp (tested below and in
//! `tests/stability.rs`).
//!
//! Results below f32's smallest normal (`x < -87.33`) flush to 0 instead of becoming
//! subnormal: an absolute difference under 1.2e-38, and it keeps subnormal arithmetic out of
//! the transmittance product.

/// `1.5 * 2^23`: adding and subtracting it rounds an f32 of magnitude below `2^22` to the
/// nearest integer in plain arithmetic (no `roundf` call on targets without SSE4.1).
const ROUND_MAGIC: f32 = 12_582_912.0;
/// `ln 2` split so that `n * LN2_HI` is exact for the `n` that occur (|n| <= 126).
const LN2_HI: f32 = 0.693_145_75;
const LN2_LO: f32 = 1.428_606_8e-6;
/// Below this, `e^x` is not a normal f32.
const SMALLEST_NORMAL_LN: f32 = -87.336_54;

/// Returns `e^x` for `x <= 0` (and for NaN, NaN); within 2 ulp of the exact value for results
/// >= `f32::MIN_POSITIVE`, 0 below that.
#[inline(always)]
pub(crate) fn exp_nonpositive(x: f32) -> f32 {
    // Computed for every x and the flush selected at the end, without a branch, so that loops
    // over several samples vectorise. (NaN stays NaN: both comparisons are false.)
    let flush = x < SMALLEST_NORMAL_LN;
    let x = if flush { SMALLEST_NORMAL_LN } else { x };
    // Adding the magic number rounds to an integer n, which then sits in the low mantissa bits:
    // n as an integer is a bit-pattern difference, with no float-to-int conversion (those
    // keep LLVM from vectorising the loop).
    let shifted = x * std::f32::consts::LOG2_E + ROUND_MAGIC;
    let n = shifted - ROUND_MAGIC;
    let n_int = shifted.to_bits() as i32 - ROUND_MAGIC.to_bits() as i32;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    // e^r = sum r^k / k!, by Estrin's scheme: independent pairs joined by r^2 and r^4, so the
    // dependency chain is 4 multiply-adds deep instead of Horner's 8 (the kernel's loop waits on
    // it: the transmittance product needs each sample's exp).
    let r2 = r * r;
    let r4 = r2 * r2;
    let p01 = 1.0 + r;
    let p23 = 0.5 + r * (1.0 / 6.0);
    let p45 = 1.0 / 24.0 + r * (1.0 / 120.0);
    let p67 = 1.0 / 720.0 + r * (1.0 / 5040.0);
    let p = (p01 + r2 * p23) + r4 * (p45 + r2 * p67);
    // n is in [-126, 0] here, so 127 + n is a valid biased exponent of a normal f32.
    // The flush selects a scale of 0 rather than the result, a cheap choice LLVM keeps as a
    // select instead of branching around the polynomial.
    let scale_bits = if flush {
        0
    } else {
        ((127 + n_int) as u32) << 23
    };
    p * f32::from_bits(scale_bits)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::ulps;

    #[test]
    fn within_two_ulp_of_f64_exp() {
        let mut worst = (0.0, 0.0f32);
        let mut check = |x: f32| {
            let e = ulps(exp_nonpositive(x), (x as f64).exp());
            if e > worst.0 {
                worst = (e, x);
            }
        };
        // Every 2^-12 step over the normal range and its neighbour one ulp below.
        let steps = (87.3 * 4096.0) as usize;
        for i in 0..=steps {
            let x = -(i as f32) / 4096.0;
            check(x);
            check(f32::from_bits(x.to_bits() + 1));
        }
        // The range reduction's seams, (k + 1/2) ln 2, and their neighbours.
        for k in 0..125 {
            let seam = -((k as f64 + 0.5) * std::f64::consts::LN_2) as f32;
            for bits in [seam.to_bits() - 1, seam.to_bits(), seam.to_bits() + 1] {
                check(f32::from_bits(bits));
            }
        }
        assert!(
            worst.0 <= 2.0,
            "worst error {} ulp at x = {}",
            worst.0,
            worst.1
        );
    }

    #[test]
    fn edges() {
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-0.0), 1.0);
        assert_eq!(exp_nonpositive(-88.0), 0.0);
        assert_eq!(exp_nonpositive(-1e30), 0.0);
        assert_eq!(exp_nonpositive(f32::NEG_INFINITY), 0.0);
        assert!(exp_nonpositive(f32::NAN).is_nan());
        // Monotone across the flush point.
        assert!(exp_nonpositive(SMALLEST_NORMAL_LN) >= f32::MIN_POSITIVE * 0.99);
    }
}
