//! Shared test helpers: random volumes and the ray kinds the issue asks for.
#![allow(dead_code)] // each test binary uses a subset

use candle_core::{DType, Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use volrender::Rays;

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A `(4, d, h, w)` volume: density uniform in [0, max_sigma), colour in [0, 1).
pub fn random_volume(
    rng: &mut ChaCha8Rng,
    dims: [usize; 3],
    max_sigma: f64,
    dtype: DType,
) -> Tensor {
    let v = dims.iter().product::<usize>();
    let mut values: Vec<f64> = (0..v).map(|_| rng.random::<f64>() * max_sigma).collect();
    values.extend((0..3 * v).map(|_| rng.random::<f64>()));
    Tensor::from_vec(values, (4, dims[0], dims[1], dims[2]), &Device::Cpu)
        .and_then(|t| t.to_dtype(dtype))
        .unwrap()
}

/// A sparse volume: a few balls of density `sigma`, exactly 0 elsewhere, random colour.
pub fn sparse_volume(rng: &mut ChaCha8Rng, n: usize, balls: usize, sigma: f64) -> Tensor {
    let centres: Vec<([f64; 3], f64)> = (0..balls)
        .map(|_| {
            (
                [0; 3].map(|_| rng.random_range(-0.8..0.8)),
                rng.random_range(0.1..0.4),
            )
        })
        .collect();
    let v = n * n * n;
    let mut values = vec![0.0; 4 * v];
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = [x, y, z].map(|i| -1.0 + (i as f64 + 0.5) * 2.0 / n as f64);
                let i = (z * n + y) * n + x;
                if centres
                    .iter()
                    .any(|(c, r)| (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() < r * r)
                {
                    values[i] = sigma * rng.random_range(0.5..1.0);
                }
                for c in 1..4 {
                    values[c * v + i] = rng.random();
                }
            }
        }
    }
    Tensor::from_vec(values, (4, n, n, n), &Device::Cpu)
        .and_then(|t| t.to_dtype(DType::F32))
        .unwrap()
}

/// One ray of each kind: generic, axis-parallel, grazing a face, starting inside, missing,
/// touching a single edge point (zero length), plus `extra` generic ones.
pub fn mixed_rays(rng: &mut ChaCha8Rng, extra: usize) -> Rays {
    let mut o = Vec::new();
    let mut d = Vec::new();
    let generic = |rng: &mut ChaCha8Rng, o: &mut Vec<[f32; 3]>, d: &mut Vec<[f32; 3]>| {
        let from = [0; 3].map(|_| rng.random_range(-1.0f32..1.0));
        let len = (from.iter().map(|x| x * x).sum::<f32>()).sqrt().max(1e-3);
        let origin = from.map(|x| x / len * 3.0);
        let target = [0; 3].map(|_| rng.random_range(-0.8f32..0.8));
        o.push(origin);
        d.push([0, 1, 2].map(|k| target[k] - origin[k]));
    };
    generic(rng, &mut o, &mut d);
    // Axis-parallel.
    let a = rng.random_range(0..3);
    let mut origin = [0; 3].map(|_| rng.random_range(-0.9f32..0.9));
    origin[a] = -3.0;
    let mut dir = [0.0; 3];
    dir[a] = 1.0;
    o.push(origin);
    d.push(dir);
    // Grazing: along x in the face y = 1.
    o.push([-3.0, 1.0, rng.random_range(-0.9f32..0.9)]);
    d.push([1.0, 0.0, 0.0]);
    // Starting inside.
    o.push([0; 3].map(|_| rng.random_range(-0.9f32..0.9)));
    d.push([0; 3].map(|_| rng.random_range(-1.0f32..1.0)));
    // Missing the box.
    o.push([0.0, 0.0, 3.0]);
    d.push([1.0, 0.0, 0.2]);
    // Touching only the edge point (1, 1, 0.5): a zero-length segment.
    o.push([0.0, 2.0, 0.5]);
    d.push([1.0, -1.0, 0.0]);
    for _ in 0..extra {
        generic(rng, &mut o, &mut d);
    }
    Rays::new(o, d).unwrap()
}

/// Flattens a tensor to f64 values.
pub fn values(t: &Tensor) -> Vec<f64> {
    t.flatten_all()
        .and_then(|t| t.to_dtype(DType::F64))
        .and_then(|t| t.to_vec1())
        .unwrap()
}
