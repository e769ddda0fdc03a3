//! What the fuzz targets share: damage applied to valid files, so that mutations reach past
//! the headers into the parts a reader must check, and small volumes built from fuzzed input.

use arbitrary::Arbitrary;
use candle_core::{Device, Tensor};
use radiance_volume::{Aabb, GridDims, RadianceVolume};

/// Damage to a valid file: bytes flipped at chosen offsets, then optionally cut short.
#[derive(Arbitrary, Debug)]
pub struct Damage {
    /// (offset modulo the length, XOR mask) pairs.
    pub flips: Vec<(u32, u8)>,
    /// Keep only this many bytes (modulo the length + 1).
    pub truncate: Option<u32>,
}

impl Damage {
    /// Applies the damage to `bytes`.
    pub fn apply(&self, mut bytes: Vec<u8>) -> Vec<u8> {
        if !bytes.is_empty() {
            for &(at, mask) in &self.flips {
                let i = at as usize % bytes.len();
                bytes[i] ^= mask;
            }
        }
        if let Some(keep) = self.truncate {
            bytes.truncate(keep as usize % (bytes.len() + 1));
        }
        bytes
    }
}

/// A small volume (edges 1 to 8) to write and damage.
#[derive(Arbitrary, Debug)]
pub struct SmallVolume {
    pub dims: (u8, u8, u8),
    /// Cycled to fill the 4 channels.
    pub values: Vec<f32>,
}

impl SmallVolume {
    /// The volume with its values made finite and the density non-negative (what the writers
    /// accept), or `None` without values.
    pub fn build(&self) -> Option<RadianceVolume> {
        let dims = GridDims::new(
            usize::from(self.dims.0 % 8) + 1,
            usize::from(self.dims.1 % 8) + 1,
            usize::from(self.dims.2 % 8) + 1,
        );
        if self.values.is_empty() {
            return None;
        }
        let n = dims.voxel_count();
        let data: Vec<f32> = self
            .values
            .iter()
            .map(|v| {
                if v.is_finite() {
                    v.clamp(-1e4, 1e4)
                } else {
                    0.5
                }
            })
            .cycle()
            .take(4 * n)
            .enumerate()
            .map(|(i, v)| if i < n { v.abs() } else { v })
            .collect();
        let tensor = Tensor::from_vec(data, (4, dims.d, dims.h, dims.w), &Device::Cpu).ok()?;
        RadianceVolume::new(tensor, Aabb::CUBE).ok()
    }
}

/// Whether every element of an f32 tensor is finite.
pub fn all_finite(tensor: &Tensor) -> bool {
    let values: Vec<f32> = tensor.flatten_all().unwrap().to_vec1().unwrap();
    values.iter().all(|v| v.is_finite())
}

/// Asserts that a volume a reader accepted holds only finite values.
pub fn assert_finite(volume: &RadianceVolume, what: &str) {
    assert!(
        all_finite(volume.tensor()),
        "{what}: the reader accepted non-finite values"
    );
}

/// libFuzzer's panic hook aborts on every panic, also on those the code under test catches on
/// purpose: radiance-volume's VDB reader turns vdb-rs's panics on malformed files into errors
/// (`catch_unwind`). This hook only prints the message, so caught panics stay errors while an
/// uncaught one still reaches libfuzzer-sys, which aborts and records the input.
pub fn let_caught_panics_unwind() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        std::panic::set_hook(Box::new(|info| eprintln!("panic (caught or not): {info}")));
    });
}
