//! Painted test volumes shared by the unit tests of the layout metrics.

use candle_core::{Device, Tensor};

use crate::LayoutPoints;

/// A `(4, 1, n, n)` slab, one voxel deep (every voxel weighs alike): each cell's colour from
/// `paint`, density 40 where it gives one.
pub fn slab(n: usize, paint: impl Fn(usize, usize) -> Option<[f32; 3]>) -> LayoutPoints {
    let cells = n * n;
    let mut v = vec![0f32; 4 * cells];
    for y in 0..n {
        for x in 0..n {
            if let Some(rgb) = paint(x, y) {
                let i = y * n + x;
                v[i] = 40.0;
                for c in 0..3 {
                    v[(c + 1) * cells + i] = rgb[c];
                }
            }
        }
    }
    let volume = Tensor::from_vec(v, (4, 1, n, n), &Device::Cpu).unwrap();
    LayoutPoints::from_volume(&volume, 0.1).unwrap()
}
