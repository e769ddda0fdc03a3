//! Small arbitrary volumes -> EXR slices -> read back -> compare (f32 exactly, f16 rounded).
//! Non-finite input must be refused, never written.
#![no_main]

use candle_core::{Device, Tensor};
use libfuzzer_sys::fuzz_target;
use radiance_volume::{Aabb, Error, GridDims, RadianceVolume};

fuzz_target!(|input: (u8, u8, u8, bool, Vec<f32>)| {
    let (d, h, w, half, values) = input;
    // Cap the size first: at most 6 slices of 16 x 16.
    let dims = GridDims::new(
        usize::from(d % 6) + 1,
        usize::from(h % 16) + 1,
        usize::from(w % 16) + 1,
    );
    if values.is_empty() {
        return;
    }
    let n = dims.voxel_count();
    let data: Vec<f32> = values.iter().copied().cycle().take(4 * n).collect();
    let t = Tensor::from_vec(data.clone(), (4, dims.d, dims.h, dims.w), &Device::Cpu).unwrap();
    let v = RadianceVolume::new(t, Aabb::CUBE).expect("a valid tensor");
    let dir = tempfile::tempdir().unwrap();
    match v.write_exr_slices().half(half).to_dir(dir.path(), "fuzz") {
        Ok(_) => {}
        Err(Error::NonFinite { .. }) => {
            assert!(data.iter().any(|x| !x.is_finite()));
            return;
        }
        Err(Error::InvalidArgument { what: "half", .. }) if half => return,
        Err(e) => panic!("unexpected export error: {e}"),
    }
    let back =
        RadianceVolume::read_exr_slices(dir.path(), "fuzz").expect("our own stack reads back");
    let got: Vec<f32> = back.tensor().flatten_all().unwrap().to_vec1().unwrap();
    for (g, x) in got.iter().zip(&data) {
        let want = if half {
            half::f16::from_f32(*x).to_f32()
        } else {
            *x
        };
        assert_eq!(
            g.to_bits(),
            want.to_bits(),
            "EXR stores the bits as they are"
        );
    }
});
