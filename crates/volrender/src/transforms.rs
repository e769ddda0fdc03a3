//! Loading cameras from a NeRF `transforms.json` (Blender NeRF data, nerfstudio).
//!
//! Intrinsics come from `camera_angle_x` (horizontal field of view, radians) or from `fl_x`
//! (`fl_y` defaults to `fl_x`), `cx`, `cy` (default: the image centre) with the image size `w`,
//! `h`; each may be given at the top level or per frame (a frame's value wins). Each frame needs
//! a 4x4 row-major `transform_matrix` (camera-to-world). Its camera axes are the NeRF/Blender
//! (OpenGL) convention, which nerfstudio also writes: x right, y up, looking down -z; with
//! `"camera_axes": "opencv"` (top level or per frame) they are OpenCV's and COLMAP's instead:
//! x right, y down, looking down +z.

use std::path::Path;

use glam::Mat4;
use serde_json::Value;

use crate::camera::Camera;
use crate::error::{Error, Result};

/// One frame of a `transforms.json`: its camera and, when present, its image path.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameCamera {
    /// `frames[i].file_path`, as written in the file.
    pub file_path: Option<String>,
    /// The frame's camera.
    pub camera: Camera,
}

/// Loads every frame's camera. With `size = Some((width, height))` the cameras render at that
/// size (intrinsics given in pixels are scaled from the file's `w`, `h`); with `None` the file
/// must give `w` and `h`.
///
/// Errors name the file, the frame and the field.
///
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("transforms.json");
/// std::fs::write(&path, r#"{"camera_angle_x": 0.6, "frames": [{"file_path": "r_0",
///     "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#)?;
/// let frames = volrender::load_transforms(&path, Some((32, 24)))?;
/// assert_eq!(frames[0].camera.position(), glam::Vec3::new(0.0, 0.0, 4.0));
/// assert_eq!(frames[0].file_path.as_deref(), Some("r_0"));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn load_transforms(
    path: impl AsRef<Path>,
    size: Option<(usize, usize)>,
) -> Result<Vec<FrameCamera>> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let fail = |why: String| Error::InvalidTransforms {
        path: path.to_path_buf(),
        why,
    };
    let root: Value = serde_json::from_str(&text).map_err(|e| fail(format!("not JSON: {e}")))?;
    transforms_from_json(&root, path, size)
}

/// [`load_transforms`] of a `transforms.json` already parsed (`root`), for a reader that needs
/// the file's other fields too; `path` names the file in errors.
///
/// ```
/// let root = serde_json::json!({"camera_angle_x": 0.6, "frames": [{"transform_matrix":
///     [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]});
/// let frames = volrender::transforms_from_json(&root, "transforms.json".as_ref(), Some((8, 8)))?;
/// assert_eq!(frames[0].camera.width, 8);
/// # Ok::<(), volrender::Error>(())
/// ```
pub fn transforms_from_json(
    root: &Value,
    path: &Path,
    size: Option<(usize, usize)>,
) -> Result<Vec<FrameCamera>> {
    let fail = |why: String| Error::InvalidTransforms {
        path: path.to_path_buf(),
        why,
    };
    let frames = root
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| fail("missing array field `frames`".into()))?;
    frames
        .iter()
        .enumerate()
        .map(|(i, frame)| {
            parse_frame(root, frame, size).map_err(|why| fail(format!("frames[{i}]: {why}")))
        })
        .collect()
}

/// Reads a number from the frame, falling back to the top level.
fn number(root: &Value, frame: &Value, key: &str) -> std::result::Result<Option<f64>, String> {
    match frame.get(key).or_else(|| root.get(key)) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => v
            .as_f64()
            .filter(|x| x.is_finite())
            .map(Some)
            .ok_or_else(|| format!("field `{key}` must be a finite number, got {v}")),
    }
}

/// The turn from the file's camera axes to the NeRF convention's, from `camera_axes`.
fn camera_axes(root: &Value, frame: &Value) -> std::result::Result<Mat4, String> {
    match frame.get("camera_axes").or_else(|| root.get("camera_axes")) {
        None => Ok(Mat4::IDENTITY),
        Some(Value::String(axes)) if axes == "opengl" => Ok(Mat4::IDENTITY),
        // y and z turned around: OpenCV's y down and z forward become y up and z backward.
        Some(Value::String(axes)) if axes == "opencv" => {
            Ok(Mat4::from_scale(glam::Vec3::new(1.0, -1.0, -1.0)))
        }
        Some(other) => Err(format!(
            "field `camera_axes` must be \"opengl\" (NeRF, Blender, nerfstudio: y up, looking \
             down -z) or \"opencv\" (COLMAP: y down, looking down +z), got {other}"
        )),
    }
}

fn parse_frame(
    root: &Value,
    frame: &Value,
    size: Option<(usize, usize)>,
) -> std::result::Result<FrameCamera, String> {
    let matrix = frame
        .get("transform_matrix")
        .and_then(Value::as_array)
        .filter(|rows| rows.len() == 4)
        .ok_or("field `transform_matrix` must be a 4x4 array")?;
    let mut m = [[0f32; 4]; 4];
    for (r, row) in matrix.iter().enumerate() {
        let row = row
            .as_array()
            .filter(|row| row.len() == 4)
            .ok_or_else(|| format!("field `transform_matrix` row {r} must have 4 numbers"))?;
        for (c, v) in row.iter().enumerate() {
            m[r][c] = v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                format!("field `transform_matrix[{r}][{c}]` must be a finite number, got {v}")
            })? as f32;
        }
    }
    // The file is row-major; glam is column-major.
    let c2w = Mat4::from_cols_array_2d(&m).transpose() * camera_axes(root, frame)?;
    let file_w = number(root, frame, "w")?;
    let file_h = number(root, frame, "h")?;
    let (width, height) = match (size, file_w, file_h) {
        (Some(s), _, _) => s,
        (None, Some(w), Some(h)) if w >= 1.0 && h >= 1.0 => (w as usize, h as usize),
        _ => {
            return Err("no image size: give `w` and `h` in the file or a size to render at".into())
        }
    };
    let scale_x = file_w.map_or(1.0, |w| width as f64 / w);
    let scale_y = file_h.map_or(scale_x, |h| height as f64 / h);
    let camera = if let Some(fl_x) = number(root, frame, "fl_x")? {
        if file_w.is_none() && size.is_some() {
            return Err("field `fl_x` is in pixels of an image whose `w` is not given".into());
        }
        let fl_y = number(root, frame, "fl_y")?.unwrap_or(fl_x);
        let cx = number(root, frame, "cx")?.map_or(0.5 * width as f64, |c| c * scale_x);
        let cy = number(root, frame, "cy")?.map_or(0.5 * height as f64, |c| c * scale_y);
        let k = [fl_x * scale_x, fl_y * scale_y, cx, cy].map(|v| v as f32);
        Camera::from_intrinsics(c2w, width, height, k)
    } else if let Some(angle) = number(root, frame, "camera_angle_x")? {
        Camera::from_fov(c2w, width, height, angle as f32)
    } else {
        return Err("no intrinsics: give `camera_angle_x` or `fl_x`".into());
    };
    let file_path = frame
        .get("file_path")
        .and_then(Value::as_str)
        .map(str::to_owned);
    camera
        .map(|camera| FrameCamera { file_path, camera })
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(json: &str, size: Option<(usize, usize)>) -> Result<Vec<FrameCamera>> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("transforms.json");
        std::fs::write(&path, json).unwrap();
        load_transforms(&path, size)
    }

    const EYE: &str = "[[1,0,0,1],[0,1,0,2],[0,0,1,3],[0,0,0,1]]";

    #[test]
    fn intrinsics_scale_to_the_render_size() {
        let json = format!(
            r#"{{"fl_x": 100, "cx": 40, "w": 80, "h": 60, "frames": [{{"transform_matrix": {EYE}}}]}}"#
        );
        let cam = load(&json, Some((160, 120))).unwrap()[0].camera;
        assert_eq!((cam.fx, cam.fy, cam.cx, cam.cy), (200.0, 200.0, 80.0, 60.0));
        assert_eq!(cam.position(), glam::Vec3::new(1.0, 2.0, 3.0));
        let cam = load(&json, None).unwrap()[0].camera;
        assert_eq!((cam.width, cam.height, cam.fx), (80, 60, 100.0));
    }

    #[test]
    fn opencv_camera_axes_turn_y_and_z_around() {
        let json = |axes: &str| {
            format!(
                r#"{{"camera_angle_x": 0.5, {axes} "frames": [{{"transform_matrix": {EYE}}}]}}"#
            )
        };
        let gl = load(&json(""), Some((8, 8))).unwrap()[0].camera;
        let cv = load(&json(r#""camera_axes": "opencv","#), Some((8, 8))).unwrap()[0].camera;
        assert_eq!(cv.position(), gl.position());
        assert_eq!(cv.c2w.x_axis, gl.c2w.x_axis);
        assert_eq!(cv.c2w.y_axis, -gl.c2w.y_axis);
        assert_eq!(cv.c2w.z_axis, -gl.c2w.z_axis);
        let msg = load(&json(r#""camera_axes": "directx","#), Some((8, 8)))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("camera_axes") && msg.contains("directx"),
            "{msg}"
        );
    }

    #[test]
    fn errors_name_the_frame_and_field() {
        let bad = format!(
            r#"{{"camera_angle_x": 0.5, "frames": [{{"transform_matrix": {EYE}}}, {{"transform_matrix": [[1,0,0,0]]}}]}}"#
        );
        let msg = load(&bad, Some((8, 8))).unwrap_err().to_string();
        assert!(
            msg.contains("frames[1]") && msg.contains("transform_matrix"),
            "{msg}"
        );
        let msg = load(
            &format!(r#"{{"frames": [{{"transform_matrix": {EYE}}}]}}"#),
            Some((8, 8)),
        )
        .unwrap_err()
        .to_string();
        assert!(
            msg.contains("frames[0]") && msg.contains("intrinsics"),
            "{msg}"
        );
        let msg = load(
            r#"{"camera_angle_x": "wide", "frames": [{}]}"#,
            Some((8, 8)),
        )
        .unwrap_err()
        .to_string();
        assert!(msg.contains("transform_matrix"), "{msg}");
        assert!(load("{", None).is_err());
        assert!(matches!(
            load("{}", None),
            Err(Error::InvalidTransforms { .. })
        ));
    }
}
