//! Exports an example volume and runs the independent validators on it (Blender via bpy,
//! OpenVDB 10 and 12, OpenEXR and OpenImageIO; see `../shared/validators/README.md`).
//! Ignored by default because the validators are an optional ~1 GB install:
//!
//! ```sh
//! bash ../shared/validators/setup.sh
//! VALIDATORS_DIR=../shared/validators VOLGEN_EXPORT_DIR=/tmp/volgen-export \
//!   cargo test -p radiance-volume --features vdb,exr --test vdb_validators -- --ignored --nocapture
//! ```
//!
//! The files stay in `VOLGEN_EXPORT_DIR` (default: a fresh temporary directory) for inspection;
//! the volume is also saved there as `example.safetensors`, the input of `volgen export`.
#![cfg(all(feature = "vdb", feature = "exr"))]

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::Vec3;
use radiance_volume::{Aabb, GridDims, RadianceVolume};

/// A coloured smoke torus around the z axis, lying in a non-cubic box off the origin (so a
/// wrong axis order or transform shows up in the bounds check), on a 24 x 64 x 64 grid (cubic
/// voxels), or on 24 x 32 x 64 (non-uniform voxels) when `uniform` is false.
fn example_volume(uniform: bool) -> RadianceVolume {
    let aabb = Aabb::try_new(Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.75)).unwrap();
    let dims = GridDims::new(24, if uniform { 64 } else { 32 }, 64);
    RadianceVolume::from_fn(dims, aabb, 4, |p, out| {
        let ring = Vec3::new(p.x, p.y, 0.0).normalize_or_zero() * 0.6 + Vec3::new(0.0, 0.0, 0.35);
        let r = (p - ring).length();
        let wobble = 0.05 * (5.0 * p.x).sin() * (5.0 * p.y).cos();
        out[0] = (20.0 * (0.25 + wobble - r)).max(0.0);
        let hue = p.y.atan2(p.x) / std::f32::consts::TAU + 0.5;
        out[1] = 0.5 + 0.5 * (std::f32::consts::TAU * hue).cos();
        out[2] = 0.5 + 0.5 * (std::f32::consts::TAU * (hue - 1.0 / 3.0)).cos();
        out[3] = 0.5 + 0.5 * (std::f32::consts::TAU * (hue - 2.0 / 3.0)).cos();
    })
    .unwrap()
}

fn out_dir() -> (PathBuf, Option<tempfile::TempDir>) {
    match std::env::var_os("VOLGEN_EXPORT_DIR") {
        Some(d) => {
            std::fs::create_dir_all(&d).unwrap();
            (PathBuf::from(d), None)
        }
        None => {
            let t = tempfile::tempdir().unwrap();
            (t.path().to_path_buf(), Some(t))
        }
    }
}

fn run(script: &str, args: &[&str]) {
    let dir = std::env::var("VALIDATORS_DIR").expect("set VALIDATORS_DIR to ../shared/validators");
    let script = Path::new(&dir).join(script);
    println!("$ python3 {} {}", script.display(), args.join(" "));
    let status = Command::new("python3")
        .arg(&script)
        .args(args)
        .status()
        .unwrap();
    assert!(status.success(), "{} failed: {status}", script.display());
}

#[test]
#[ignore = "needs the validators (bash ../shared/validators/setup.sh)"]
fn blender_and_openvdb_open_the_export() {
    let (dir, _keep) = out_dir();
    let v = example_volume(true);
    v.save_safetensors(dir.join("example.safetensors")).unwrap();
    let non_uniform = example_volume(false);
    for (name, v, half, zlib) in [
        ("example", &v, false, false),
        ("example_zlib", &v, false, true),
        ("example_half", &v, true, false),
        ("example_half_zlib", &v, true, true),
        ("example_non_uniform", &non_uniform, false, false),
    ] {
        let path = dir.join(format!("{name}.vdb"));
        let stats = v.write_vdb().half(half).zlib(zlib).to_file(&path).unwrap();
        println!("{name}: {stats:?}");
        let png = dir.join(format!("{name}.png"));
        run(
            "check_vdb.py",
            &[
                path.to_str().unwrap(),
                "--png",
                png.to_str().unwrap(),
                "--require-visible",
                "--require-grid",
                "density",
                "--require-grid",
                "color",
            ],
        );
    }
}

#[test]
#[ignore = "needs the validators (bash ../shared/validators/setup.sh)"]
fn openexr_and_oiio_open_the_slices() {
    let (dir, _keep) = out_dir();
    let v = example_volume(true);
    for (name, half) in [("slices_f32", false), ("slices_f16", true)] {
        let slices = dir.join(name);
        v.write_exr_slices()
            .half(half)
            .to_dir(&slices, "example")
            .unwrap();
        run(
            "check_exr.py",
            &[
                slices.to_str().unwrap(),
                "--require-channels",
                "density,R,G,B",
                "--expect-slices",
                "24",
                "--expect-size",
                "64x64",
            ],
        );
    }
}

/// Files written by OpenVDB itself (Blosc-compressed, as its Python writer does by default) import
/// onto a grid whose cell centres are the file's voxel centres with the voxel values: the
/// sample is a soft sphere, density `1 - r` and colour `(1 - i/(n-1), k/(n-1), i/(n-1))`.
#[test]
#[ignore = "needs the validators (bash ../shared/validators/setup.sh)"]
fn openvdb_written_files_import() {
    let (dir, _keep) = out_dir();
    let (n, voxel) = (24usize, 0.05f32);
    for (color, half) in [("vec3", false), ("vec3", true), ("rgb", false)] {
        let path = dir.join(format!("openvdb_sample_{color}_{half}.vdb"));
        let mut args = vec![path.to_str().unwrap(), "--size", "24", "--color", color];
        if half {
            args.push("--half");
        }
        run("make_sample_vdb.py", &args);
        // Cell i of n over [-voxel/2, (n - 1/2) voxel] is centred on index i.
        let aabb = Aabb::try_new(
            Vec3::splat(-0.5 * voxel),
            Vec3::splat((n as f32 - 0.5) * voxel),
        );
        let grid = radiance_volume::VoxelGrid::new(aabb.unwrap(), GridDims::cube(n)).unwrap();
        let v = RadianceVolume::read_vdb(&path, &grid).unwrap();
        let vals: Vec<f32> = v.tensor().flatten_all().unwrap().to_vec1().unwrap();
        let tol = if half { 1e-3 } else { 1e-6 };
        let c = (n as f32 - 1.0) / 2.0;
        let m = n * n * n;
        let mut max_err = 0f32;
        for (k, j, i) in
            (0..n).flat_map(|k| (0..n).flat_map(move |j| (0..n).map(move |i| (k, j, i))))
        {
            let idx = (k * n + j) * n + i;
            let r = Vec3::new(i as f32 - c, j as f32 - c, k as f32 - c).length() / (n as f32 / 2.0);
            let density = (1.0 - r).clamp(0.0, 1.0);
            max_err = max_err.max((vals[idx] - density).abs());
            if density > 0.0 {
                let rgb = [
                    1.0 - i as f32 / (n as f32 - 1.0),
                    k as f32 / (n as f32 - 1.0),
                    i as f32 / (n as f32 - 1.0),
                ];
                for (ch, want) in rgb.iter().enumerate() {
                    max_err = max_err.max((vals[(ch + 1) * m + idx] - want).abs());
                }
            }
        }
        println!("{color} half={half}: max |imported - OpenVDB sample| = {max_err:e}");
        assert!(max_err <= tol, "{color} half={half}: {max_err}");
    }
}
