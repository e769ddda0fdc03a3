//! `volgen demo`, `train` and `sample` end to end with the `micro` preset: the files they promise
//! exist and load, VDB files read back through vdb-rs, a killed-free resume is a no-op, and bad
//! input is a clear error.

use std::path::Path;

use radiance_volume::RadianceVolume;

mod common;
use common::{assert_vdb_matches, failure, ok, path, train_micro, volgen};

#[test]
fn demo_writes_dataset_model_samples_pictures_and_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let args = [
        "demo",
        "--out",
        path(&out),
        "--preset",
        "micro",
        "--views",
        "6",
        "--resolution",
        "36",
        "--count",
        "2",
    ];
    let text = ok(&volgen(&args));
    assert!(
        text.contains("overview.png") && text.contains("summary.md"),
        "{text}"
    );
    assert!(text.contains("generated in"), "{text}");
    for file in [
        "dataset/transforms.json",
        "run/checkpoint.safetensors",
        "run/config.json",
        "run/log.jsonl",
        "run/samples/scale_3.png",
        "samples/scene_0.safetensors",
        "samples/scene_1.png",
        "summary.md",
        "summary.json",
    ] {
        assert!(out.join(file).is_file(), "missing {file}");
    }
    // The overview: one row of input views and one per scene, three views each.
    let overview = image::open(out.join("overview.png")).unwrap();
    assert!(overview.height() > overview.width() / 3 * 2 / 3);
    // The VDB export reads back through an independent reader and matches the volume.
    let volume = RadianceVolume::load_safetensors(out.join("samples/scene_0.safetensors")).unwrap();
    assert_vdb_matches(&volume, &out.join("samples/scene_0.vdb"));
    // So do its EXR slices (one per z slice, full floats), read back with the exr crate.
    let slices =
        RadianceVolume::read_exr_slices(out.join("samples/scene_0_exr"), "scene_0").unwrap();
    assert_eq!(slices.dims(), volume.dims());
    let largest_difference = (slices.tensor() - volume.tensor())
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert_eq!(largest_difference, 0.0, "full-float slices are exact");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["scale_seconds"].as_array().unwrap().len(), 3);

    // summary.md: the losses as a table (not raw JSON) and links to the turntables, which are
    // 36-frame orbits at the samples' size. A loss the run never computed has no column (micro
    // has no height profile, nor a 3D critic).
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains(
            "| scale | seconds | peak MiB | iterations | critic loss | gradient penalty | \
             adversarial loss | RGB reconstruction | depth reconstruction | SWD texture loss | \
             opacity reconstruction | colour distribution |\n"
        ),
        "{md}"
    );
    assert!(!md.contains("{\""), "raw JSON in {md}");
    let last = summary["final_losses"][2].clone();
    let row = md
        .lines()
        .find(|l| l.starts_with("| 3 |"))
        .unwrap_or_else(|| panic!("no scale 3 row in {md}"));
    let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
    // micro: 4 iterations; the upsampler has no depth, opacity or colour-distribution term
    // but an SWD loss.
    assert_eq!(cells[3], "4", "{row}");
    assert_eq!([cells[8], cells[10], cells[11]], ["-", "-", "-"], "{row}");
    assert_eq!(
        cells[9],
        format!("{:.4}", last["swd"].as_f64().unwrap()),
        "{row}"
    );
    assert!(
        md.contains("[scene_0](samples/scene_0.gif), [scene_1](samples/scene_1.gif)"),
        "{md}"
    );
    assert_eq!(gif_frames(&out.join("samples/scene_1.gif")), (36, 36, 36));

    // Sampling the trained run again with the same seed gives the same scenes.
    let again = tmp.path().join("again");
    let text = ok(&volgen(&[
        "sample",
        path(&out.join("run")),
        "--count",
        "2",
        "--out",
        path(&again),
        "--exr-slices",
    ]));
    assert!(text.contains("scene 1: generated in"), "{text}");
    let a = RadianceVolume::load_safetensors(again.join("scene_0.safetensors")).unwrap();
    assert!(again.join("scene_0_exr").is_dir());
    let values =
        |v: &RadianceVolume| -> Vec<f32> { v.tensor().flatten_all().unwrap().to_vec1().unwrap() };
    assert_eq!(
        values(&a),
        values(&volume),
        "same model, same seed, same scene"
    );

    // --upsample K writes the same scene on a grid K times finer (K odd), in every format;
    // VDB read back by vdb-rs. Even factors are refused by name.
    let fine_dir = tmp.path().join("fine");
    let sample_fine = |factor: &str| {
        volgen(&[
            "sample",
            path(&out.join("run")),
            "--count",
            "1",
            "--out",
            path(&fine_dir),
            "--vdb",
            "--upsample",
            factor,
        ])
    };
    ok(&sample_fine("3"));
    let fine = RadianceVolume::load_safetensors(fine_dir.join("scene_0.safetensors")).unwrap();
    let coarse = volume.dims();
    assert_eq!(
        [fine.dims().d, fine.dims().h, fine.dims().w],
        [3 * coarse.d, 3 * coarse.h, 3 * coarse.w]
    );
    assert_eq!(fine.aabb(), volume.aabb());
    assert_vdb_matches(&fine, &fine_dir.join("scene_0.vdb"));
    let err = failure(&sample_fine("2"));
    assert!(err.contains("--upsample") && err.contains("odd"), "{err}");

    // A finished run resumes as a no-op; training it afresh is refused rather than overwritten.
    let dataset = out.join("dataset");
    let run = out.join("run");
    ok(&volgen(&[
        "train",
        path(&dataset),
        "--out",
        path(&run),
        "--preset",
        "micro",
        "--resume",
    ]));
    let refused = volgen(&[
        "train",
        path(&dataset),
        "--out",
        path(&run),
        "--preset",
        "micro",
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--resume"));
}

#[test]
fn train_and_sample_report_bad_input_clearly() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = volgen(&[
        "train",
        path(&tmp.path().join("nowhere")),
        "--out",
        path(tmp.path()),
    ]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains("nowhere") && !err.contains("panicked"),
        "{err}"
    );

    let preset = volgen(&[
        "train",
        path(tmp.path()),
        "--out",
        path(tmp.path()),
        "--preset",
        "huge",
    ]);
    let err = String::from_utf8_lossy(&preset.stderr);
    assert!(err.contains("huge") && err.contains("tiny"), "{err}");

    let no_model = volgen(&[
        "sample",
        path(tmp.path()),
        "--out",
        path(&tmp.path().join("s")),
    ]);
    let err = String::from_utf8_lossy(&no_model.stderr);
    assert!(
        !no_model.status.success() && err.contains("checkpoint"),
        "{err}"
    );
}

#[test]
fn train_refuses_unknown_depth_and_takes_the_depth_kind_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = (tmp.path().join("data"), tmp.path().join("run"));
    ok(&volgen(&[
        "scene",
        "stones",
        "--out",
        path(&data),
        "--views",
        "3",
        "--resolution",
        "16",
        "--grid",
        "16",
    ]));
    // A foreign dataset that does not say how its depth is measured.
    let transforms = data.join("transforms.json");
    let text = std::fs::read_to_string(&transforms).unwrap();
    let mut root: serde_json::Value = serde_json::from_str(&text).unwrap();
    root.as_object_mut().unwrap().remove("depth_kind");
    std::fs::write(&transforms, root.to_string()).unwrap();
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train",
            path(&data),
            "--out",
            path(&run),
            "--preset",
            "micro",
        ];
        args.extend_from_slice(extra);
        volgen(&args)
    };
    let err = failure(&train(&[]));
    assert!(
        err.contains("transforms.json")
            && err.contains("depth_kind")
            && err.contains("--depth-kind"),
        "{err}"
    );
    let err = failure(&train(&["--depth-kind", "planar"]));
    assert!(err.contains("planar") && err.contains("\"z\""), "{err}");
    ok(&train(&["--depth-kind", "expected", "--iterations", "2"]));
    assert!(run.join("checkpoint.safetensors").is_file());

    // Photos without depth maps (what `volgen import colmap` writes): training goes without
    // the depth loss and the critics' depth channel, and says so; eval has no depth RMSE.
    for frame in root["frames"].as_array_mut().unwrap() {
        frame.as_object_mut().unwrap().remove("depth_file_path");
    }
    root["depth_kind"] = "none".into();
    std::fs::write(&transforms, root.to_string()).unwrap();
    std::fs::remove_dir_all(data.join("depth")).unwrap();
    std::fs::remove_dir_all(&run).unwrap();
    let out = train(&["--iterations", "2"]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && said.contains("no depth maps"),
        "{said}"
    );
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["ablations"]["use_depth"], false);
    let text = ok(&volgen(&[
        "eval",
        path(&run),
        "--dataset",
        path(&data),
        "--scenes",
        "2",
        "--views",
        "2",
        "--layout-reference",
        "vstar",
    ]));
    assert!(text.contains("reconstruction_depth_rmse: none"), "{text}");
    // Depth from a fit of the views instead: recorded, and trained with the depth loss.
    std::fs::remove_dir_all(&run).unwrap();
    let out = train(&[
        "--iterations",
        "2",
        "--depth-from-fit",
        "--depth-fit-steps",
        "30",
    ]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && said.contains("depth from the fit") && said.contains("left out"),
        "{said}"
    );
    assert!(run.join("depth_fit.safetensors").is_file());
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["ablations"]["use_depth"], true);
    assert_eq!(config["run"]["depth_from_fit"], true);
    // `import colmap` names what is missing.
    let err = failure(&volgen(&[
        "import",
        "colmap",
        path(&tmp.path().join("sparse")),
        "--images",
        path(&data),
        "--out",
        path(&tmp.path().join("imported")),
    ]));
    assert!(
        err.contains("cameras.txt") && err.contains("missing"),
        "{err}"
    );
    // So does `import nerfstudio`: this capture names no sparse points.
    let err = failure(&volgen(&[
        "import",
        "nerfstudio",
        path(&data),
        "--out",
        path(&tmp.path().join("imported")),
    ]));
    assert!(
        err.contains("transforms.json")
            && err.contains("ply_file_path")
            && err.contains("--points"),
        "{err}"
    );
}

#[test]
fn bounds_are_recorded_and_samples_land_in_the_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = (tmp.path().join("data"), tmp.path().join("run"));
    ok(&volgen(&[
        "scene",
        "stones",
        "--out",
        path(&data),
        "--views",
        "3",
        "--resolution",
        "16",
        "--grid",
        "16",
    ]));
    let train = |bounds: &str| {
        volgen(&[
            "train",
            path(&data),
            "--out",
            path(&run),
            "--preset",
            "micro",
            "--iterations",
            "2",
            "--bounds",
            bounds,
        ])
    };
    let err = failure(&train("-5,-5,-5,5,5,5"));
    assert!(err.contains("inside the box"), "{err}");
    let err = failure(&train("0,0,0,1,1"));
    assert!(
        err.contains("--bounds") && err.contains("6 numbers"),
        "{err}"
    );
    let text = ok(&train("auto"));
    assert!(text.contains("scene bounds"), "{text}");
    std::fs::remove_dir_all(&run).unwrap();

    // A box of half side 1.5 centred at z = -0.5: the model's cube is [-1.5, 1.5]^2 x [-2, 1].
    ok(&train("-1.5,-1.5,-2,1.5,1.5,1"));
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(
        config["run"]["bounds"]["min"],
        serde_json::json!([-1.5, -1.5, -2.0])
    );
    let samples = tmp.path().join("samples");
    ok(&volgen(&[
        "sample",
        path(&run),
        "--out",
        path(&samples),
        "--count",
        "1",
        "--vdb",
    ]));
    let volume = RadianceVolume::load_safetensors(samples.join("scene_0.safetensors")).unwrap();
    let aabb = volume.aabb();
    assert_eq!(aabb.min.to_array(), [-1.5, -1.5, -2.0]);
    assert_eq!(aabb.max.to_array(), [1.5, 1.5, 1.0]);
    let from_vdb = RadianceVolume::read_vdb(samples.join("scene_0.vdb"), volume.grid()).unwrap();
    assert_eq!(from_vdb.aabb(), aabb);
    // Twice as wide, in the scene's coordinates: the cube grown about its centre along x.
    let wide = tmp.path().join("wide");
    ok(&volgen(&[
        "sample",
        path(&run),
        "--out",
        path(&wide),
        "--count",
        "1",
        "--extent",
        "2,1,1",
    ]));
    let grown = RadianceVolume::load_safetensors(wide.join("scene_0.safetensors")).unwrap();
    assert_eq!(grown.aabb().min.to_array(), [-3.0, -1.5, -2.0]);
    assert_eq!(grown.aabb().max.to_array(), [3.0, 1.5, 1.0]);

    // Edit boxes are in the scene's coordinates too: this one is the cube's lower quarter in
    // x and y, and one reaching z = 1.5 leaves the cube.
    let edit = |remove: &str| {
        volgen(&[
            "edit",
            path(&run),
            "--out",
            path(&tmp.path().join("edit")),
            "--no-harmonize",
            "--remove",
            remove,
        ])
    };
    ok(&edit("-1.5,-1.5,-2,0,0,1"));
    let err = failure(&edit("-1,-1,-1,1,1,1.5"));
    assert!(err.contains("remove"), "{err}");
}

#[test]
fn scene_writes_a_loadable_dataset_and_rejects_unknown_names() {
    let tmp = tempfile::tempdir().unwrap();
    // Every built-in scene, from the one list of them.
    for name in rgbd_dataset::scenes::SceneKind::ALL.map(|kind| kind.name()) {
        let dir = tmp.path().join(name);
        let text = ok(&volgen(&[
            "scene",
            name,
            "--out",
            path(&dir),
            "--views",
            "4",
            "--resolution",
            "16",
            "--grid",
            "24",
        ]));
        assert!(
            text.contains("wrote 4 views") && text.contains("transforms.json"),
            "{text}"
        );
        let data = rgbd_dataset::Dataset::load(&dir, [1.0; 3]).unwrap();
        assert_eq!((data.len(), data.width(), data.height()), (4, 16, 16));
    }
    let bad = volgen(&["scene", "volcano", "--out", path(tmp.path())]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("volcano")
            && rgbd_dataset::scenes::SceneKind::ALL
                .iter()
                .all(|kind| err.contains(kind.name())),
        "{err}"
    );
}

/// A `micro` model trained once for the application tests (under cargo's per-target scratch
/// directory, replaced on every run of this test binary).
fn trained_micro() -> &'static Path {
    static RUN: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    RUN.get_or_init(|| {
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_singrav_micro");
        let _ = std::fs::remove_dir_all(&root);
        train_micro(&root).1
    })
}

/// Every value of a volume file, channel-major.
fn volume_values(file: &Path) -> Vec<f32> {
    let volume = RadianceVolume::load_safetensors(file).unwrap();
    volume.tensor().flatten_all().unwrap().to_vec1().unwrap()
}

/// The frame count and the first frame's width and height of an animated GIF.
fn gif_frames(file: &Path) -> (usize, u32, u32) {
    use image::AnimationDecoder;
    let reader = std::io::BufReader::new(std::fs::File::open(file).unwrap());
    let frames = image::codecs::gif::GifDecoder::new(reader)
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap();
    let (w, h) = frames[0].buffer().dimensions();
    (frames.len(), w, h)
}

fn mean_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32
}

#[test]
fn animate_writes_frames_that_move_a_little_and_repeat_with_the_seed() {
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    let animate = |dir: &Path| {
        ok(&volgen(&[
            "animate",
            path(model),
            "--frames",
            "3",
            "--seed",
            "7",
            "--out",
            path(dir),
        ]))
    };
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let text = animate(&a);
    assert!(text.contains("frame 2: generated in"), "{text}");
    for t in 0..3 {
        for ext in ["safetensors", "png"] {
            assert!(
                a.join(format!("frame_{t:04}.{ext}")).is_file(),
                "frame {t} {ext}"
            );
        }
    }
    assert!(!a.join("frame_0003.safetensors").exists());

    // Consecutive frames differ, but far less than two independent scenes do.
    let frames: Vec<Vec<f32>> = (0..3)
        .map(|t| volume_values(&a.join(format!("frame_{t:04}.safetensors"))))
        .collect();
    let samples = tmp.path().join("samples");
    ok(&volgen(&[
        "sample",
        path(model),
        "--count",
        "2",
        "--seed",
        "7",
        "--out",
        path(&samples),
    ]));
    let scene = |i: usize| volume_values(&samples.join(format!("scene_{i}.safetensors")));
    let independent = mean_abs_diff(&scene(0), &scene(1));
    for t in 0..2 {
        let step = mean_abs_diff(&frames[t], &frames[t + 1]);
        assert!(
            step > 0.0 && step < 0.5 * independent,
            "{step} vs {independent}"
        );
    }
    // The first frame is the scene `sample` makes with the same seed.
    assert_eq!(frames[0], scene(0));

    // The same seed writes the same volumes and pictures. (The bytes of a safetensors file
    // can differ: its header's metadata order follows a HashMap.)
    animate(&b);
    for t in 0..3 {
        let volume = format!("frame_{t:04}.safetensors");
        assert_eq!(
            volume_values(&a.join(&volume)),
            volume_values(&b.join(&volume))
        );
        let picture = format!("frame_{t:04}.png");
        assert_eq!(
            std::fs::read(a.join(&picture)).unwrap(),
            std::fs::read(b.join(&picture)).unwrap(),
            "{picture}"
        );
    }
}

#[test]
fn edit_removal_empties_the_box_and_keeps_the_rest() {
    let model = trained_micro();
    let out = tempfile::tempdir().unwrap();
    let dir = out.path();
    let text = ok(&volgen(&[
        "edit",
        path(model),
        "--seed",
        "3",
        "--out",
        path(dir),
        "--remove",
        "-0.5,-0.5,-1,0.5,0.5,0.2",
    ]));
    assert!(text.contains("remove -0.5,-0.5,-1,0.5,0.5,0.2"), "{text}");
    for stem in ["original", "edited", "harmonized"] {
        assert!(dir.join(format!("{stem}.png")).is_file(), "{stem}.png");
    }
    let original = RadianceVolume::load_safetensors(dir.join("original.safetensors")).unwrap();
    let edited = RadianceVolume::load_safetensors(dir.join("edited.safetensors")).unwrap();
    let grid = *original.grid();
    let (before, after) = (
        volume_values(&dir.join("original.safetensors")),
        volume_values(&dir.join("edited.safetensors")),
    );
    let (lo, hi) = (
        glam::Vec3::new(-0.5, -0.5, -1.0),
        glam::Vec3::new(0.5, 0.5, 0.2),
    );
    let (mut inside, mut far) = (0, 0);
    let dims = grid.dims;
    for z in 0..dims.d {
        for y in 0..dims.h {
            for x in 0..dims.w {
                let p = grid.cell_center(z, y, x);
                // Distance outside the box (0 inside), per axis, then the largest.
                let gap = (lo - p).max(p - hi).max(glam::Vec3::ZERO).max_element();
                let i = dims.index(z, y, x);
                if p.cmpge(lo).all() && p.cmple(hi).all() {
                    inside += 1;
                    assert!(after[i] < 1e-3, "density {} left at {p}", after[i]);
                } else if gap > 0.3 {
                    far += 1;
                    let voxels = dims.voxel_count();
                    for c in 0..4 {
                        let j = c * voxels + i;
                        assert_eq!(before[j], after[j], "channel {c} changed at {p}");
                    }
                }
            }
        }
    }
    assert!(inside > 0 && far > 0, "{inside} cells inside, {far} far");
    let max_inside_before = before[..dims.voxel_count()]
        .iter()
        .enumerate()
        .filter(|&(i, _)| {
            let p = grid.cell_center(i / (dims.h * dims.w), (i / dims.w) % dims.h, i % dims.w);
            p.cmpge(lo).all() && p.cmple(hi).all()
        })
        .map(|(_, v)| *v)
        .fold(0f32, f32::max);
    assert!(max_inside_before > 1e-2, "nothing was there to remove");
    assert_eq!(edited.dims(), original.dims());

    // Duplicate and move together, without harmonisation.
    let both = tempfile::tempdir().unwrap();
    let text = ok(&volgen(&[
        "edit",
        path(model),
        "--out",
        path(both.path()),
        "--duplicate",
        "-0.8,-0.8,-0.8,-0.2,-0.2,-0.2",
        "--to",
        "1,1,1",
        "--move",
        "0.2,-0.8,-0.8,0.8,-0.2,-0.2",
        "--by",
        "-1,0,0",
        "--no-harmonize",
    ]));
    assert!(
        text.contains("duplicate") && text.contains("move"),
        "{text}"
    );
    assert!(both.path().join("edited.safetensors").is_file());
    assert!(!both.path().join("harmonized.safetensors").exists());
}

/// `volgen compose`: each taken box holds exactly the source scene's voxels at its new place
/// (the scene `volgen sample --seed` makes first, as `edit` writes it as `original`), the rest
/// is the base's; without `--base` the base is V*'s ground; bad takes are refused by name.
#[test]
fn compose_puts_boxes_of_other_scenes_into_a_base_and_names_bad_takes() {
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    // The sources as `edit` writes them: seed 5's and seed 6's scenes, unharmonised.
    for seed in ["5", "6"] {
        let dir = tmp.path().join(format!("scene{seed}"));
        ok(&volgen(&[
            "edit",
            path(model),
            "--seed",
            seed,
            "--out",
            path(&dir),
            "--remove",
            "0.9,0.9,0.9,1,1,1",
            "--no-harmonize",
        ]));
    }
    let out = tmp.path().join("composed");
    let text = ok(&volgen(&[
        "compose",
        path(model),
        "--out",
        path(&out),
        "--base",
        "6",
        "--take",
        "5:-1,-1,-1,-0.1,-0.1,-0.1",
        "--at",
        "1.09,1.09,0",
        "--take",
        "6:0.1,0.1,0.1,1,1,1",
        "--at",
        "-1.09,-1.09,-1.09",
    ]));
    assert!(
        text.contains("seed 5: -1,-1,-1,-0.1,-0.1,-0.1 at 1.09,1.09,0"),
        "{text}"
    );
    for stem in ["base", "composed", "harmonized"] {
        assert!(out.join(format!("{stem}.png")).is_file(), "{stem}.png");
    }
    let original =
        |seed: &str| volume_values(&tmp.path().join(format!("scene{seed}/original.safetensors")));
    let (five, six) = (original("5"), original("6"));
    assert_eq!(volume_values(&out.join("base.safetensors")), six);
    let composed = volume_values(&out.join("composed.safetensors"));
    let grid = *RadianceVolume::load_safetensors(out.join("base.safetensors"))
        .unwrap()
        .grid();
    let dims = grid.dims;
    // micro's 11^3 grid: cell centres below -0.1 are cells 0..5, above 0.1 cells 6..11, and
    // 1.09 is 5.995 voxels of 2/11: the takes move by 6 cells.
    assert_eq!(dims.w, 11);
    let n = dims.voxel_count();
    let (low, high) = (0..5, 6..11);
    for z in 0..dims.d {
        for y in 0..dims.h {
            for x in 0..dims.w {
                let i = dims.index(z, y, x);
                // The first take lands at high x and y, low z, from seed 5's low corner; the
                // second at the low corner, from seed 6's high one.
                let want = if high.contains(&x) && high.contains(&y) && low.contains(&z) {
                    Some((&five, dims.index(z, y - 6, x - 6)))
                } else if low.contains(&x) && low.contains(&y) && low.contains(&z) {
                    Some((&six, dims.index(z + 6, y + 6, x + 6)))
                } else {
                    None
                };
                for c in 0..4 {
                    let expected = match want {
                        Some((source, j)) => source[c * n + j],
                        None => six[c * n + i],
                    };
                    assert_eq!(composed[c * n + i], expected, "({x}, {y}, {z}) channel {c}");
                }
            }
        }
    }

    // Without --base: V*'s ground, never denser than V* itself.
    let ground = tmp.path().join("ground");
    let text = ok(&volgen(&[
        "compose",
        path(model),
        "--out",
        path(&ground),
        "--take",
        "5:-0.5,-0.5,-1,0.5,0.5,1",
        "--at",
        "0,0,0",
        "--no-harmonize",
    ]));
    assert!(text.contains("the ground of V*"), "{text}");
    assert!(!ground.join("harmonized.safetensors").exists());

    let compose = |extra: &[&str]| {
        let mut args = vec!["compose", path(model), "--out", path(&ground)];
        args.extend_from_slice(extra);
        failure(&volgen(&args))
    };
    let cases: [(&[&str], &[&str]); 5] = [
        (&[], &["nothing to compose"]),
        (
            &["--take", "0,0,0,1,1,1", "--at", "0,0,0"],
            &["--take", "SEED:"],
        ),
        (
            &["--take", "1:0,0,0,0.5,0.5,0.5", "--at", "0.8,0,0"],
            &["placement `0,0,0,0.5,0.5,0.5 at 0.8,0,0`", "destination"],
        ),
        (&["--take", "1:0,0,0,0.5,0.5,0.5"], &["--at"]),
        (
            &[
                "--take",
                "1:0,0,0,0.5,0.5,0.5",
                "--at",
                "0,0",
                "--base",
                "2",
            ],
            &["--at", "three comma-separated numbers"],
        ),
    ];
    for (args, expected) in cases {
        let err = compose(args);
        for needle in expected {
            assert!(err.contains(needle), "{args:?}: {err}");
        }
    }
}

#[test]
fn animate_and_edit_name_the_bad_flag() {
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    let out = path(tmp.path());
    let edit = |extra: &[&str]| {
        let mut args = vec!["edit", path(model), "--out", out];
        args.extend_from_slice(extra);
        failure(&volgen(&args))
    };
    let cases: [(&[&str], &[&str]); 8] = [
        (
            &["--remove", "1,2,3"],
            &[
                "--remove",
                "expected six comma-separated numbers x0,y0,z0,x1,y1,z1",
                "1,2,3",
            ],
        ),
        (
            &["--remove", "0,0,0,1,x,1"],
            &["--remove", "six comma-separated"],
        ),
        (&["--remove", "0.5,0,0,0,1,1"], &["--remove", "empty"]),
        (
            &["--remove", "0,0,0,2,1,1"],
            &["remove 0,0,0,2,1,1", "inside the volume box [-1, 1]^3"],
        ),
        (
            &["--move", "0,0,0,0.5,0.5,0.5", "--by", "1,2"],
            &["--by", "three comma-separated numbers dx,dy,dz"],
        ),
        (
            &["--duplicate", "0,0,0,0.5,0.5,0.5", "--to", "0.8,0,0"],
            &["duplicate", "destination", "inside the volume box"],
        ),
        (
            &["--harmonize-from", "7", "--remove", "0,0,0,0.5,0.5,0.5"],
            &["--harmonize-from", "7"],
        ),
        (&[], &["nothing to edit"]),
    ];
    for (args, expected) in cases {
        let err = edit(args);
        for needle in expected {
            assert!(err.contains(needle), "{args:?}: {err}");
        }
    }
    let missing_to = edit(&["--duplicate", "0,0,0,0.5,0.5,0.5"]);
    assert!(missing_to.contains("--to"), "{missing_to}");

    let animate = |extra: &[&str]| {
        let mut args = vec!["animate", path(model), "--out", out];
        args.extend_from_slice(extra);
        failure(&volgen(&args))
    };
    let err = animate(&["--anchor", "1.5"]);
    assert!(
        err.contains("anchor") && err.contains("between 0 and 1"),
        "{err}"
    );
    let err = animate(&["--first-moving-scale", "9"]);
    assert!(
        err.contains("first_moving_scale") && err.contains('9'),
        "{err}"
    );
    let err = animate(&["--frames", "0"]);
    assert!(err.contains("--frames"), "{err}");
}

#[test]
fn train_refuses_missing_vgg19_weights_and_vgg19_without_swd() {
    let data = trained_micro().parent().unwrap().join("data");
    let tmp = tempfile::tempdir().unwrap();
    let weights = tmp.path().join("no-such-vgg19.safetensors");
    let run = tmp.path().join("run");
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train",
            path(&data),
            "--out",
            path(&run),
            "--preset",
            "micro",
            "--vgg19",
            path(&weights),
        ];
        args.extend_from_slice(extra);
        failure(&volgen(&args))
    };
    let err = train(&[]);
    assert!(err.contains("no-such-vgg19.safetensors"), "{err}");
    assert!(!run.exists(), "the run started: {err}");
    let err = train(&["--no-swd"]);
    assert!(err.contains("--no-swd") && err.contains("--vgg19"), "{err}");
}

#[test]
fn sample_reconstruction_writes_v_star_like_any_sample() {
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    let (alone, beside) = (tmp.path().join("alone"), tmp.path().join("beside"));
    let text = ok(&volgen(&[
        "sample",
        path(model),
        "--count",
        "0",
        "--reconstruction",
        "--vdb",
        "--mesh",
        "ply",
        // micro's V* is thin fog: its densest voxel stops about a sixth of the light.
        "--mesh-level",
        "0.1",
        "--mesh-smooth",
        "1",
        "--mesh-decimate",
        "0.5",
        "--turntable",
        "5",
        "--out",
        path(&alone),
    ]));
    assert!(text.contains("reconstruction V*"), "{text}");
    for file in [
        "reconstruction.safetensors",
        "reconstruction.png",
        "reconstruction.vdb",
        "reconstruction.gif",
        "reconstruction.ply",
    ] {
        assert!(alone.join(file).is_file(), "{file} missing: {text}");
    }
    assert!(!alone.join("scene_0.safetensors").exists());
    // Five orbit frames at the final size (micro: 36); the PNG keeps the three showcase views.
    assert_eq!(gif_frames(&alone.join("reconstruction.gif")), (5, 36, 36));
    let png = image::open(alone.join("reconstruction.png")).unwrap();
    assert_eq!((png.width(), png.height()), (3 * 36 + 4 * 2, 36 + 2 * 2));

    // V* is the generators' output for the fixed noise, whatever the seed of the samples.
    ok(&volgen(&[
        "sample",
        path(model),
        "--count",
        "1",
        "--seed",
        "5",
        "--reconstruction",
        "--out",
        path(&beside),
    ]));
    let v_star = volume_values(&alone.join("reconstruction.safetensors"));
    assert_eq!(
        v_star,
        volume_values(&beside.join("reconstruction.safetensors"))
    );
    let (trained, _) = singrav::SinGrav::load(model, &candle_core::Device::Cpu).unwrap();
    let want = trained
        .to_physical(&trained.reconstruct().unwrap())
        .unwrap();
    let want: Vec<f32> = want.tensor().flatten_all().unwrap().to_vec1().unwrap();
    assert_eq!(v_star, want);
    let scene = volume_values(&beside.join("scene_0.safetensors"));
    assert!(mean_abs_diff(&v_star, &scene) > 1e-4);
    assert!(!beside.join("scene_0.gif").exists(), "no turntable asked");
    let err = failure(&volgen(&[
        "sample",
        path(model),
        "--turntable",
        "0",
        "--out",
        path(&beside),
    ]));
    assert!(err.contains("--turntable"), "{err}");
}

#[test]
fn animate_gif_holds_every_frame_as_its_png_shows_it() {
    use image::AnimationDecoder;
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("anim");
    let text = ok(&volgen(&[
        "animate",
        path(model),
        "--frames",
        "3",
        "--seed",
        "2",
        "--gif",
        "--out",
        path(&out),
    ]));
    assert!(text.contains("animation.gif"), "{text}");
    let reader = std::io::BufReader::new(std::fs::File::open(out.join("animation.gif")).unwrap());
    let frames = image::codecs::gif::GifDecoder::new(reader)
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap();
    assert_eq!(frames.len(), 3);
    for (t, frame) in frames.iter().enumerate() {
        // The PNG is the same view inside a 2-pixel white border; the GIF's palette is within
        // a few levels of it.
        let png = image::open(out.join(format!("frame_{t:04}.png")))
            .unwrap()
            .to_rgb8();
        let gif = frame.buffer();
        assert_eq!(gif.dimensions(), (png.width() - 4, png.height() - 4));
        let mut total = 0u64;
        for (x, y, p) in gif.enumerate_pixels() {
            let q = png.get_pixel(x + 2, y + 2).0;
            total += (0..3)
                .map(|k| u64::from(p.0[k].abs_diff(q[k])))
                .sum::<u64>();
        }
        let mean = total as f64 / f64::from(3 * gif.width() * gif.height());
        assert!(mean < 4.0, "frame {t}: mean difference {mean} levels");
    }
}

/// `--extent`: `sample` writes scenes over the grown box (volume, VDB read back by vdb-rs,
/// views at the learned pixel size), `edit` takes boxes beyond the learned cube, `animate`
/// grows its frames, and every refusal names its flag.
#[test]
fn extent_grows_samples_edits_and_animations_and_names_bad_flags() {
    let model = trained_micro();
    let tmp = tempfile::tempdir().unwrap();
    let (learned, wide) = (tmp.path().join("learned"), tmp.path().join("wide"));
    let sample = |dir: &Path, extra: &[&str]| {
        let mut args = vec!["sample", path(model), "--count", "1", "--upsample", "1"];
        args.extend_from_slice(&["--vdb", "--out", path(dir)]);
        args.extend_from_slice(extra);
        ok(&volgen(&args))
    };
    sample(&learned, &[]);
    sample(&wide, &["--extent", "2,1,1", "--csg-outside", "clamp"]);
    let small = RadianceVolume::load_safetensors(learned.join("scene_0.safetensors")).unwrap();
    let grown = RadianceVolume::load_safetensors(wide.join("scene_0.safetensors")).unwrap();
    let (s, g) = (small.dims(), grown.dims());
    assert_eq!((g.d, g.h, g.w), (s.d, s.h, 2 * s.w));
    assert_eq!(grown.aabb().min, glam::Vec3::new(-2.0, -1.0, -1.0));
    assert_eq!(grown.aabb().max, glam::Vec3::new(2.0, 1.0, 1.0));
    common::assert_vdb_matches(&grown, &wide.join("scene_0.vdb"));
    // Three views twice the learned size (micro: 36 after the upsampler), 2-pixel borders.
    let png = image::open(wide.join("scene_0.png")).unwrap();
    assert_eq!((png.width(), png.height()), (3 * 72 + 4 * 2, 72 + 2 * 2));

    // A box beyond the learned cube: refused at the learned size, emptied at 2,1,1.
    let beyond = "1.2,-0.5,-1,1.8,0.5,0.2";
    let edit = |dir: &Path, extra: &[&str]| {
        let mut args = vec!["edit", path(model), "--remove", beyond, "--no-harmonize"];
        args.extend_from_slice(&["--upsample", "1", "--out", path(dir)]);
        args.extend_from_slice(extra);
        volgen(&args)
    };
    let err = failure(&edit(&tmp.path().join("refused"), &[]));
    assert!(err.contains("[-1, 1]^3"), "{err}");
    let edited_dir = tmp.path().join("edited");
    ok(&edit(&edited_dir, &["--extent", "2,1,1"]));
    let edited = RadianceVolume::load_safetensors(edited_dir.join("edited.safetensors")).unwrap();
    assert_eq!(edited.dims(), grown.dims());
    let density = volume_values(&edited_dir.join("edited.safetensors"));
    let (grid, dims) = (*edited.grid(), edited.dims());
    let mut inside = 0;
    for z in 0..dims.d {
        for y in 0..dims.h {
            for x in 0..dims.w {
                let p = grid.cell_center(z, y, x);
                if p.x > 1.2 && p.x < 1.8 && p.y.abs() < 0.5 && p.z < 0.2 {
                    inside += 1;
                    assert!(density[dims.index(z, y, x)] < 1e-3, "density left at {p}");
                }
            }
        }
    }
    assert!(inside > 0);

    let frames = tmp.path().join("frames");
    ok(&volgen(&[
        "animate",
        path(model),
        "--frames",
        "1",
        "--extent",
        "1,2,1",
        "--upsample",
        "1",
        "--out",
        path(&frames),
    ]));
    let frame = RadianceVolume::load_safetensors(frames.join("frame_0000.safetensors")).unwrap();
    assert_eq!(frame.dims().h, 2 * s.h);

    let refusals: [(&[&str], &[&str]); 5] = [
        (&["--extent", "2,1"], &["--extent", "X,Y,Z"]),
        (&["--extent", "0,1,1"], &["--extent", "between"]),
        (&["--csg-outside", "tile"], &["--csg-outside", "mirror"]),
        (
            &["--extent", "2,1,1", "--reconstruction"],
            &["--reconstruction"],
        ),
        (&["--extent", "2,1,1", "--vary-from", "2"], &["--vary-from"]),
    ];
    for (extra, words) in refusals {
        let dir = tmp.path().join("refusal");
        let mut args = vec!["sample", path(model), "--out", path(&dir)];
        args.extend_from_slice(extra);
        let err = failure(&volgen(&args));
        for word in words {
            assert!(err.contains(word), "{extra:?}: {err}");
        }
        assert!(
            !dir.join("scene_0.safetensors").exists(),
            "{extra:?} wrote a scene"
        );
    }
}
