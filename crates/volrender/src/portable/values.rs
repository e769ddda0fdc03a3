//! The kernel's value rules checked with tensor ops on the volume's device: density finite and
//! not negative (raw density, when post-activated, and colours: at most 1e10 in magnitude, which
//! also refuses NaN and infinities). One reduction per call; the first bad value is looked up on
//! the host only when there is one.

use candle_core::{DType, Device, Tensor};
use radiance_volume::GridDims;

use crate::config::MAX_VOLUME_VALUE;
use crate::error::Result;
use crate::op::invalid_volume;

/// Refuses `volume` `(C, D, H, W)` (volume `batch_index` of its batch) if any of its first 4 channels breaks the rules, with the
/// kernel's error (count, first bad value, rule).
pub(super) fn check(
    volume: &Tensor,
    batch_index: usize,
    dims: GridDims,
    raw_density: bool,
) -> Result<()> {
    let base = volume.narrow(0, 0, 4)?.reshape((4, dims.voxel_count()))?;
    // `<=` is false for NaN, so NaN fails every rule.
    let bounded = base.abs()?.le(f64::from(MAX_VOLUME_VALUE))?;
    let ok = if raw_density {
        bounded
    } else {
        let density = base.narrow(0, 0, 1)?;
        // Finite: at most the dtype's largest value in magnitude (false for NaN).
        let largest = if density.dtype() == DType::F32 {
            f64::from(f32::MAX)
        } else {
            f64::MAX
        };
        let finite = density.abs()?.le(largest)?;
        let density_ok = (density.ge(0.0)? * finite)?;
        Tensor::cat(&[density_ok, bounded.narrow(0, 1, 3)?], 0)?
    };
    let good = ok.to_dtype(DType::U32)?.sum_all()?.to_scalar::<u32>()? as usize;
    let count = 4 * dims.voxel_count() - good;
    if count == 0 {
        return Ok(());
    }
    let ok = ok.to_device(&Device::Cpu)?.to_vec2::<u8>()?;
    let (c, i) = (0..dims.voxel_count())
        .find_map(|i| (0..4).find(|&c| ok[c][i] == 0).map(|c| (c, i)))
        .unwrap_or((0, 0));
    let value = base
        .to_device(&Device::Cpu)?
        .to_dtype(DType::F64)?
        .get(c)?
        .get(i)?
        .to_scalar::<f64>()?;
    Err(invalid_volume(
        count,
        batch_index,
        c,
        i,
        dims,
        value,
        raw_density,
    ))
}
