//! COLMAP's text encoding: one record per line (`#` comments), images on two lines each (the
//! pose, then its 2D points, which are not needed here).

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;

use super::{model_error, CameraModel, ColmapCamera, ColmapImage, ColmapPoint};
use crate::error::{io_error, Result};

/// The file's lines that are not comments, with their 1-based numbers. Blank lines are kept
/// (an image without 2D points has a blank second line).
fn records(path: &Path) -> Result<Vec<(usize, String)>> {
    let text = std::fs::read_to_string(path).map_err(io_error(path))?;
    Ok(text
        .lines()
        .enumerate()
        .filter(|(_, line)| !line.trim_start().starts_with('#'))
        .map(|(i, line)| (i + 1, line.trim().to_string()))
        .collect())
}

/// The fields of one line, parsed on demand, each error naming the file, the line and the
/// field.
struct Fields<'a> {
    path: &'a Path,
    line: usize,
    parts: Vec<&'a str>,
}

impl<'a> Fields<'a> {
    fn new(path: &'a Path, line: usize, text: &'a str) -> Self {
        Self {
            path,
            line,
            parts: text.split_whitespace().collect(),
        }
    }

    /// Field `i`, called `what`, parsed as `T`.
    fn get<T: FromStr>(&self, i: usize, what: &str) -> Result<T> {
        let raw = self.parts.get(i).ok_or_else(|| {
            model_error(
                self.path.to_path_buf(),
                format!("line {}: missing field {i} ({what})", self.line),
            )
        })?;
        raw.parse().map_err(|_| {
            model_error(
                self.path.to_path_buf(),
                format!(
                    "line {}: field {i} ({what}) `{raw}` is not a valid value",
                    self.line
                ),
            )
        })
    }

    /// Fields `from..from + N` as `f64`, called `what`.
    fn floats<const N: usize>(&self, from: usize, what: &str) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for (k, slot) in out.iter_mut().enumerate() {
            *slot = self.get(from + k, what)?;
        }
        Ok(out)
    }
}

/// `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`.
pub(super) fn cameras(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>> {
    let mut cameras = BTreeMap::new();
    for (line, text) in records(path)? {
        if text.is_empty() {
            continue;
        }
        let f = Fields::new(path, line, &text);
        let name: String = f.get(1, "MODEL")?;
        let model = CameraModel::from_name(&name).ok_or_else(|| {
            model_error(
                path.to_path_buf(),
                format!("line {line}: unknown camera model `{name}`"),
            )
        })?;
        let count = model.parameter_count();
        if f.parts.len() != 4 + count {
            return Err(model_error(
                path.to_path_buf(),
                format!(
                    "line {line}: a {model} camera has {count} parameters, the line has {}",
                    f.parts.len().saturating_sub(4)
                ),
            ));
        }
        let params = (0..count)
            .map(|k| f.get(4 + k, "PARAMS"))
            .collect::<Result<Vec<f64>>>()?;
        let camera = ColmapCamera {
            id: f.get(0, "CAMERA_ID")?,
            model,
            width: f.get(2, "WIDTH")?,
            height: f.get(3, "HEIGHT")?,
            params,
        };
        cameras.insert(camera.id, camera);
    }
    Ok(cameras)
}

/// `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, each followed by its line of 2D points.
pub(super) fn images(path: &Path) -> Result<Vec<ColmapImage>> {
    let records = records(path)?;
    let mut images = Vec::new();
    let mut lines = records.iter();
    while let Some((line, text)) = lines.next() {
        if text.is_empty() {
            continue;
        }
        let f = Fields::new(path, *line, text);
        if f.parts.len() < 10 {
            return Err(model_error(
                path.to_path_buf(),
                format!(
                    "line {line}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {} fields",
                    f.parts.len()
                ),
            ));
        }
        images.push(ColmapImage {
            id: f.get(0, "IMAGE_ID")?,
            rotation: f.floats(1, "QW QX QY QZ")?,
            translation: f.floats(5, "TX TY TZ")?,
            camera_id: f.get(8, "CAMERA_ID")?,
            // A name may hold spaces: everything after the camera id.
            name: f.parts[9..].join(" "),
        });
        // The 2D points' line (possibly blank, possibly missing at the end of the file).
        lines.next();
    }
    Ok(images)
}

/// `POINT3D_ID X Y Z R G B ERROR TRACK[]` (the track as image id and point index pairs).
pub(super) fn points(path: &Path) -> Result<Vec<ColmapPoint>> {
    let mut points = Vec::new();
    for (line, text) in records(path)? {
        if text.is_empty() {
            continue;
        }
        let f = Fields::new(path, line, &text);
        points.push(ColmapPoint {
            id: f.get(0, "POINT3D_ID")?,
            position: f.floats(1, "X Y Z")?,
            colour: [f.get(4, "R")?, f.get(5, "G")?, f.get(6, "B")?],
            error: f.get(7, "ERROR")?,
            track_length: f.parts.len().saturating_sub(8) / 2,
        });
    }
    Ok(points)
}
