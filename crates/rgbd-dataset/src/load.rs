//! Loading a dataset: parse `transforms.json`, check every frame, decode and composite pixels.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use glam::{Mat3, Mat4};
use serde_json::Value;
use volrender::Camera;

use super::capture::{frame_lens, mask_path};
use super::depth::{to_expected, Converted, DepthKind, KINDS_EXPLAINED, MAX_HOLE_FRACTION};
use super::lens::{Lens, Undistortion};
use super::pixels::{read_depth_exr, read_depth_png, read_grey, read_rgba, Pixels};
use super::source::{SceneSource, SOURCE_FIELD};
use super::{transforms_file, Dataset, FramePixels, LoadOptions};
use crate::error::{io_error, Error, Result};

/// Tolerance of the rigidity check on a camera's rotation (orthonormality and determinant).
const RIGID_TOLERANCE: f32 = 1e-3;

/// One frame's identity for error messages: the dataset file and the frame's name.
struct FrameRef<'a> {
    transforms: &'a Path,
    name: String,
}

impl FrameRef<'_> {
    /// A dataset error about this frame, reported against `path`.
    fn error(&self, path: &Path, why: impl Into<String>) -> Error {
        Error::Dataset {
            path: path.to_path_buf(),
            frame: Some(self.name.clone()),
            why: why.into(),
        }
    }

    /// A dataset error about this frame's entry in `transforms.json`.
    fn entry_error(&self, why: impl Into<String>) -> Error {
        self.error(self.transforms, why)
    }
}

/// A dataset error about the whole `transforms.json`.
fn file_error(path: &Path, why: impl Into<String>) -> Error {
    Error::Dataset {
        path: path.to_path_buf(),
        frame: None,
        why: why.into(),
    }
}

pub(super) fn load(transforms: &Path, options: &LoadOptions) -> Result<Dataset> {
    let path = transforms_file(transforms);
    let text = std::fs::read_to_string(&path).map_err(io_error(&path))?;
    let root: Value = serde_json::from_str(&python_json_to_strict(&text))
        .map_err(|e| file_error(&path, format!("not valid JSON: {e}")))?;
    let frames = root
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| file_error(&path, "missing array field `frames`"))?;
    if frames.is_empty() {
        return Err(file_error(&path, "no frames: `frames` is empty"));
    }
    // A capture without a single depth map (nerfstudio's photos) has nothing to misread.
    let no_depth_files = frames.iter().all(|f| f.get("depth_file_path").is_none());
    let kind = match options.depth_kind {
        Some(kind) => kind,
        None if root.get("depth_kind").is_none() && no_depth_files => DepthKind::None,
        None => declared_depth_kind(&root, &path)?,
    };
    let depth_scale = match root.get("depth_scale") {
        None => None,
        Some(v) => Some(
            v.as_f64()
                .filter(|s| s.is_finite() && *s > 0.0)
                .ok_or_else(|| {
                    file_error(
                        &path,
                        format!("`depth_scale` must be a number > 0, got {v}"),
                    )
                })? as f32,
        ),
    };
    let declared = declared_size(&root, &path)?;
    let source = root
        .get(SOURCE_FIELD)
        .map(|record| SceneSource::from_json(record, &path))
        .transpose()?;
    let base = path.parent().unwrap_or(Path::new("."));

    let mut size = declared;
    let mut names = Vec::with_capacity(frames.len());
    let mut raw = Vec::with_capacity(frames.len());
    for (i, frame) in frames.iter().enumerate() {
        let frame_path = frame.get("file_path").and_then(Value::as_str);
        let at = FrameRef {
            transforms: &path,
            name: frame_path.map_or_else(|| format!("frames[{i}]"), str::to_owned),
        };
        check_rigid(frame, &at)?;
        let image_path = frame_path
            .map(|p| image_file(base, p))
            .ok_or_else(|| at.entry_error("missing field `file_path` (the colour image)"))?;
        let mut rgba = read_rgba(&image_path).map_err(|why| file_problem(&at, &image_path, why))?;
        if let Some(mask) = mask_path(frame).map_err(|why| at.entry_error(why))? {
            apply_mask(&mut rgba, &image_file(base, mask), &at)?;
        }
        let lens = frame_lens(&root, frame).map_err(|why| at.entry_error(why))?;
        if !lens.is_pinhole() && kind != DepthKind::None {
            return Err(at.entry_error(format!(
                "the lens has distortion ({lens:?}) and the frame has a depth map: volgen \
                 undistorts photos, not depth maps; undistort both first or leave the depth out"
            )));
        }
        let (width, height) = *size.get_or_insert((rgba.width, rgba.height));
        if (rgba.width, rgba.height) != (width, height) {
            let reference = if declared.is_some() {
                "`w` x `h` of transforms.json".to_owned()
            } else {
                format!("the size of frame {}", names[0])
            };
            return Err(at.error(
                &image_path,
                format!(
                    "image is {} x {} pixels, but {reference} is {width} x {height}",
                    rgba.width, rgba.height
                ),
            ));
        }
        let (depth_path, depth) = if kind == DepthKind::None {
            let none = Pixels {
                width,
                height,
                data: vec![0.0; width * height],
            };
            (image_path.clone(), none)
        } else {
            read_depth(frame, base, depth_scale, &at)?
        };
        if depth.width != width || depth.height != height {
            return Err(at.entry_error(format!(
                "depth map is {} x {} pixels, but its image is {width} x {height}",
                depth.width, depth.height
            )));
        }
        raw.push((rgba, depth_path, depth.data, lens));
        names.push(at.name);
    }
    let (width, height) = size.unwrap_or_default();
    let mut cameras: Vec<Camera> =
        volrender::transforms_from_json(&root, &path, Some((width, height)))?
            .into_iter()
            .map(|frame| frame.camera)
            .collect();
    let mut pixels = Vec::with_capacity(raw.len());
    let mut undistortions = Vec::new();
    for (((mut rgba, depth_path, depth, lens), camera), name) in
        raw.into_iter().zip(&mut cameras).zip(&names)
    {
        let at = FrameRef {
            transforms: &path,
            name: name.clone(),
        };
        undistort(&mut rgba, camera, lens, &mut undistortions, &at)?;
        let opacity: Vec<f32> = rgba.data.iter().map(|p| p[3]).collect();
        let converted = to_expected(kind, &depth, &opacity, camera)
            .map_err(|why| at.error(&depth_path, format!("`depth_kind` {kind}: {why}")))?;
        let allowed = MAX_HOLE_FRACTION * converted.foreground as f32;
        if converted.foreground_holes as f32 > allowed {
            return Err(at.error(
                &depth_path,
                format!(
                    "{} of the {} foreground pixels (opacity > 0.5 + 1/255) have no depth (infinite, \
                     NaN, >= 1e9, 65504 or 0 under `depth_kind` {kind}); more than {:.0}% \
                     means the depth map does not match the image",
                    converted.foreground_holes,
                    converted.foreground,
                    MAX_HOLE_FRACTION * 100.0
                ),
            ));
        }
        pixels.push(composite(&rgba, converted, options.background));
    }
    Ok(Dataset {
        width,
        height,
        cameras,
        names,
        frames: pixels,
        depth_kind: kind,
        source,
        points_file: points_file(&root, base, &path)?,
    })
}

/// nerfstudio's `ply_file_path` (the capture's sparse points), relative to the dataset.
fn points_file(root: &Value, base: &Path, path: &Path) -> Result<Option<PathBuf>> {
    match root.get("ply_file_path") {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(name)) => Ok(Some(base.join(name))),
        Some(other) => Err(file_error(
            path,
            format!("`ply_file_path` must be a file name (a PLY point cloud), got {other}"),
        )),
    }
}

/// The `depth_kind` of `transforms.json`; refuses a dataset without one, since reading planar
/// or ray-length depth as expected depth trains on silently wrong depth. Every dataset volgen
/// writes states its kind.
fn declared_depth_kind(root: &Value, path: &Path) -> Result<DepthKind> {
    match root.get("depth_kind") {
        None => Err(file_error(
            path,
            format!(
                "`depth_kind` is missing: say how the depth maps measure depth, either in \
                 transforms.json (\"depth_kind\": ...) or with `volgen train --depth-kind KIND`; \
                 KIND is {KINDS_EXPLAINED}"
            ),
        )),
        Some(Value::String(kind)) => kind
            .parse()
            .map_err(|why: String| file_error(path, format!("`depth_kind`: {why}"))),
        Some(other) => Err(file_error(
            path,
            format!("`depth_kind` must be a string, got {other}; expected {KINDS_EXPLAINED}"),
        )),
    }
}

/// `w` and `h` from the top level, if given.
fn declared_size(root: &Value, path: &Path) -> Result<Option<(usize, usize)>> {
    let side = |key: &str| -> Result<Option<usize>> {
        root.get(key)
            .map(|v| {
                v.as_u64()
                    .filter(|&n| n >= 1)
                    .map(|n| n as usize)
                    .ok_or_else(|| {
                        file_error(path, format!("`{key}` must be an integer >= 1, got {v}"))
                    })
            })
            .transpose()
    };
    Ok(side("w")?.zip(side("h")?))
}

/// Resolves an image path relative to the dataset; a name without extension that does not exist
/// gets `.png` appended (Blender NeRF data).
pub(crate) fn image_file(base: &Path, name: &str) -> PathBuf {
    let path = base.join(name);
    if path.extension().is_none() && !path.exists() {
        path.with_extension("png")
    } else {
        path
    }
}

/// Multiplies the photo's opacity by the mask in `file` (white on the scene).
fn apply_mask(rgba: &mut Pixels<[f32; 4]>, file: &Path, at: &FrameRef<'_>) -> Result<()> {
    let mask = read_grey(file).map_err(|why| file_problem(at, file, why))?;
    if (mask.width, mask.height) != (rgba.width, rgba.height) {
        return Err(at.error(
            file,
            format!(
                "mask is {} x {} pixels, but its image is {} x {}",
                mask.width, mask.height, rgba.width, rgba.height
            ),
        ));
    }
    for (pixel, m) in rgba.data.iter_mut().zip(mask.data) {
        pixel[3] *= m;
    }
    Ok(())
}

/// Resamples a photo taken through `lens` into a pinhole camera ([`Undistortion`]) and makes
/// `camera` that pinhole one. `made` keeps the undistortions found so far: frames of one
/// physical camera share theirs (finding the focal length takes a search).
fn undistort(
    rgba: &mut Pixels<[f32; 4]>,
    camera: &mut Camera,
    lens: Lens,
    made: &mut Vec<Undistortion>,
    at: &FrameRef<'_>,
) -> Result<()> {
    if lens.is_pinhole() {
        return Ok(());
    }
    let size = (camera.width as u32, camera.height as u32);
    let photo = [camera.fx, camera.fy, camera.cx, camera.cy].map(f64::from);
    let known = made
        .iter()
        .position(|u| u.lens() == lens && u.photo() == photo && u.size() == size);
    let index = match known {
        Some(index) => index,
        None => {
            made.push(Undistortion::new(lens, photo, size).map_err(|why| at.entry_error(why))?);
            made.len() - 1
        }
    };
    let undistortion = &made[index];
    rgba.data = undistortion.apply_straight(&rgba.data);
    let pinhole = undistortion.pinhole().map(|v| v as f32);
    *camera = Camera::from_intrinsics(camera.c2w, camera.width, camera.height, pinhole)
        .map_err(|e| at.entry_error(e.to_string()))?;
    Ok(())
}

/// The error for an image or depth file that could not be read.
fn file_problem(at: &FrameRef<'_>, file: &Path, why: String) -> Error {
    if file.exists() {
        at.error(file, why)
    } else {
        at.error(
            file,
            format!("file {} is missing (not found)", file.display()),
        )
    }
}

/// Reads a frame's depth map in world units, with the file it came from.
fn read_depth(
    frame: &Value,
    base: &Path,
    depth_scale: Option<f32>,
    at: &FrameRef<'_>,
) -> Result<(PathBuf, Pixels<f32>)> {
    let name = frame
        .get("depth_file_path")
        .and_then(Value::as_str)
        .ok_or_else(|| {
            at.entry_error("missing field `depth_file_path` (every frame needs a depth map)")
        })?;
    let file = image_file(base, name);
    let is_exr = file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if is_exr {
        let depth = read_depth_exr(&file).map_err(|why| file_problem(at, &file, why))?;
        return Ok((file, depth));
    }
    let scale = depth_scale.ok_or_else(|| {
        at.entry_error(format!(
            "depth map {name} is a PNG, but transforms.json has no `depth_scale`: the depth \
             unit must be stated (world units per count)"
        ))
    })?;
    let counts = read_depth_png(&file).map_err(|why| file_problem(at, &file, why))?;
    let depth = Pixels {
        width: counts.width,
        height: counts.height,
        data: counts.data.iter().map(|&c| f32::from(c) * scale).collect(),
    };
    Ok((file, depth))
}

/// Composites straight RGBA onto `background`, keeping opacity and the converted depth.
fn composite(rgba: &Pixels<[f32; 4]>, depth: Converted, background: [f32; 3]) -> FramePixels {
    let plane = rgba.data.len();
    let mut rgb = vec![0f32; 3 * plane];
    for (i, [r, g, b, a]) in rgba.data.iter().copied().enumerate() {
        for (c, value) in [r, g, b].into_iter().enumerate() {
            rgb[c * plane + i] = value * a + background[c] * (1.0 - a);
        }
    }
    FramePixels {
        rgb,
        opacity: rgba.data.iter().map(|p| p[3]).collect(),
        depth: depth.depth,
        depth_mask: depth.mask,
        depth_left_out: depth.left_out,
    }
}

/// Checks that the frame's `transform_matrix` is a finite rigid motion.
fn check_rigid(frame: &Value, at: &FrameRef<'_>) -> Result<()> {
    let rows = frame
        .get("transform_matrix")
        .and_then(Value::as_array)
        .filter(|rows| rows.len() == 4)
        .ok_or_else(|| at.entry_error("`transform_matrix` must be a 4x4 array"))?;
    let mut m = [[0f32; 4]; 4];
    for (r, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|row| row.len() == 4).ok_or_else(|| {
            at.entry_error(format!("`transform_matrix` row {r} must hold 4 numbers"))
        })?;
        for (c, v) in row.iter().enumerate() {
            m[r][c] = v
                .as_f64()
                .map(|x| x as f32)
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    let shown = if v.is_null() {
                        "NaN or infinite".into()
                    } else {
                        v.to_string()
                    };
                    at.entry_error(format!(
                        "`transform_matrix[{r}][{c}]` must be a finite number, got {shown}"
                    ))
                })?;
        }
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(at.entry_error(format!(
            "`transform_matrix` last row must be [0, 0, 0, 1], got {:?}",
            m[3]
        )));
    }
    let rotation = Mat3::from_mat4(Mat4::from_cols_array_2d(&m).transpose());
    let off_identity = (rotation.transpose() * rotation - Mat3::IDENTITY)
        .to_cols_array()
        .into_iter()
        .fold(0f32, |worst, e| worst.max(e.abs()));
    let det = rotation.determinant();
    if off_identity > RIGID_TOLERANCE || (det - 1.0).abs() > RIGID_TOLERANCE {
        return Err(at.entry_error(format!(
            "`transform_matrix` is not rigid: its rotation part is off orthonormal by \
             {off_identity:.2e} with determinant {det:.4} (tolerance {RIGID_TOLERANCE:.0e}, \
             determinant +1)"
        )));
    }
    Ok(())
}

/// Python's `json.dump` writes `NaN`, `Infinity` and `-Infinity`, which JSON has no words for;
/// reading them as `null` lets the checks name the frame and field instead of failing on the
/// whole file.
pub(crate) fn python_json_to_strict(text: &str) -> Cow<'_, str> {
    if !text.contains("NaN") && !text.contains("Infinity") {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len());
    let mut in_string = false;
    let mut escaped = false;
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if in_string {
            in_string = c != '"' || escaped;
            escaped = c == '\\' && !escaped;
        } else if c == '"' {
            in_string = true;
        } else if let Some(word) = ["-Infinity", "Infinity", "NaN"]
            .into_iter()
            .find(|w| rest.starts_with(w))
        {
            out.push_str("null");
            rest = &rest[word.len()..];
            continue;
        }
        out.push(c);
        rest = &rest[c.len_utf8()..];
    }
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::python_json_to_strict;

    #[test]
    fn python_non_finite_words_become_null_outside_strings() {
        let text = r#"{"a": [NaN, -Infinity, Infinity], "NaN": "x\"NaN"}"#;
        let strict = python_json_to_strict(text);
        assert_eq!(strict, r#"{"a": [null, null, null], "NaN": "x\"NaN"}"#);
        assert!(serde_json::from_str::<serde_json::Value>(&strict).is_ok());
        assert!(matches!(
            python_json_to_strict("[1]"),
            std::borrow::Cow::Borrowed(_)
        ));
    }
}
