//! Safetensors round trips bit-exactly; foreign, truncated and mismatched files give errors
//! that name the file and the field.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use glam::Vec3;
use radiance_volume::{Aabb, Error, GridDims, RadianceVolume};
use safetensors::{tensor::TensorView, Dtype};

fn sample_volume() -> RadianceVolume {
    RadianceVolume::from_fn(
        GridDims::new(3, 5, 7),
        Aabb::try_new(Vec3::new(-2.0, 0.0, 1.0), Vec3::new(2.0, 1.0, 3.0)).unwrap(),
        6,
        |p, out| {
            for (c, o) in out.iter_mut().enumerate() {
                // Awkward values: subnormals, negative zero, large magnitudes.
                *o = (p.x * 1e-39 + p.y * 3.3e7 - p.z) * (c as f32 + 1.0) - 0.0;
            }
        },
    )
    .unwrap()
    .with_channel_names(["sigma", "r", "g", "b", "label", "albedo_w"])
    .unwrap()
}

fn bits(v: &RadianceVolume) -> Vec<u32> {
    let vals: Vec<f32> = v.tensor().flatten_all().unwrap().to_vec1().unwrap();
    vals.iter().map(|x| x.to_bits()).collect()
}

/// Writes a safetensors file with the given tensors (name, dtype, shape, bytes) and metadata.
fn write_raw(
    path: &Path,
    tensors: &[(&str, Dtype, Vec<usize>, Vec<u8>)],
    meta: Option<HashMap<String, String>>,
) {
    let views: Vec<(&str, TensorView)> = tensors
        .iter()
        .map(|(n, dt, s, b)| (*n, TensorView::new(*dt, s.clone(), b).unwrap()))
        .collect();
    std::fs::write(path, safetensors::serialize(views, meta).unwrap()).unwrap();
}

fn f32_bytes(n: usize, value: f32) -> Vec<u8> {
    std::iter::repeat_n(value.to_le_bytes(), n)
        .flatten()
        .collect()
}

fn error_text(path: &Path) -> String {
    let err = RadianceVolume::load_safetensors(path).expect_err("must fail");
    err.to_string()
}

#[test]
fn round_trip_is_bit_exact_with_box_and_names() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.safetensors");
    let v = sample_volume();
    v.save_safetensors(&path).unwrap();
    let back = RadianceVolume::load_safetensors(&path).unwrap();
    assert_eq!(bits(&back), bits(&v));
    assert_eq!(back.aabb(), v.aabb());
    assert_eq!(back.dims(), v.dims());
    assert_eq!(back.channel_names(), v.channel_names());
    // No temporary file is left beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn a_bare_tensor_loads_with_the_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("numpy.safetensors");
    write_raw(
        &path,
        &[("volume", Dtype::F32, vec![4, 2, 2, 2], f32_bytes(32, 0.5))],
        None,
    );
    let v = RadianceVolume::load_safetensors(&path).unwrap();
    assert_eq!(v.aabb(), Aabb::CUBE);
    assert_eq!(v.channel_names(), ["sigma", "r", "g", "b"]);
    assert_eq!(v.sample(Vec3::ZERO).unwrap(), vec![0.5; 4]);
}

#[test]
fn foreign_and_broken_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);

    std::fs::write(p("text.safetensors"), b"hello, I am not a tensor file").unwrap();
    let e = error_text(&p("text.safetensors"));
    assert!(
        e.contains("text.safetensors") && e.contains("not a readable safetensors"),
        "{e}"
    );

    let good = sample_volume().to_safetensors_bytes().unwrap();
    std::fs::write(p("cut.safetensors"), &good[..good.len() - 10]).unwrap();
    let e = error_text(&p("cut.safetensors"));
    assert!(e.contains("cut.safetensors"), "{e}");

    write_raw(
        &p("named.safetensors"),
        &[("weights", Dtype::F32, vec![4, 1, 1, 1], f32_bytes(4, 0.0))],
        None,
    );
    let e = error_text(&p("named.safetensors"));
    assert!(
        e.contains("no tensor named `volume`") && e.contains("weights"),
        "{e}"
    );

    write_raw(
        &p("f64.safetensors"),
        &[("volume", Dtype::F64, vec![4, 1, 1, 1], vec![0u8; 32])],
        None,
    );
    let e = error_text(&p("f64.safetensors"));
    assert!(e.contains("F64") && e.contains("F32"), "{e}");

    write_raw(
        &p("rank3.safetensors"),
        &[("volume", Dtype::F32, vec![4, 2, 2], f32_bytes(16, 0.0))],
        None,
    );
    assert!(error_text(&p("rank3.safetensors")).contains("[4, 2, 2]"));

    write_raw(
        &p("c3.safetensors"),
        &[("volume", Dtype::F32, vec![3, 1, 1, 1], f32_bytes(3, 0.0))],
        None,
    );
    assert!(error_text(&p("c3.safetensors")).contains("C >= 4"));

    let mut values = f32_bytes(32, 0.0);
    values[4 * 9..4 * 10].copy_from_slice(&f32::NAN.to_le_bytes());
    values[4 * 30..4 * 31].copy_from_slice(&f32::INFINITY.to_le_bytes());
    write_raw(
        &p("nan.safetensors"),
        &[("volume", Dtype::F32, vec![4, 2, 2, 2], values)],
        None,
    );
    let err = RadianceVolume::load_safetensors(p("nan.safetensors")).unwrap_err();
    match &err {
        Error::NonFinite { count, first, .. } => {
            assert_eq!(*count, 2);
            assert!(
                first.contains("channel 1 (r)") && first.contains("(d=0, h=0, w=1)"),
                "{first}"
            );
        }
        other => panic!("expected NonFinite, got {other}"),
    }

    let bad_meta = |k: &str, v: &str| Some(HashMap::from([(k.to_string(), v.to_string())]));
    for (key, value, needle) in [
        ("aabb", "[0, 0, 0, 1, 1]", "`aabb`"),
        ("aabb", "[1, 0, 0, 0, 1, 1]", "`aabb`"),
        ("aabb", "not json", "`aabb`"),
        ("channels", "[\"a\", \"b\"]", "`channels`"),
        ("channels", "[\"a\", \"a\", \"b\", \"c\"]", "duplicate"),
        ("format", "something.else", "`format`"),
        ("format_version", "99", "`format_version`"),
    ] {
        let name = format!("meta-{key}.safetensors");
        write_raw(
            &p(&name),
            &[("volume", Dtype::F32, vec![4, 1, 1, 1], f32_bytes(4, 0.0))],
            bad_meta(key, value),
        );
        let e = error_text(&p(&name));
        assert!(
            e.contains(&name) && e.contains(needle),
            "{key}={value}: {e}"
        );
    }

    let e = RadianceVolume::load_safetensors(p("missing.safetensors"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.safetensors"), "{e}");
}

#[test]
fn saving_into_a_missing_directory_fails_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/dir/v.safetensors");
    let err = sample_volume().save_safetensors(&path).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn tensors_on_the_cpu_are_converted_to_f32() {
    let t = Tensor::ones((4, 2, 2, 2), candle_core::DType::F64, &Device::Cpu).unwrap();
    let v = RadianceVolume::new(t, Aabb::CUBE).unwrap();
    assert_eq!(v.tensor().dtype(), candle_core::DType::F32);
}
