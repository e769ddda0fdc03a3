//! Dilation of boolean voxel masks: the cells within a margin of a marked one.

use rayon::prelude::*;

use crate::error::{invalid, Result};

/// `cells` (z-major `[d, h, w]`, as a volume's voxels) dilated by a cube of half-width `margin`:
/// a cell is marked when any cell within Chebyshev distance `margin` is. Three passes, one per
/// axis, each marking the cells within `margin` of a marked one along that axis (a cube is the
/// product of three segments, so this is exact at `3 (2 margin + 1)` reads per cell).
///
/// ```
/// // One marked voxel in the middle of a 5^3 grid, dilated by 1: the 3^3 cube around it.
/// let mut cells = vec![false; 125];
/// cells[2 * 25 + 2 * 5 + 2] = true;
/// let near = radiance_volume::dilate_mask(&cells, [5, 5, 5], 1)?;
/// assert_eq!(near.iter().filter(|&&c| c).count(), 27);
/// assert!(near[1 * 25 + 1 * 5 + 1] && !near[0]);
/// assert!(radiance_volume::dilate_mask(&cells, [5, 5, 4], 1).is_err());
/// # Ok::<(), radiance_volume::Error>(())
/// ```
pub fn dilate_mask(cells: &[bool], [d, h, w]: [usize; 3], margin: usize) -> Result<Vec<bool>> {
    if cells.len() != d * h * w {
        return Err(invalid(
            "cells",
            format!(
                "{} cells for a [{d}, {h}, {w}] grid of {}",
                cells.len(),
                d * h * w
            ),
        ));
    }
    let mut current = cells.to_vec();
    for (stride, len) in [(h * w, d), (w, h), (1, w)] {
        let mut next = vec![false; current.len()];
        next.par_iter_mut().enumerate().for_each(|(i, cell)| {
            let at = (i / stride) % len;
            let base = i - at * stride;
            let lo = at.saturating_sub(margin);
            let hi = (at + margin).min(len - 1);
            *cell = (lo..=hi).any(|j| current[base + j * stride]);
        });
        current = next;
    }
    Ok(current)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::dilate_mask as dilate;

    /// The same dilation by its definition: any marked cell within Chebyshev distance `margin`.
    fn dilate_by_definition(cells: &[bool], n: usize, margin: usize) -> Vec<bool> {
        let at = |i: usize| [i / (n * n), (i / n) % n, i % n];
        (0..cells.len())
            .map(|i| {
                (0..cells.len()).any(|j| {
                    cells[j]
                        && at(i)
                            .iter()
                            .zip(at(j))
                            .all(|(&a, b)| a.abs_diff(b) <= margin)
                })
            })
            .collect()
    }

    #[test]
    fn dilation_matches_its_definition_on_random_sets_and_at_the_faces() {
        let n = 6;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12345);
        for density in [0.0, 0.02, 0.1, 0.5, 1.0] {
            let cells: Vec<bool> = (0..n * n * n)
                .map(|_| rng.random::<f64>() < density)
                .collect();
            for margin in 0..4 {
                assert_eq!(
                    dilate(&cells, [n, n, n], margin).unwrap(),
                    dilate_by_definition(&cells, n, margin),
                    "density {density}, margin {margin}"
                );
            }
        }
    }
}
