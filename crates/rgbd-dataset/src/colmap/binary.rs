//! COLMAP's binary encoding: little-endian counts (`u64`), records of fixed fields, names
//! ending in a NUL byte.

use std::collections::BTreeMap;
use std::path::Path;

use super::{model_error, CameraModel, ColmapCamera, ColmapImage, ColmapPoint};
use crate::error::{io_error, Result};

/// A cursor over a file's bytes whose reads name the file, the record and the field when the
/// file ends early.
struct Reader<'a> {
    path: &'a Path,
    bytes: Vec<u8>,
    at: usize,
    /// What is being read, for errors: `camera 3`, ...
    record: String,
}

impl<'a> Reader<'a> {
    fn open(path: &'a Path) -> Result<Self> {
        Ok(Self {
            path,
            bytes: std::fs::read(path).map_err(io_error(path))?,
            at: 0,
            record: "the header".into(),
        })
    }

    fn take<const N: usize>(&mut self, field: &str) -> Result<[u8; N]> {
        let end = self.at + N;
        let Some(slice) = self.bytes.get(self.at..end) else {
            return Err(model_error(
                self.path.to_path_buf(),
                format!(
                    "ends at byte {} inside {}, field {field} (truncated?)",
                    self.bytes.len(),
                    self.record
                ),
            ));
        };
        self.at = end;
        Ok(slice.try_into().expect("the slice has N bytes"))
    }

    fn u64(&mut self, field: &str) -> Result<u64> {
        self.take(field).map(u64::from_le_bytes)
    }

    fn u32(&mut self, field: &str) -> Result<u32> {
        self.take(field).map(u32::from_le_bytes)
    }

    fn i32(&mut self, field: &str) -> Result<i32> {
        self.take(field).map(i32::from_le_bytes)
    }

    fn f64(&mut self, field: &str) -> Result<f64> {
        self.take(field).map(f64::from_le_bytes)
    }

    fn u8(&mut self, field: &str) -> Result<u8> {
        self.take::<1>(field).map(|b| b[0])
    }

    fn floats<const N: usize>(&mut self, field: &str) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for slot in &mut out {
            *slot = self.f64(field)?;
        }
        Ok(out)
    }

    /// A count of records, checked against the bytes left (each at least `min_size` bytes),
    /// so that a corrupt count cannot ask for a huge allocation.
    fn count(&mut self, field: &str, min_size: usize) -> Result<usize> {
        let count = self.u64(field)?;
        let left = (self.bytes.len() - self.at) as u64;
        if count.saturating_mul(min_size as u64) > left {
            return Err(model_error(
                self.path.to_path_buf(),
                format!(
                    "{}: {field} says {count}, but only {left} bytes follow (truncated or not a \
                     COLMAP model?)",
                    self.record
                ),
            ));
        }
        Ok(count as usize)
    }

    /// Skips `count` records of `size` bytes.
    fn skip(&mut self, count: usize, size: usize, field: &str) -> Result<()> {
        let end = self.at + count * size;
        if end > self.bytes.len() {
            return Err(model_error(
                self.path.to_path_buf(),
                format!("ends inside {}, field {field} (truncated?)", self.record),
            ));
        }
        self.at = end;
        Ok(())
    }

    /// A NUL-terminated UTF-8 string.
    fn name(&mut self, field: &str) -> Result<String> {
        let rest = &self.bytes[self.at..];
        let Some(len) = rest.iter().position(|&b| b == 0) else {
            return Err(model_error(
                self.path.to_path_buf(),
                format!(
                    "{}: field {field} has no terminating NUL (truncated?)",
                    self.record
                ),
            ));
        };
        let name = std::str::from_utf8(&rest[..len]).map_err(|_| {
            model_error(
                self.path.to_path_buf(),
                format!("{}: field {field} is not UTF-8", self.record),
            )
        })?;
        self.at += len + 1;
        Ok(name.to_string())
    }

    /// Errors unless every byte was read.
    fn finish(self) -> Result<()> {
        if self.at == self.bytes.len() {
            return Ok(());
        }
        Err(model_error(
            self.path.to_path_buf(),
            format!(
                "{} bytes follow the last record (not a COLMAP model of this kind?)",
                self.bytes.len() - self.at
            ),
        ))
    }
}

/// `u64` count, then per camera `i32 id, i32 model, u64 width, u64 height, f64 params[]`.
pub(super) fn cameras(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>> {
    let mut r = Reader::open(path)?;
    let count = r.count("the number of cameras", 24)?;
    let mut cameras = BTreeMap::new();
    for i in 0..count {
        r.record = format!("camera {i}");
        let id = r.u32("camera_id")?;
        let model_id = r.i32("model_id")?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            model_error(
                path.to_path_buf(),
                format!("camera {id}: unknown camera model id {model_id}"),
            )
        })?;
        let (width, height) = (r.u64("width")?, r.u64("height")?);
        let params = (0..model.parameter_count())
            .map(|_| r.f64("params"))
            .collect::<Result<Vec<f64>>>()?;
        cameras.insert(
            id,
            ColmapCamera {
                id,
                model,
                width,
                height,
                params,
            },
        );
    }
    r.finish()?;
    Ok(cameras)
}

/// `u64` count, then per image `u32 id, f64 qvec[4], f64 tvec[3], u32 camera_id, name\0, u64
/// points, (f64 x, f64 y, i64 point3D_id)[]`.
pub(super) fn images(path: &Path) -> Result<Vec<ColmapImage>> {
    let mut r = Reader::open(path)?;
    let count = r.count("the number of images", 64)?;
    let mut images = Vec::with_capacity(count);
    for i in 0..count {
        r.record = format!("image {i}");
        let id = r.u32("image_id")?;
        let rotation = r.floats("qvec")?;
        let translation = r.floats("tvec")?;
        let camera_id = r.u32("camera_id")?;
        let name = r.name("name")?;
        let points = r.count("num_points2D", 24)?;
        r.skip(points, 24, "points2D")?;
        images.push(ColmapImage {
            id,
            rotation,
            translation,
            camera_id,
            name,
        });
    }
    r.finish()?;
    Ok(images)
}

/// `u64` count, then per point `u64 id, f64 xyz[3], u8 rgb[3], f64 error, u64 track length,
/// (i32 image_id, i32 point2D_idx)[]`.
pub(super) fn points(path: &Path) -> Result<Vec<ColmapPoint>> {
    let mut r = Reader::open(path)?;
    let count = r.count("the number of points", 51)?;
    let mut points = Vec::with_capacity(count);
    for i in 0..count {
        r.record = format!("point {i}");
        let id = r.u64("point3D_id")?;
        let position = r.floats("xyz")?;
        let colour = [r.u8("rgb")?, r.u8("rgb")?, r.u8("rgb")?];
        let error = r.f64("error")?;
        let track_length = r.count("track_length", 8)?;
        r.skip(track_length, 8, "track")?;
        points.push(ColmapPoint {
            id,
            position,
            colour,
            error,
            track_length,
        });
    }
    r.finish()?;
    Ok(points)
}

#[cfg(test)]
pub(super) mod write {
    //! The binary encoding written back, for the tests: what `colmap mapper` writes.

    use super::super::{ColmapModel, MODELS};

    fn model_id(model: super::CameraModel) -> i32 {
        MODELS.iter().position(|m| m.0 == model).unwrap() as i32
    }

    /// `cameras.bin`, `images.bin` and `points3D.bin` of `model` (images with `points2d` 2D
    /// points each, all unmatched; points with a track of 2).
    pub fn files(model: &ColmapModel, points2d: usize) -> [Vec<u8>; 3] {
        let mut cameras = (model.cameras.len() as u64).to_le_bytes().to_vec();
        for c in model.cameras.values() {
            cameras.extend(c.id.to_le_bytes());
            cameras.extend(model_id(c.model).to_le_bytes());
            cameras.extend(c.width.to_le_bytes());
            cameras.extend(c.height.to_le_bytes());
            c.params
                .iter()
                .for_each(|p| cameras.extend(p.to_le_bytes()));
        }
        let mut images = (model.images.len() as u64).to_le_bytes().to_vec();
        for im in &model.images {
            images.extend(im.id.to_le_bytes());
            im.rotation
                .iter()
                .for_each(|v| images.extend(v.to_le_bytes()));
            im.translation
                .iter()
                .for_each(|v| images.extend(v.to_le_bytes()));
            images.extend(im.camera_id.to_le_bytes());
            images.extend(im.name.as_bytes());
            images.push(0);
            images.extend((points2d as u64).to_le_bytes());
            for k in 0..points2d {
                images.extend((k as f64).to_le_bytes());
                images.extend((2.0 * k as f64).to_le_bytes());
                images.extend((-1i64).to_le_bytes());
            }
        }
        let mut points = (model.points.len() as u64).to_le_bytes().to_vec();
        for p in &model.points {
            points.extend(p.id.to_le_bytes());
            p.position
                .iter()
                .for_each(|v| points.extend(v.to_le_bytes()));
            points.extend(p.colour);
            points.extend(p.error.to_le_bytes());
            points.extend((p.track_length as u64).to_le_bytes());
            for k in 0..p.track_length {
                points.extend((k as i32).to_le_bytes());
                points.extend((k as i32 + 5).to_le_bytes());
            }
        }
        [cameras, images, points]
    }
}
