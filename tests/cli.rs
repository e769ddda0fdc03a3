//! The `volgen` binary end to end: info, export and render on a small volume, and clear errors.

use std::path::Path;
use std::process::{Command, Stdio};

use radiance_volume::{Aabb, GridDims, RadianceVolume};

mod common;
use common::volgen;

fn small_volume(dir: &Path) -> String {
    let v = RadianceVolume::from_fn(GridDims::new(12, 16, 20), Aabb::CUBE, 4, |p, o| {
        o[0] = if p.length() < 0.5 { 8.0 } else { 0.0 };
        o[1..4].copy_from_slice(&[0.9, 0.4, 0.1]);
    })
    .unwrap();
    let path = dir.join("ball.safetensors");
    v.save_safetensors(&path).unwrap();
    path.to_string_lossy().into_owned()
}

/// Piped into a reader that stops early (`volgen info FILE | head -3`), a command stops quietly:
/// no panic, no "Broken pipe", whatever it was printing.
#[test]
fn a_closed_pipe_ends_a_command_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let vol = small_volume(dir.path());
    for args in [
        vec!["info", vol.as_str()],
        vec!["help", "train"],
        vec!["--help"],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_volgen"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The reader is gone before the first line comes.
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !err.contains("panicked") && !err.contains("Broken pipe"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn info_export_and_render_write_what_they_say() {
    let dir = tempfile::tempdir().unwrap();
    let vol = small_volume(dir.path());

    let out = volgen(&["info", &vol]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("12 x 16 x 20") && text.contains("sigma"),
        "{text}"
    );

    let vdb = dir.path().join("ball.vdb");
    let slices = dir.path().join("slices");
    let out = volgen(&[
        "export",
        &vol,
        "--vdb",
        vdb.to_str().unwrap(),
        "--exr-slices",
        slices.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let original = RadianceVolume::load_safetensors(&vol).unwrap();
    let back = RadianceVolume::read_vdb(&vdb, original.grid()).unwrap();
    let diff = (back.density().unwrap() - original.density().unwrap())
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap();
    assert!(diff.to_scalar::<f32>().unwrap() < 1e-6);
    let stack = RadianceVolume::read_exr_slices(&slices, "ball").unwrap();
    assert_eq!(stack.dims(), original.dims());

    let cameras = dir.path().join("transforms.json");
    std::fs::write(
        &cameras,
        r#"{"camera_angle_x": 0.6, "frames": [{"file_path": "./r_0.png",
            "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#,
    )
    .unwrap();
    let renders = dir.path().join("renders");
    let out = volgen(&[
        "render",
        &vol,
        "--cameras",
        cameras.to_str().unwrap(),
        "--width",
        "16",
        "--height",
        "12",
        "--samples",
        "32",
        "--out",
        renders.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(renders.join("r_0.exr").is_file() && renders.join("r_0.png").is_file());
}

/// The first primitive of the first mesh of a glTF document: the one mesh volgen writes.
fn first_primitive(document: &gltf::Document) -> gltf::Primitive<'_> {
    document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap()
}

#[test]
fn mesh_writes_each_format_and_refuses_bad_input_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let vol = small_volume(dir.path());
    for extension in ["glb", "gltf", "ply", "obj"] {
        let file = dir.path().join("meshes").join(format!("ball.{extension}"));
        let text = common::ok(&volgen(&["mesh", &vol, "--out", common::path(&file)]));
        assert!(
            text.contains("closed") && text.contains(common::path(&file)),
            "{text}"
        );
        let bytes = std::fs::read(&file).unwrap();
        let magic: &[u8] = match extension {
            "glb" => b"glTF",
            "gltf" => b"{",
            "ply" => b"ply\n",
            _ => b"# written by volgen",
        };
        assert!(bytes.starts_with(magic), "{extension}");
    }
    // The glTF as an independent reader sees it: a ball of radius 0.5 (y up in the file).
    let (document, buffers, _) = gltf::import(dir.path().join("meshes/ball.glb")).unwrap();
    let primitive = first_primitive(&document);
    let positions: Vec<[f32; 3]> = primitive
        .reader(|b| Some(&buffers[b.index()]))
        .read_positions()
        .unwrap()
        .collect();
    assert!(positions.len() > 100);
    for p in &positions {
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((r - 0.5).abs() < 0.15, "{p:?}");
    }
    // Decimated to a quarter and smoothed: a quarter of the triangles, read back by the same
    // reader, still on the ball.
    let light = dir.path().join("light.glb");
    let text = common::ok(&volgen(&[
        "mesh",
        &vol,
        "--out",
        common::path(&light),
        "--smooth",
        "3",
        "--decimate",
        "0.25",
    ]));
    assert!(text.contains("closed"), "{text}");
    let (document, _, _) = gltf::import(&light).unwrap();
    let triangles =
        |document: &gltf::Document| first_primitive(document).indices().unwrap().count() / 3;
    let full = triangles(&gltf::import(dir.path().join("meshes/ball.glb")).unwrap().0);
    let quarter = triangles(&document);
    assert!(
        quarter <= full / 4 + 2 && quarter >= full / 8,
        "{full} -> {quarter}"
    );
    for bad in ["0", "1.5", "x"] {
        let err = common::failure(&volgen(&[
            "mesh",
            &vol,
            "--out",
            common::path(&light),
            "--decimate",
            bad,
        ]));
        assert!(
            err.contains("--decimate") && err.contains("(0, 1]"),
            "{err}"
        );
    }
    let out = dir.path().join("ball.stl");
    let err = common::failure(&volgen(&["mesh", &vol, "--out", common::path(&out)]));
    assert!(err.contains("ball.stl") && err.contains(".glb"), "{err}");
    let glb = dir.path().join("x.glb");
    let err = common::failure(&volgen(&[
        "mesh",
        &vol,
        "--out",
        common::path(&glb),
        "--level",
        "1",
    ]));
    assert!(err.contains("--level"), "{err}");
    let empty = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |_, _| {}).unwrap();
    let empty_path = dir.path().join("empty.safetensors");
    empty.save_safetensors(&empty_path).unwrap();
    let err = common::failure(&volgen(&[
        "mesh",
        common::path(&empty_path),
        "--out",
        common::path(&glb),
    ]));
    assert!(
        err.contains("no surface") && err.contains("empty.safetensors"),
        "{err}"
    );
    assert!(!glb.exists());
}

#[test]
fn bad_input_is_a_clear_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.safetensors");
    let out = volgen(&["info", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("missing.safetensors") && !err.contains("panicked"),
        "{err}"
    );

    let vol = small_volume(dir.path());
    let out = volgen(&["export", &vol]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing to export"));

    let out = volgen(&[
        "export",
        &vol,
        "--vdb",
        dir.path().join("no/dir/x.vdb").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no/dir/x.vdb"));
}

/// The 4x4 (column vectors) that a VDB file's transform maps index to world by, read from its
/// bytes as OpenVDB lays them out: an `AffineMap`'s 16 doubles (row-major for row vectors), or a
/// `ScaleTranslateMap`'s translation and scale.
fn vdb_index_to_world(bytes: &[u8]) -> glam::DMat4 {
    let doubles = |at: usize, n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| f64::from_le_bytes(bytes[at + 8 * i..at + 8 * i + 8].try_into().unwrap()))
            .collect()
    };
    let find = |name: &[u8]| bytes.windows(name.len()).position(|w| w == name);
    if let Some(at) = find(b"AffineMap") {
        return glam::DMat4::from_cols_array(&doubles(at + 9, 16).try_into().unwrap());
    }
    let at = find(b"ScaleTranslateMap").unwrap() + "ScaleTranslateMap".len();
    let v = doubles(at, 6);
    glam::DMat4::from_translation(glam::DVec3::new(v[0], v[1], v[2]))
        * glam::DMat4::from_scale(glam::DVec3::new(v[3], v[4], v[5]))
}

#[test]
fn export_and_mesh_take_volumes_back_to_the_capture_frame() {
    use glam::{DMat4, DQuat, DVec3};
    let dir = tempfile::tempdir().unwrap();
    let vol = small_volume(dir.path());
    // An imported dataset's record: the capture's frame halved, turned and moved.
    let to_dataset = DMat4::from_scale_rotation_translation(
        DVec3::splat(0.5),
        DQuat::from_rotation_z(1.2),
        DVec3::new(1.0, 2.0, 3.0),
    );
    let rows: Vec<[f64; 4]> = (0..4).map(|r| to_dataset.row(r).to_array()).collect();
    let dataset = dir.path().join("imported");
    std::fs::create_dir_all(&dataset).unwrap();
    let record = serde_json::json!({"frames": [], "volgen_import": {"capture_to_dataset": rows}});
    std::fs::write(dataset.join("transforms.json"), record.to_string()).unwrap();
    let to_capture = to_dataset.inverse();

    let (plain, placed) = (dir.path().join("plain.vdb"), dir.path().join("placed.vdb"));
    common::ok(&volgen(&["export", &vol, "--vdb", common::path(&plain)]));
    let text = common::ok(&volgen(&[
        "export",
        &vol,
        "--vdb",
        common::path(&placed),
        "--to-capture",
        common::path(&dataset),
    ]));
    assert!(
        text.contains("a unit of the dataset is 2.0000 there"),
        "{text}"
    );
    // The placed file's index -> world map is the plain one's followed by the way back.
    let plain_map = vdb_index_to_world(&std::fs::read(&plain).unwrap());
    let placed_map = vdb_index_to_world(&std::fs::read(&placed).unwrap());
    for index in [DVec3::ZERO, DVec3::X, DVec3::new(3.0, 5.0, 7.0)] {
        let expected = to_capture.transform_point3(plain_map.transform_point3(index));
        let got = placed_map.transform_point3(index);
        assert!(
            (got - expected).length() < 1e-9,
            "{index}: {got} vs {expected}"
        );
    }

    // The mesh, read by the glTF crate: the ball of radius 0.5 at the origin is one of radius
    // 1 (the capture's units are half the dataset's) around where the origin goes back to.
    let glb = dir.path().join("ball.glb");
    common::ok(&volgen(&[
        "mesh",
        &vol,
        "--out",
        common::path(&glb),
        "--to-capture",
        common::path(&dataset),
    ]));
    let (document, buffers, _) = gltf::import(&glb).unwrap();
    let positions: Vec<DVec3> = first_primitive(&document)
        .reader(|b| Some(&buffers[b.index()]))
        .read_positions()
        .unwrap()
        .map(|p| DVec3::from(p.map(f64::from)))
        .collect();
    let centre = positions.iter().sum::<DVec3>() / positions.len() as f64;
    // glTF turns z-up into y-up, a rotation: distances from the origin survive it.
    let origin_back = to_capture.transform_point3(DVec3::ZERO);
    assert!(
        (centre.length() - origin_back.length()).abs() < 0.05,
        "{centre} {origin_back}"
    );
    for p in &positions {
        assert!(((*p - centre).length() - 1.0).abs() < 0.3, "{p}");
    }

    // A dataset without the record, and EXR slices (axis-aligned), are refused by name.
    let plain_data = dir.path().join("plain_data");
    std::fs::create_dir_all(&plain_data).unwrap();
    std::fs::write(plain_data.join("transforms.json"), r#"{"frames": []}"#).unwrap();
    let err = common::failure(&volgen(&[
        "mesh",
        &vol,
        "--out",
        common::path(&glb),
        "--to-capture",
        common::path(&plain_data),
    ]));
    assert!(
        err.contains("volgen_import.capture_to_dataset") && err.contains("transforms.json"),
        "{err}"
    );
    let err = common::failure(&volgen(&[
        "export",
        &vol,
        "--exr-slices",
        common::path(&dir.path().join("slices")),
        "--to-capture",
        common::path(&dataset),
    ]));
    assert!(err.contains("--to-capture") && err.contains("EXR"), "{err}");
}
