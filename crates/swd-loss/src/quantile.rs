//! Pairing the quantile functions of two uniform empirical measures of different sizes.
//!
//! The 1D Wasserstein distance between uniform measures on sorted samples `u` (n points) and `v`
//! (m points) is `W_p^p = ∫_0^1 |F_u^{-1}(q) - F_v^{-1}(q)|^p dq`, where `F_u^{-1}` is the step
//! function equal to `u[i]` on `(i/n, (i+1)/n]`. Both step functions are constant between the
//! merged breakpoints `{i/n} ∪ {j/m}`, so the integral is an exact finite sum over those pieces
//! (the definition POT uses). When n = m every piece is one point of each set and the sum is
//! the usual mean over sorted pairs.

use candle_core::{DType, Device, Tensor, D};

use crate::error::Result;

/// One constant piece of both quantile functions: indices into the sorted samples and the
/// length of the quantile interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Piece {
    pub(crate) u_index: u32,
    pub(crate) v_index: u32,
    pub(crate) weight: f64,
}

/// Lists the pieces of `(0, 1]` on which both quantile functions (n and m points) are
/// constant, in increasing order. There are at most `n + m - 1` of them; weights sum to 1.
pub(crate) fn merged_pieces(n: usize, m: usize) -> Vec<Piece> {
    // Work in units of 1 / (n m) so every breakpoint is an integer: u's are multiples of m,
    // v's multiples of n. u64 holds n m for any sizes that fit in memory.
    let (n64, m64) = (n as u64, m as u64);
    let total = (n64 * m64) as f64;
    let mut pieces = Vec::with_capacity(n + m - 1);
    let (mut next_u, mut next_v) = (m64, n64);
    let mut left = 0u64;
    while left < n64 * m64 {
        let right = next_u.min(next_v);
        pieces.push(Piece {
            // The piece (left, right] lies inside u's step floor(left / m) and v's step
            // floor(left / n), because left is itself a breakpoint.
            u_index: (left / m64) as u32,
            v_index: (left / n64) as u32,
            weight: (right - left) as f64 / total,
        });
        if right == next_u {
            next_u += m64;
        }
        if right == next_v {
            next_v += n64;
        }
        left = right;
    }
    pieces
}

/// How sorted projections of the two sets are paired before their differences are averaged.
#[derive(Debug, Clone)]
pub(crate) enum Coupling {
    /// n = m: the i-th smallest of one set against the i-th smallest of the other, weight 1/n.
    Equal,
    /// n ≠ m: the merged pieces of [`merged_pieces`], as gather indices and weights.
    Merged {
        u_index: Tensor,
        v_index: Tensor,
        weights: Tensor,
    },
}

impl Coupling {
    /// Builds the coupling of n against m sorted points, with weights in `dtype`.
    pub(crate) fn new(n: usize, m: usize, dtype: DType, device: &Device) -> Result<Self> {
        if n == m {
            return Ok(Self::Equal);
        }
        let pieces = merged_pieces(n, m);
        let u: Vec<u32> = pieces.iter().map(|p| p.u_index).collect();
        let v: Vec<u32> = pieces.iter().map(|p| p.v_index).collect();
        let w: Vec<f64> = pieces.iter().map(|p| p.weight).collect();
        let len = pieces.len();
        Ok(Self::Merged {
            u_index: Tensor::from_vec(u, len, device)?,
            v_index: Tensor::from_vec(v, len, device)?,
            weights: Tensor::from_vec(w, len, device)?.to_dtype(dtype)?,
        })
    }

    /// Pairs sorted `(.., n)` and `(.., m)` tensors into two tensors of the same last dimension.
    pub(crate) fn align(&self, xs: &Tensor, ys: &Tensor) -> Result<(Tensor, Tensor)> {
        Ok(match self {
            Self::Equal => (xs.clone(), ys.clone()),
            Self::Merged {
                u_index, v_index, ..
            } => (
                xs.index_select(u_index, D::Minus1)?,
                ys.index_select(v_index, D::Minus1)?,
            ),
        })
    }

    /// Integrates per-piece values over the quantile levels (the last dimension).
    pub(crate) fn integrate(&self, terms: &Tensor) -> Result<Tensor> {
        Ok(match self {
            Self::Equal => terms.mean(D::Minus1)?,
            Self::Merged { weights, .. } => terms.broadcast_mul(weights)?.sum(D::Minus1)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_of_two_against_three() {
        // Breakpoints 1/2 and 1/3, 2/3: pieces (0,1/3], (1/3,1/2], (1/2,2/3], (2/3,1].
        let p = merged_pieces(2, 3);
        let got: Vec<(u32, u32)> = p.iter().map(|p| (p.u_index, p.v_index)).collect();
        assert_eq!(got, vec![(0, 0), (0, 1), (1, 1), (1, 2)]);
        let w: Vec<f64> = p.iter().map(|p| p.weight).collect();
        let want = [1.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 3.0];
        assert!(w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-15));
    }

    #[test]
    fn pieces_cover_unit_interval_and_are_symmetric() {
        for (n, m) in [(1, 1), (1, 5), (4, 6), (7, 3), (10, 10), (12, 8)] {
            let p = merged_pieces(n, m);
            let q = merged_pieces(m, n);
            assert!(p.len() < n + m);
            assert!((p.iter().map(|p| p.weight).sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(p
                .iter()
                .all(|p| (p.u_index as usize) < n && (p.v_index as usize) < m));
            for (a, b) in p.iter().zip(&q) {
                assert_eq!((a.u_index, a.v_index), (b.v_index, b.u_index));
                assert_eq!(a.weight, b.weight);
            }
        }
    }
}
