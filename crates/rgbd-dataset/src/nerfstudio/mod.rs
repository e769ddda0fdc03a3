//! A nerfstudio capture (`ns-process-data`'s `transforms.json` with its sparse point cloud) placed
//! in the model's cube as [`crate::colmap::import`] places a COLMAP model: turned upright,
//! centred and scaled ([`Placement`]). nerfstudio leaves the scene where structure from motion put
//! it (and orients it only when it trains); [`import`] writes a copy of the capture whose cameras
//! are placed, with the photos and masks copied as they are (the lens is still undistorted when
//! the copy loads) and the placement recorded (`volgen_import.capture_to_dataset`).
//!
//! [`read_points`] reads the point cloud (PLY).

mod ply;

pub use ply::read_points;

use std::path::{Component, Path, PathBuf};

use glam::DMat4;
use serde_json::{json, Value};

use crate::error::{invalid, io_error, Error, Result};
use crate::io::{create_dir, write_bytes};
use crate::load::{image_file, python_json_to_strict};
use crate::placement::{Foreground, Placement, SparseCapture, UpFrom};
use crate::{transforms_file, Dataset, DepthKind, LoadOptions};

/// How [`import`] places a capture.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    /// The sparse points (PLY); `None`: the file's `ply_file_path` (nerfstudio writes
    /// `sparse_pc.ply` beside it).
    pub points: Option<PathBuf>,
    /// Which way is up ([`crate::placement::up_direction`]).
    pub up: UpFrom,
}

/// What [`import`] wrote.
#[derive(Debug, Clone)]
pub struct ImportSummary {
    /// The placed capture's `transforms.json`.
    pub transforms: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// The point cloud placing read, and its number of points.
    pub points: (PathBuf, usize),
    /// How the capture was placed in the model's cube.
    pub placement: Placement,
}

/// Writes the nerfstudio capture `transforms` (the file or its directory) placed in the model's
/// cube into `out`: its photos and masks copied (at their relative paths in the capture, or to
/// `images/` and `masks/` when they are elsewhere), and a
/// `transforms.json` (written last) that is the capture's with each `transform_matrix` placed,
/// `depth_kind` "none" and the placement in `volgen_import`. The capture must load as a dataset
/// ([`Dataset::load`]), have no depth maps (training places a scene with depth maps itself:
/// `--bounds auto`), show a foreground (alpha or `mask_path`) and have sparse points.
///
/// ```no_run
/// use rgbd_dataset::nerfstudio::{import, ImportOptions};
/// let summary = import("capture/transforms.json".as_ref(), &ImportOptions::default(), "data/mine".as_ref())?;
/// println!("scale {}", summary.placement.scale);
/// # Ok::<(), rgbd_dataset::Error>(())
/// ```
pub fn import(transforms: &Path, options: &ImportOptions, out: &Path) -> Result<ImportSummary> {
    let path = transforms_file(transforms);
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let file_error = |why: String| Error::Dataset {
        path: path.clone(),
        frame: None,
        why,
    };
    // The copy must not replace the capture's own file (or its photos with themselves).
    let same_dir = std::fs::canonicalize(&base)
        .ok()
        .zip(std::fs::canonicalize(out).ok())
        .is_some_and(|(a, b)| a == b);
    if same_dir {
        return Err(file_error(format!(
            "the output directory {} is the capture's own: write the placed copy elsewhere",
            out.display()
        )));
    }
    let dataset = Dataset::load_with(&path, &LoadOptions::default())?;
    if dataset.depth_kind() != DepthKind::None {
        return Err(file_error(
            "has depth maps: train on it directly with `--bounds auto`, which places the scene \
             from them (importing places captures without depth, from their sparse points)"
                .into(),
        ));
    }
    if dataset
        .frames
        .iter()
        .all(|f| f.opacity.iter().all(|&a| a >= 1.0))
    {
        return Err(file_error(
            "every photo is opaque everywhere and no frame has a `mask_path`: volgen learns a \
             bounded scene and needs to know which pixels show it (an alpha channel, or masks \
             white on the scene)"
                .into(),
        ));
    }
    let points_path =
        match (&options.points, &dataset.points_file) {
            (Some(given), _) => given.clone(),
            (None, Some(in_file)) => in_file.clone(),
            (None, None) => return Err(file_error(
                "has no `ply_file_path` (the sparse points nerfstudio writes as sparse_pc.ply): \
                 placing the scene needs them; give the points with --points FILE.ply"
                    .into(),
            )),
        };
    let points = read_points(&points_path)?;
    let capture = SparseCapture {
        cameras: dataset
            .cameras
            .iter()
            .map(|c| DMat4::from_cols_array(&c.c2w.to_cols_array().map(f64::from)))
            .collect(),
        points,
    };
    let size = (dataset.width, dataset.height);
    let foreground: Vec<Foreground> = dataset
        .cameras
        .iter()
        .zip(&dataset.frames)
        .map(|(c, f)| Foreground {
            intrinsics: [c.fx, c.fy, c.cx, c.cy].map(f64::from),
            size,
            alpha: f
                .opacity
                .iter()
                .map(|a| (a.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect(),
        })
        .collect();
    let placement = Placement::of_foreground(&capture, &foreground, options.up)?;

    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let mut root: Value = serde_json::from_str(&python_json_to_strict(&text))
        .map_err(|e| file_error(format!("not valid JSON: {e}")))?;
    let transforms_out = out.join("transforms.json");
    radiance_volume::io::remove_file_if_exists(&transforms_out)?;
    let frames = root["frames"]
        .as_array_mut()
        .expect("the dataset loaded, so `frames` is an array");
    for (i, frame) in frames.iter_mut().enumerate() {
        for (field, dir) in [("file_path", "images"), ("mask_path", "masks")] {
            if let Some(name) = frame.get(field).and_then(Value::as_str) {
                let copied = copy_into(&image_file(&base, name), name, out, dir, i)?;
                frame[field] = copied.into();
            }
        }
        let c2w = matrix(&frame["transform_matrix"]);
        let placed = placement.place_camera(c2w);
        frame["transform_matrix"] = rows(&placed);
    }
    let object = root.as_object_mut().expect("a dataset's root is an object");
    // The points and nerfstudio's own transform describe the capture's frame, not the placed one.
    object.remove("ply_file_path");
    object.remove("applied_transform");
    object.insert("depth_kind".into(), "none".into());
    object.insert(
        "volgen_import".into(),
        json!({
            "from": "nerfstudio",
            "capture": path.display().to_string(),
            "points": points_path.display().to_string(),
            "capture_to_dataset": rows(&placement.matrix()),
            "scale": placement.scale,
        }),
    );
    let text = serde_json::to_string_pretty(&root)
        .map_err(|e| invalid("transforms.json", e.to_string()))?;
    write_bytes(&transforms_out, text.as_bytes())?;
    Ok(ImportSummary {
        transforms: transforms_out,
        frames: dataset.len(),
        points: (points_path, capture.points.len()),
        placement,
    })
}

/// Copies frame `index`'s `file` (named `name` in the capture) into `out`, at the same relative
/// path when it is one inside the capture (so names stay as they were), else at `dir/NNN.ext`;
/// returns the path relative to `out`.
fn copy_into(file: &Path, name: &str, out: &Path, dir: &str, index: usize) -> Result<String> {
    let inside = Path::new(name)
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    let relative = if inside {
        name.to_owned()
    } else {
        let extension = file
            .extension()
            .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
        format!("{dir}/{index:03}{extension}")
    };
    let target = out.join(&relative);
    if let Some(parent) = target.parent() {
        create_dir(parent)?;
    }
    let bytes = std::fs::read(file).map_err(io_error(file))?;
    write_bytes(&target, &bytes)?;
    Ok(relative)
}

/// A `transform_matrix` (rows, checked when the dataset loaded) in f64.
fn matrix(rows: &Value) -> DMat4 {
    let at = |r: usize, c: usize| rows[r][c].as_f64().unwrap_or(f64::NAN);
    DMat4::from_cols_array_2d(&[0, 1, 2, 3].map(|c| [0, 1, 2, 3].map(|r| at(r, c))))
}

/// A matrix as `transforms.json` rows.
fn rows(m: &DMat4) -> Value {
    json!((0..4).map(|r| m.row(r).to_array()).collect::<Vec<_>>())
}
