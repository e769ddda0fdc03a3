//! COLMAP's sparse reconstructions (structure from motion), as `colmap mapper` writes them: a
//! directory with `cameras`, `images` and `points3D`, each either `.bin` (COLMAP's default) or
//! `.txt` (`colmap model_converter --output_type TXT`). [`ColmapModel::read`] reads either
//! encoding; [`ColmapImage::camera_to_world`] turns COLMAP's world-to-camera poses (OpenCV axes:
//! x right, y down, z forward) into the NeRF convention datasets use (x right, y up, looking
//! down -z). [`import`] writes a reconstruction and its photos as a dataset (`volgen import
//! colmap`).
//!
//! ```
//! use rgbd_dataset::colmap::{CameraModel, ColmapModel};
//! let dir = tempfile::tempdir()?;
//! std::fs::write(dir.path().join("cameras.txt"), "1 PINHOLE 640 480 500 500 320 240\n")?;
//! std::fs::write(
//!     dir.path().join("images.txt"),
//!     "# one image, the identity pose\n1 1 0 0 0 0 0 0 1 photo.jpg\n\n",
//! )?;
//! std::fs::write(dir.path().join("points3D.txt"), "7 0 0 5 255 0 0 0.5 1 0\n")?;
//! let model = ColmapModel::read(dir.path())?;
//! assert_eq!(model.cameras[&1].model, CameraModel::Pinhole);
//! assert_eq!(model.images[0].name, "photo.jpg");
//! // COLMAP's identity pose looks down +z; in the NeRF convention the camera's -z does.
//! let c2w = model.images[0].camera_to_world();
//! assert_eq!(c2w.z_axis.truncate(), glam::DVec3::NEG_Z);
//! assert_eq!(model.points[0].position, [0.0, 0.0, 5.0]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod binary;
mod import;
mod text;

pub use import::{import, ImportOptions, ImportSummary, UndistortedCamera};

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DQuat, DVec3, DVec4};

use crate::error::{Error, Result};
use crate::lens::Lens;

/// A camera model of COLMAP, by its id in the binary files and its name in the text ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraModel {
    /// `f, cx, cy`.
    SimplePinhole,
    /// `fx, fy, cx, cy`.
    Pinhole,
    /// `f, cx, cy, k`: one radial distortion term.
    SimpleRadial,
    /// `f, cx, cy, k1, k2`.
    Radial,
    /// `fx, fy, cx, cy, k1, k2, p1, p2`: radial and tangential distortion.
    OpenCv,
    /// `fx, fy, cx, cy, k1, k2, k3, k4`: the equidistant fisheye.
    OpenCvFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6`.
    FullOpenCv,
    /// `fx, fy, cx, cy, omega`.
    Fov,
    /// `f, cx, cy, k`.
    SimpleRadialFisheye,
    /// `f, cx, cy, k1, k2`.
    RadialFisheye,
    /// `fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1`.
    ThinPrismFisheye,
}

/// Every model with its binary id, text name and parameter count, in id order.
const MODELS: [(CameraModel, &str, usize); 11] = [
    (CameraModel::SimplePinhole, "SIMPLE_PINHOLE", 3),
    (CameraModel::Pinhole, "PINHOLE", 4),
    (CameraModel::SimpleRadial, "SIMPLE_RADIAL", 4),
    (CameraModel::Radial, "RADIAL", 5),
    (CameraModel::OpenCv, "OPENCV", 8),
    (CameraModel::OpenCvFisheye, "OPENCV_FISHEYE", 8),
    (CameraModel::FullOpenCv, "FULL_OPENCV", 12),
    (CameraModel::Fov, "FOV", 5),
    (CameraModel::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4),
    (CameraModel::RadialFisheye, "RADIAL_FISHEYE", 5),
    (CameraModel::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12),
];

impl CameraModel {
    /// The model of a binary file's id.
    pub fn from_id(id: i32) -> Option<Self> {
        usize::try_from(id)
            .ok()
            .and_then(|i| MODELS.get(i))
            .map(|m| m.0)
    }

    /// The model of a text file's name (`PINHOLE`, ...).
    pub fn from_name(name: &str) -> Option<Self> {
        MODELS.iter().find(|m| m.1 == name).map(|m| m.0)
    }

    /// COLMAP's name of the model.
    pub fn name(self) -> &'static str {
        self.entry().1
    }

    /// How many parameters the model has.
    pub fn parameter_count(self) -> usize {
        self.entry().2
    }

    fn entry(self) -> &'static (CameraModel, &'static str, usize) {
        MODELS
            .iter()
            .find(|m| m.0 == self)
            .expect("every model is in the table")
    }
}

impl fmt::Display for CameraModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One camera (intrinsics) of a reconstruction.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapCamera {
    /// The camera's id.
    pub id: u32,
    /// Its lens model.
    pub model: CameraModel,
    /// Image width, pixels.
    pub width: u64,
    /// Image height, pixels.
    pub height: u64,
    /// The model's parameters in COLMAP's order ([`CameraModel`] lists them).
    pub params: Vec<f64>,
}

/// One registered image: its pose (world to camera, COLMAP's convention) and camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapImage {
    /// The image's id.
    pub id: u32,
    /// The rotation world to camera as a unit quaternion `(w, x, y, z)`.
    pub rotation: [f64; 4],
    /// The translation world to camera: a world point `X` is `R X + t` in the camera's frame.
    pub translation: [f64; 3],
    /// The id of the camera ([`ColmapCamera`]) that took it.
    pub camera_id: u32,
    /// The image file's name, relative to the images directory the reconstruction used.
    pub name: String,
}

/// One triangulated point.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapPoint {
    /// The point's id.
    pub id: u64,
    /// Its position in the reconstruction's frame.
    pub position: [f64; 3],
    /// Its colour, 8-bit RGB.
    pub colour: [u8; 3],
    /// Mean reprojection error in pixels.
    pub error: f64,
    /// How many images see it.
    pub track_length: usize,
}

/// A sparse reconstruction: cameras by id, registered images in file order, points.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ColmapModel {
    /// Cameras by id.
    pub cameras: BTreeMap<u32, ColmapCamera>,
    /// Registered images, in file order.
    pub images: Vec<ColmapImage>,
    /// Triangulated points.
    pub points: Vec<ColmapPoint>,
}

impl ColmapModel {
    /// Reads the model in `dir`: `cameras.bin`, `images.bin` and `points3D.bin` when
    /// `cameras.bin` exists, else the three `.txt` files. Errors name the file and, in text
    /// files, the line; an image whose camera is missing is an error naming both.
    pub fn read(dir: &Path) -> Result<Self> {
        let binary = dir.join("cameras.bin").is_file();
        let (extension, encoding) = if binary {
            ("bin", "binary")
        } else {
            ("txt", "text")
        };
        let file = |stem: &str| dir.join(format!("{stem}.{extension}"));
        for stem in ["cameras", "images", "points3D"] {
            if !file(stem).is_file() {
                return Err(model_error(
                    file(stem),
                    format!(
                        "missing: a COLMAP {encoding} model has cameras, images and points3D \
                         (.bin or .txt, as `colmap mapper` or `colmap model_converter` write them)"
                    ),
                ));
            }
        }
        let model = if binary {
            Self {
                cameras: binary::cameras(&file("cameras"))?,
                images: binary::images(&file("images"))?,
                points: binary::points(&file("points3D"))?,
            }
        } else {
            Self {
                cameras: text::cameras(&file("cameras"))?,
                images: text::images(&file("images"))?,
                points: text::points(&file("points3D"))?,
            }
        };
        for image in &model.images {
            if !model.cameras.contains_key(&image.camera_id) {
                return Err(model_error(
                    file("images"),
                    format!(
                        "image {} (`{}`) has camera {}, which {} does not hold",
                        image.id,
                        image.name,
                        image.camera_id,
                        file("cameras").display()
                    ),
                ));
            }
        }
        Ok(model)
    }
}

impl ColmapCamera {
    /// The models [`ColmapCamera::lens`] knows, for messages.
    pub const UNDISTORTED_MODELS: &'static str =
        "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV and OPENCV_FISHEYE";

    /// `fx, fy, cx, cy` (pixels) and the lens of the camera; `None` for the models volgen does
    /// not undistort itself (FULL_OPENCV, FOV and the other fisheyes: `colmap
    /// image_undistorter` does).
    pub fn lens(&self) -> Option<([f64; 4], Lens)> {
        let p = &self.params;
        let radial = |k: &[f64]| {
            let mut radial = [0.0; 4];
            radial[..k.len()].copy_from_slice(k);
            Lens::BrownConrady {
                radial,
                tangential: [0.0; 2],
            }
        };
        Some(match self.model {
            CameraModel::SimplePinhole => ([p[0], p[0], p[1], p[2]], Lens::Pinhole),
            CameraModel::Pinhole => ([p[0], p[1], p[2], p[3]], Lens::Pinhole),
            CameraModel::SimpleRadial => ([p[0], p[0], p[1], p[2]], radial(&p[3..4])),
            CameraModel::Radial => ([p[0], p[0], p[1], p[2]], radial(&p[3..5])),
            CameraModel::OpenCv => (
                [p[0], p[1], p[2], p[3]],
                Lens::BrownConrady {
                    radial: [p[4], p[5], 0.0, 0.0],
                    tangential: [p[6], p[7]],
                },
            ),
            CameraModel::OpenCvFisheye => (
                [p[0], p[1], p[2], p[3]],
                Lens::Fisheye {
                    radial: [p[4], p[5], p[6], p[7]],
                },
            ),
            _ => return None,
        })
    }
}

impl ColmapImage {
    /// The rotation world to camera.
    pub fn world_to_camera_rotation(&self) -> DMat3 {
        let [w, x, y, z] = self.rotation;
        DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize())
    }

    /// The camera's centre in world coordinates, `-R^T t`.
    pub fn centre(&self) -> DVec3 {
        -(self.world_to_camera_rotation().transpose() * DVec3::from(self.translation))
    }

    /// Camera to world in the NeRF convention (x right, y up, looking down -z): COLMAP's camera
    /// axes (x right, y down, z forward) with y and z turned around.
    pub fn camera_to_world(&self) -> DMat4 {
        let to_world = self.world_to_camera_rotation().transpose();
        DMat4::from_cols(
            to_world.x_axis.extend(0.0),
            (-to_world.y_axis).extend(0.0),
            (-to_world.z_axis).extend(0.0),
            DVec4::from((self.centre(), 1.0)),
        )
    }
}

/// A malformed or missing model file.
fn model_error(path: PathBuf, why: impl Into<String>) -> Error {
    Error::Dataset {
        path,
        frame: None,
        why: why.into(),
    }
}

#[cfg(test)]
mod tests;
