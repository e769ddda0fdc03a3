//! EXR slice stacks read back by the exr crate and by `read_exr_slices`: exact f32, half within
//! half precision, the documented pixel layout and sidecar, and the error paths.
#![cfg(feature = "exr")]

use candle_core::{Device, Tensor};
use glam::Vec3;
use half::f16;
use radiance_volume::{Aabb, Error, GridDims, RadianceVolume};

fn volume(dims: GridDims) -> RadianceVolume {
    let aabb = Aabb::try_new(Vec3::new(-1.0, -2.0, 0.0), Vec3::new(1.0, 2.0, 0.5)).unwrap();
    RadianceVolume::from_fn(dims, aabb, 5, |p, out| {
        out.copy_from_slice(&[
            (p.x + p.y * 3.0 + p.z * 7.0).abs(),
            0.5 + 0.4 * p.x.sin(),
            0.3,
            0.123_456_78 * p.y,
            -2.5 * p.z,
        ]);
    })
    .unwrap()
    .with_channel_names(["sigma", "r", "g", "b", "emission"])
    .unwrap()
}

fn values(v: &RadianceVolume) -> Vec<f32> {
    v.tensor().flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn f32_stack_round_trips_exactly_and_has_the_documented_layout() {
    let dims = GridDims::new(3, 4, 5);
    let v = volume(dims);
    let dir = tempfile::tempdir().unwrap();
    let files = v.write_exr_slices().to_dir(dir.path(), "vol").unwrap();
    assert_eq!(files.len(), 4);
    let back = RadianceVolume::read_exr_slices(dir.path(), "vol").unwrap();
    assert_eq!(values(&back), values(&v));
    assert_eq!(back.channel_names(), v.channel_names());
    assert_eq!(back.aabb(), v.aabb());

    // Read one slice with the exr crate alone: channel names, and the top row is the largest y.
    let image =
        exr::prelude::read_all_flat_layers_from_file(dir.path().join("vol.0002.exr")).unwrap();
    let layer = &image.layer_data[0];
    let mut names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    names.sort();
    assert_eq!(names, ["B", "G", "R", "density", "emission"]);
    let density = layer
        .channel_data
        .list
        .iter()
        .find(|c| c.name.to_string() == "density")
        .unwrap();
    let samples: Vec<f32> = density.sample_data.values_as_f32().collect();
    let vals = values(&v);
    // Pixel (column 1, row 0) is voxel (d=2, h=3, w=1).
    assert_eq!(samples[1], vals[dims.index(2, 3, 1)]);

    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("vol.json")).unwrap()).unwrap();
    assert_eq!(sidecar["format"], "volgen.exr-slices");
    assert_eq!(sidecar["resolution"]["d"], 3);
    assert_eq!(sidecar["files"], "vol.%04d.exr");
    assert_eq!(sidecar["channels"][0]["exr"], "density");
    assert_eq!(sidecar["channels"][4]["exr"], "emission");
}

#[test]
fn half_stack_is_within_half_precision() {
    let v = volume(GridDims::new(2, 3, 4));
    let dir = tempfile::tempdir().unwrap();
    v.write_exr_slices()
        .half(true)
        .to_dir(dir.path(), "h")
        .unwrap();
    let back = RadianceVolume::read_exr_slices(dir.path(), "h").unwrap();
    for (a, b) in values(&v).iter().zip(values(&back)) {
        assert_eq!(b, f16::from_f32(*a).to_f32());
    }
}

#[test]
fn non_finite_values_fail_unless_replaced_and_leave_no_files() {
    let dims = GridDims::new(2, 2, 2);
    let mut vals = vec![0.25f32; 4 * dims.voxel_count()];
    vals[5] = f32::NEG_INFINITY;
    let t = Tensor::from_vec(vals, (4, 2, 2, 2), &Device::Cpu).unwrap();
    let v = RadianceVolume::new(t, Aabb::CUBE).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let err = v.write_exr_slices().to_dir(dir.path(), "nf").unwrap_err();
    assert!(matches!(err, Error::NonFinite { count: 1, .. }), "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    v.write_exr_slices()
        .replace_non_finite(Some(0.0))
        .to_dir(dir.path(), "nf")
        .unwrap();
    let back = RadianceVolume::read_exr_slices(dir.path(), "nf").unwrap();
    assert_eq!(values(&back)[5], 0.0);
}

#[test]
fn unwritable_directory_and_missing_slices_are_errors() {
    let v = volume(GridDims::new(2, 2, 2));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    assert!(matches!(
        v.write_exr_slices().to_dir(file.join("sub"), "v"),
        Err(Error::Io { .. })
    ));
    v.write_exr_slices().to_dir(dir.path(), "v").unwrap();
    std::fs::remove_file(dir.path().join("v.0001.exr")).unwrap();
    let err = RadianceVolume::read_exr_slices(dir.path(), "v").unwrap_err();
    assert!(err.to_string().contains("v.0001.exr"), "{err}");
    assert!(v.write_exr_slices().to_dir(dir.path(), "a/b").is_err());
}

#[test]
fn a_re_export_that_fails_part_way_leaves_no_stack_the_reader_accepts() {
    let dims = GridDims::new(3, 2, 2);
    let dir = tempfile::tempdir().unwrap();
    volume(dims)
        .write_exr_slices()
        .to_dir(dir.path(), "v")
        .unwrap();
    // A second export over it fails at slice 1 (its name is taken by a directory): the old
    // sidecar must not survive to describe a mix of old and new slices.
    let blocked = dir.path().join("v.0001.exr");
    std::fs::remove_file(&blocked).unwrap();
    std::fs::create_dir(&blocked).unwrap();
    let t = Tensor::from_vec(
        vec![0.5f32; 4 * dims.voxel_count()],
        (4, 3, 2, 2),
        &Device::Cpu,
    )
    .unwrap();
    let other = RadianceVolume::new(t, Aabb::CUBE).unwrap();
    assert!(other.write_exr_slices().to_dir(dir.path(), "v").is_err());
    let err = RadianceVolume::read_exr_slices(dir.path(), "v").unwrap_err();
    assert!(err.to_string().contains("v.json"), "{err}");
}

/// Found by fuzzing (`fuzz/fuzz_targets/exr_slices_read.rs`): a slice whose header claims a
/// huge data window made the reader allocate it (6.6 GB) before finding the pixels missing.
/// The header is now checked against the sidecar first.
#[test]
fn a_slice_header_claiming_a_huge_image_is_refused_before_reading_pixels() {
    let dir = tempfile::tempdir().unwrap();
    volume(GridDims::new(2, 2, 2))
        .write_exr_slices()
        .to_dir(dir.path(), "v")
        .unwrap();
    let path = dir.path().join("v.0000.exr");
    let mut bytes = std::fs::read(&path).unwrap();
    // The dataWindow attribute: name, type, size (16), then xMin, yMin, xMax, yMax as i32.
    let key = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(key.len())
        .position(|w| w == key)
        .expect("a dataWindow attribute")
        + key.len()
        + 4;
    for (i, value) in [0i32, 0, 60_000, 60_000].iter().enumerate() {
        bytes[at + 4 * i..at + 4 * i + 4].copy_from_slice(&value.to_le_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    let err = RadianceVolume::read_exr_slices(dir.path(), "v").unwrap_err();
    assert!(err.to_string().contains("v.0000.exr"), "{err}");
}
