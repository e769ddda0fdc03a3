//! Small arbitrary volumes and options -> our VDB writer -> our reader (vdb-rs underneath) ->
//! compare: active voxels (density > threshold) keep their values (f32 exactly, f16 rounded),
//! the rest read back as the background 0. Non-finite input must be refused, never written.
#![no_main]

use candle_core::{Device, Tensor};
use libfuzzer_sys::fuzz_target;
use radiance_volume::{Aabb, Error, GridDims, RadianceVolume};

fuzz_target!(|input: (u8, u8, u8, bool, bool, u8, Vec<f32>)| {
    volgen_fuzz::let_caught_panics_unwind();
    let (d, h, w, half, zlib, threshold, values) = input;
    // Cap the size first: at most 20^3 voxels.
    let dims = GridDims::new(
        usize::from(d % 20) + 1,
        usize::from(h % 20) + 1,
        usize::from(w % 20) + 1,
    );
    if values.is_empty() {
        return;
    }
    let n = dims.voxel_count();
    let data: Vec<f32> = values.iter().copied().cycle().take(4 * n).collect();
    let Ok(t) = Tensor::from_vec(data.clone(), (4, dims.d, dims.h, dims.w), &Device::Cpu) else {
        return;
    };
    let v = RadianceVolume::new(t, Aabb::CUBE).expect("a valid tensor");
    let threshold = f32::from(threshold) / 16.0;
    let mut bytes = Vec::new();
    match v
        .write_vdb()
        .half(half)
        .zlib(zlib)
        .threshold(threshold)
        .to_writer(&mut bytes)
    {
        Ok(_) => {}
        Err(Error::NonFinite { .. }) => {
            assert!(data.iter().any(|x| !x.is_finite()));
            return;
        }
        // Values beyond the half range are refused in half mode.
        Err(Error::InvalidArgument { what: "half", .. }) if half => return,
        Err(e) => panic!("unexpected export error: {e}"),
    }
    let back = RadianceVolume::read_vdb_bytes(bytes, v.grid(), "fuzz.vdb".as_ref())
        .expect("our own file reads back");
    let got: Vec<f32> = back.tensor().flatten_all().unwrap().to_vec1().unwrap();
    let round = |x: f32| {
        if half {
            half::f16::from_f32(x).to_f32()
        } else {
            x
        }
    };
    for i in 0..n {
        let active = data[i] > threshold;
        for c in 0..4 {
            let want = if active { round(data[c * n + i]) } else { 0.0 };
            // Compared as numbers: the reader sums weighted corners, which turns -0 into +0.
            assert_eq!(got[c * n + i], want, "channel {c} voxel {i}");
        }
    }
});
