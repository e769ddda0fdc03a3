//! Volumes read block by block: a [`Resampled`] volume gives, block by block, exactly what it
//! gives whole, and what the differentiable tensor path computes; and every writer fed a
//! source writes the same file as when fed that volume whole (safetensors, which the
//! safetensors crate reads, and OpenVDB byte for byte, EXR slices value for value), through the blocks the streaming needs (several
//! 128^3 bricks of VDB leaves), and the same again when read in the thinnest slabs
//! ([`SlabLimit`]: one plane, or one layer of VDB leaves, at a time).

use candle_core::{Device, Tensor};
use glam::Vec3;
use radiance_volume::{
    io::write_safetensors, resample_tensor, Aabb, Activation, GridDims, RadianceVolume, Resampled,
    SlabLimit, VolumeSource, VoxelRange,
};

/// Raw density that crosses the activation's knee (a ball), colour and one feature varying
/// everywhere.
fn coarse(dims: GridDims) -> RadianceVolume {
    let aabb = Aabb::try_new(Vec3::new(-2.0, -1.0, 0.0), Vec3::new(2.0, 1.0, 1.5)).unwrap();
    RadianceVolume::from_fn(dims, aabb, 5, |p, out| {
        out[0] = 6.0 * (0.6 - (p - Vec3::new(0.3, 0.1, 0.7)).length()) - 1.0;
        out[1] = 0.5 + 0.4 * (3.0 * p.x).sin();
        out[2] = 0.5 + 0.4 * (2.0 * p.y).cos();
        out[3] = 0.2 + 0.1 * p.z;
        out[4] = p.x * p.y - p.z;
    })
    .unwrap()
    .with_channel_names(["sigma", "r", "g", "b", "albedo"])
    .unwrap()
}

fn activation() -> Activation {
    Activation::default()
        .with_density_scale(25.0)
        .with_density_shift(-4.0)
}

fn values(v: &RadianceVolume) -> Vec<f32> {
    v.tensor().flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn blocks_equal_the_whole_and_the_tensor_path() {
    let v = coarse(GridDims::new(5, 7, 6));
    let fine = Resampled::finer(v.clone(), 3)
        .unwrap()
        .with_density_activation(activation());
    let d = fine.dims();
    assert_eq!(d, GridDims::new(15, 21, 18));
    let whole = fine.to_volume().unwrap();
    assert_eq!(whole.channel_names(), v.channel_names());
    assert_eq!(whole.aabb(), v.aabb());

    // The tensor path: trilinear resampling of the whole volume, then density activated.
    let resampled = resample_tensor(v.tensor(), d).unwrap();
    let sigma = activation()
        .apply_density(&resampled.narrow(0, 0, 1).unwrap())
        .unwrap();
    let want = Tensor::cat(&[&sigma, &resampled.narrow(0, 1, 4).unwrap()], 0).unwrap();
    let want: Vec<f32> = want.flatten_all().unwrap().to_vec1().unwrap();
    // Bit for bit: on the CPU both lerp along x, then y, then z.
    assert_eq!(values(&whole), want);

    // Blocks of every shape and place, any channel range, against the whole.
    let whole_values = values(&whole);
    for (channels, region) in [
        (0..5, VoxelRange::all(d)),
        (
            0..1,
            VoxelRange {
                z: 3..4,
                y: 0..21,
                x: 5..6,
            },
        ),
        (
            1..4,
            VoxelRange {
                z: 14..15,
                y: 20..21,
                x: 0..18,
            },
        ),
        (
            2..5,
            VoxelRange {
                z: 0..7,
                y: 4..13,
                x: 9..17,
            },
        ),
        (
            0..3,
            VoxelRange {
                z: 1..15,
                y: 1..2,
                x: 17..18,
            },
        ),
    ] {
        let block = fine.read_block(channels.clone(), &region).unwrap();
        let mut want = Vec::new();
        for c in channels {
            for z in region.z.clone() {
                for y in region.y.clone() {
                    for x in region.x.clone() {
                        want.push(whole_values[c * d.voxel_count() + d.index(z, y, x)]);
                    }
                }
            }
        }
        assert_eq!(block, want, "{region:?}");
    }
    assert!(fine
        .read_block(
            0..1,
            &VoxelRange {
                z: 0..16,
                y: 0..1,
                x: 0..1
            }
        )
        .is_err());
    assert!(fine.read_block(5..6, &VoxelRange::all(d)).is_err());

    // At the volume's own size nothing is interpolated: the values are copied bit for bit.
    let same = Resampled::new(v.clone(), v.dims())
        .unwrap()
        .to_volume()
        .unwrap();
    assert_eq!(values(&same), values(&v));
}

#[test]
fn streamed_safetensors_are_the_safetensors_crates_bytes() {
    let fine = Resampled::finer(coarse(GridDims::new(3, 4, 5)), 3)
        .unwrap()
        .with_density_activation(activation());
    let whole = fine.to_volume().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fine.safetensors");
    write_safetensors(&fine, &path).unwrap();
    let written = std::fs::read(&path).unwrap();

    // The safetensors crate reads the whole volume's values, little-endian, in its shape.
    let bytes: Vec<u8> = values(&whole)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let d = whole.dims();
    let parsed = safetensors::SafeTensors::deserialize(&written).unwrap();
    let tensor = parsed.tensor("volume").unwrap();
    assert_eq!(tensor.dtype(), safetensors::Dtype::F32);
    assert_eq!(tensor.shape(), &[5, d.d, d.h, d.w]);
    assert!(tensor.data() == &bytes[..]);
    // The same bytes whatever wrote them: the whole volume, or the source a plane at a time.
    assert!(whole.to_safetensors_bytes().unwrap() == written);
    let thin = dir.path().join("thin.safetensors");
    write_safetensors(&SlabLimit::new(&fine, 1), &thin).unwrap();
    assert!(std::fs::read(&thin).unwrap() == written);

    let back = RadianceVolume::load_safetensors(&path).unwrap();
    assert_eq!(values(&back), values(&whole));
    assert_eq!(back.channel_names(), whole.channel_names());
    assert_eq!(back.aabb(), whole.aabb());
}

#[cfg(feature = "vdb")]
#[test]
fn streamed_vdb_is_the_whole_volumes_file() {
    use std::io::Cursor;
    // 140 voxels along x and 135 along y: leaves in four 128^3 bricks.
    let fine = Resampled::finer(coarse(GridDims::new(4, 45, 28)), 5)
        .unwrap()
        .with_density_activation(activation());
    let whole = fine.to_volume().unwrap();
    assert_eq!(whole.dims(), GridDims::new(20, 225, 140));
    let dir = tempfile::tempdir().unwrap();
    for (half, zlib, threshold) in [(false, false, 0.5), (true, true, 0.5), (false, true, 0.0)] {
        let path = dir.path().join("fine.vdb");
        let stats = radiance_volume::io::VdbWriter::new(&fine)
            .half(half)
            .zlib(zlib)
            .threshold(threshold)
            .feature_grids(true)
            .to_file(&path)
            .unwrap();
        let streamed = std::fs::read(&path).unwrap();
        let mut in_memory = Vec::new();
        let stats_whole = whole
            .write_vdb()
            .half(half)
            .zlib(zlib)
            .threshold(threshold)
            .feature_grids(true)
            .to_writer(&mut in_memory)
            .unwrap();
        assert_eq!(stats, stats_whole);
        assert_eq!(stats.bytes, streamed.len() as u64);
        assert!(streamed == in_memory, "half {half} zlib {zlib}");
        let mut thin = Vec::new();
        radiance_volume::io::VdbWriter::new(&SlabLimit::new(&fine, 1))
            .half(half)
            .zlib(zlib)
            .threshold(threshold)
            .feature_grids(true)
            .to_writer(&mut thin)
            .unwrap();
        assert!(thin == in_memory, "thin slabs, half {half} zlib {zlib}");
        // An independent reader finds each grid where the offsets say, with the values of the
        // whole volume at exactly the voxels above the threshold.
        let mut reader = vdb_rs::VdbReader::new(Cursor::new(&streamed)).unwrap();
        let d = whole.dims();
        let all = values(&whole);
        for (name, c) in [("density", 0), ("albedo", 4)] {
            let grid = reader.read_grid::<f32>(name).unwrap();
            let mut active = 0;
            for (p, got, _) in grid.iter() {
                let i = d.index(p.z as usize, p.y as usize, p.x as usize);
                let want = all[c * d.voxel_count() + i];
                let want = if half {
                    half::f16::from_f32(want).to_f32()
                } else {
                    want
                };
                assert!(
                    all[i] > threshold && got == want,
                    "{name} at {p:?}: {got} vs {want}"
                );
                active += 1;
            }
            let above = all[..d.voxel_count()]
                .iter()
                .filter(|&&s| s > threshold)
                .count();
            assert_eq!(active, above, "{name}");
        }
    }
}

#[cfg(feature = "exr")]
#[test]
fn streamed_exr_slices_hold_the_whole_volume() {
    let fine = Resampled::finer(coarse(GridDims::new(3, 5, 4)), 3)
        .unwrap()
        .with_density_activation(activation());
    let dir = tempfile::tempdir().unwrap();
    radiance_volume::io::ExrSlicesWriter::new(&fine)
        .to_dir(dir.path(), "fine")
        .unwrap();
    let back = RadianceVolume::read_exr_slices(dir.path(), "fine").unwrap();
    assert_eq!(values(&back), values(&fine.to_volume().unwrap()));
    assert_eq!(back.channel_names(), fine.channel_names());
}

#[test]
fn sources_report_non_finite_values_with_their_place() {
    let mut data = vec![0.5f32; 4 * 2 * 3 * 4];
    data[24 + 13] = f32::NAN; // channel 1, voxel (d=1, h=0, w=1)
    data[2 * 24 + 2] = f32::NAN; // channel 2, in an earlier plane
    data[3 * 24 + 2] = f32::INFINITY;
    let t = Tensor::from_vec(data, (4, 2, 3, 4), &Device::Cpu).unwrap();
    let v = RadianceVolume::new(t, Aabb::CUBE).unwrap();
    // Read whole or a plane at a time, the first is the first in channel order.
    for source in [&v as &dyn VolumeSource, &SlabLimit::new(&v, 1)] {
        match source.check_finite_channels("volume", 0..4).unwrap_err() {
            radiance_volume::Error::NonFinite { count, first, .. } => {
                assert_eq!(count, 3);
                assert!(
                    first.contains("channel 1 (r)") && first.contains("(d=1, h=0, w=1)"),
                    "{first}"
                );
            }
            other => panic!("expected NonFinite, got {other}"),
        }
    }
    assert!(v.check_finite_channels("volume", 0..1).is_ok());
}
