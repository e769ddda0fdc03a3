//! A COLMAP reconstruction and its photos as a dataset volgen trains on: the capture turned
//! upright, centred and scaled into the model's cube ([`crate::placement::Placement`]), each photo written as
//! RGBA (its own alpha, or a mask image as alpha), and a `transforms.json` with per-frame
//! intrinsics, `depth_kind` "none" and the placement recorded.

use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use serde_json::json;

use super::{model_error, CameraModel, ColmapCamera, ColmapModel};
use crate::error::{invalid, io_error, Error, Result};
use crate::io::{create_dir, write_bytes};
use crate::lens::Undistortion;
use crate::placement::{Foreground, Placement, SparseCapture, UpFrom};

/// Where a capture's pictures are.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// The photos the reconstruction was made from (`colmap feature_extractor --image_path`).
    pub images: PathBuf,
    /// Masks of the foreground, one per photo with the photo's file name (PNG: `.png` appended
    /// when the name has another extension), white on the scene, black elsewhere; `None`: the
    /// photos' own alpha channel.
    pub masks: Option<PathBuf>,
    /// Which way is up ([`crate::placement::up_direction`]): the ground plane's normal where credible (the
    /// default), or the cameras' mean up.
    pub up: UpFrom,
}

/// What [`import`] wrote.
#[derive(Debug, Clone)]
pub struct ImportSummary {
    /// The `transforms.json` written.
    pub transforms: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// Width of the photos, pixels.
    pub width: u32,
    /// Height of the photos, pixels.
    pub height: u32,
    /// How the capture was placed in the model's cube.
    pub placement: Placement,
    /// The cameras whose photos were undistorted (lens models other than the pinholes).
    pub undistorted: Vec<UndistortedCamera>,
}

/// A camera whose photos [`import`] undistorted.
#[derive(Debug, Clone, PartialEq)]
pub struct UndistortedCamera {
    /// The camera's id in the reconstruction.
    pub id: u32,
    /// Its lens model.
    pub model: CameraModel,
    /// `fx, fy, cx, cy` of the photos' camera, pixels.
    pub photo: [f64; 4],
    /// `fx, fy, cx, cy` of the pinhole camera written (same size and principal point, the focal
    /// lengths scaled so that every pixel is seen).
    pub pinhole: [f64; 4],
}

/// Writes the reconstruction in `model_dir` ([`ColmapModel::read`]) with its photos as a
/// dataset in `out`: `images/NNN.png` (RGBA) and `transforms.json` (written last), the scene
/// placed in the model's cube ([`Placement`]). Photos of cameras with lens distortion
/// (SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE) are undistorted into pinhole cameras
/// ([`crate::lens::Undistortion`]); other distorting models are refused by name.
/// Photos need a foreground: their alpha channel or `options.masks`; photos that are opaque
/// everywhere with no masks are refused, since the model learns a bounded scene.
pub fn import(model_dir: &Path, options: &ImportOptions, out: &Path) -> Result<ImportSummary> {
    let model = ColmapModel::read(model_dir)?;
    let size = common_size(&model, model_dir)?;
    // Only the cameras of registered images: a model may hold others (of images the mapper
    // dropped), whose sizes and lenses the dataset never sees.
    let mut undistortions = BTreeMap::new();
    for image in &model.images {
        if !undistortions.contains_key(&image.camera_id) {
            let camera = &model.cameras[&image.camera_id];
            undistortions.insert(camera.id, undistortion(camera, size, model_dir)?);
        }
    }
    let photos = model
        .images
        .iter()
        .map(|image| {
            let photo = photo_with_alpha(&image.name, options, size)?;
            let undistortion = &undistortions[&image.camera_id];
            Ok(if undistortion.is_identity() {
                photo
            } else {
                undistortion.apply(&photo)
            })
        })
        .collect::<Result<Vec<_>>>()?;
    if photos
        .iter()
        .all(|photo| photo.pixels().all(|p| p[3] == u8::MAX))
    {
        return Err(invalid(
            "photos",
            format!(
                "every photo in {} is opaque everywhere and no --masks were given: volgen learns a \
                 bounded scene and needs to know which pixels show it (an alpha channel, or mask \
                 images white on the scene)",
                options.images.display()
            ),
        ));
    }
    let intrinsics: Vec<[f64; 4]> = model
        .images
        .iter()
        .map(|image| undistortions[&image.camera_id].pinhole())
        .collect();
    let foreground: Vec<Foreground> = photos
        .iter()
        .zip(&intrinsics)
        .map(|(photo, &intrinsics)| Foreground {
            intrinsics,
            size: (size.0 as usize, size.1 as usize),
            alpha: photo.pixels().map(|p| p[3]).collect(),
        })
        .collect();
    let placement = Placement::of_foreground(&(&model).into(), &foreground, options.up)?;
    create_dir(&out.join("images"))?;
    let transforms_path = out.join("transforms.json");
    radiance_volume::io::remove_file_if_exists(&transforms_path)?;
    let mut frames = Vec::with_capacity(model.images.len());
    for (i, ((image, rgba), [fx, fy, cx, cy])) in model
        .images
        .iter()
        .zip(&photos)
        .zip(&intrinsics)
        .enumerate()
    {
        let file = format!("images/{i:03}.png");
        let mut bytes = Vec::new();
        rgba.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| invalid(file.clone(), e.to_string()))?;
        write_bytes(&out.join(&file), &bytes)?;
        let c2w = placement.place_camera(image.camera_to_world());
        let rows: Vec<[f64; 4]> = (0..4).map(|r| c2w.row(r).to_array()).collect();
        let camera = &model.cameras[&image.camera_id];
        frames.push(json!({
            "file_path": file,
            "colmap_name": image.name,
            "colmap_camera_model": camera.model.name(),
            "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy,
            "transform_matrix": rows,
        }));
    }
    let matrix: Vec<[f64; 4]> = (0..4)
        .map(|r| placement.matrix().row(r).to_array())
        .collect();
    let root = json!({
        "w": size.0,
        "h": size.1,
        "depth_kind": "none",
        "volgen_import": {
            "from": "colmap",
            "model": model_dir.display().to_string(),
            "capture_to_dataset": matrix,
            "scale": placement.scale,
        },
        "frames": frames,
    });
    let text = serde_json::to_string_pretty(&root)
        .map_err(|e| invalid("transforms.json", e.to_string()))?;
    write_bytes(&transforms_path, text.as_bytes())?;
    Ok(ImportSummary {
        transforms: transforms_path,
        frames: model.images.len(),
        width: size.0,
        height: size.1,
        placement,
        undistorted: undistortions
            .iter()
            .filter(|(_, undistortion)| !undistortion.is_identity())
            .map(|(id, undistortion)| UndistortedCamera {
                id: *id,
                model: model.cameras[id].model,
                photo: undistortion.photo(),
                pinhole: undistortion.pinhole(),
            })
            .collect(),
    })
}

impl From<&ColmapModel> for SparseCapture {
    /// The model's registered cameras (in file order) and points, as placing it reads them.
    fn from(model: &ColmapModel) -> Self {
        Self {
            cameras: model.images.iter().map(|i| i.camera_to_world()).collect(),
            points: model.points.iter().map(|p| p.position.into()).collect(),
        }
    }
}

/// The one image size every camera of the model has (a dataset's images share one size).
fn common_size(model: &ColmapModel, dir: &Path) -> Result<(u32, u32)> {
    let mut sizes = model.images.iter().map(|image| {
        let camera = &model.cameras[&image.camera_id];
        (camera.width, camera.height)
    });
    let Some(first) = sizes.next() else {
        return Err(model_error(dir.to_path_buf(), "no registered images"));
    };
    if let Some(other) = sizes.find(|&s| s != first) {
        return Err(model_error(
            dir.to_path_buf(),
            format!(
                "the cameras have different image sizes ({} x {} and {} x {}); a dataset's images \
                 share one size: resize the photos to one size before the reconstruction",
                first.0, first.1, other.0, other.1
            ),
        ));
    }
    let fit = |v: u64| u32::try_from(v).ok().filter(|&v| v > 0);
    match (fit(first.0), fit(first.1)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(model_error(
            dir.to_path_buf(),
            format!(
                "camera size {} x {} is not a picture size",
                first.0, first.1
            ),
        )),
    }
}

/// How `camera`'s photos, of the checked common `size`, become pinhole ones; models volgen does
/// not undistort are refused naming the model.
fn undistortion(camera: &ColmapCamera, size: (u32, u32), dir: &Path) -> Result<Undistortion> {
    let Some((intrinsics, lens)) = camera.lens() else {
        return Err(model_error(
            dir.to_path_buf(),
            format!(
                "camera {} is {}, a lens model volgen does not undistort (it does {}): undistort \
                 the photos first (`colmap image_undistorter --image_path IMAGES --input_path \
                 SPARSE --output_path UNDISTORTED` writes PINHOLE cameras and the undistorted \
                 photos), then import UNDISTORTED/sparse with --images UNDISTORTED/images",
                camera.id,
                camera.model,
                ColmapCamera::UNDISTORTED_MODELS
            ),
        ));
    };
    Undistortion::new(lens, intrinsics, size).map_err(|why| {
        model_error(
            dir.to_path_buf(),
            format!("camera {} ({}): {why}", camera.id, camera.model),
        )
    })
}

/// The photo `name` as RGBA: its alpha, or the mask's grey as alpha.
fn photo_with_alpha(
    name: &str,
    options: &ImportOptions,
    (width, height): (u32, u32),
) -> Result<image::RgbaImage> {
    let path = options.images.join(name);
    let photo = image::open(&path).map_err(|e| photo_error(&path, e.to_string()))?;
    if (photo.width(), photo.height()) != (width, height) {
        return Err(photo_error(
            &path,
            format!(
                "is {} x {} pixels, its camera {width} x {height}",
                photo.width(),
                photo.height()
            ),
        ));
    }
    let mut rgba = photo.to_rgba8();
    if let Some(masks) = &options.masks {
        let mask_path = mask_file(masks, name);
        let mask = image::open(&mask_path)
            .map_err(|e| photo_error(&mask_path, e.to_string()))?
            .to_luma8();
        if mask.dimensions() != (width, height) {
            return Err(photo_error(
                &mask_path,
                format!(
                    "is {} x {} pixels, its photo {width} x {height}",
                    mask.width(),
                    mask.height()
                ),
            ));
        }
        for (pixel, m) in rgba.pixels_mut().zip(mask.pixels()) {
            pixel[3] = m[0];
        }
    }
    Ok(rgba)
}

/// The mask of photo `name`: the same name in `masks`, or with `.png` appended or put in place of
/// its extension (nerfstudio's masks are PNG whatever the photos are).
fn mask_file(masks: &Path, name: &str) -> PathBuf {
    let same = masks.join(name);
    if same.is_file() {
        return same;
    }
    let replaced = masks.join(Path::new(name).with_extension("png"));
    if replaced.is_file() {
        return replaced;
    }
    masks.join(format!("{name}.png"))
}

fn photo_error(path: &Path, why: String) -> Error {
    match std::fs::metadata(path) {
        Err(e) => io_error(path)(e),
        Ok(_) => Error::Dataset {
            path: path.to_path_buf(),
            frame: None,
            why,
        },
    }
}
