//! A COLMAP reconstruction and its photos as a dataset volgen trains on: the capture turned
//! upright, centred and scaled into the model's cube ([`Placement`]), each photo written as
//! RGBA (its own alpha, or a mask image as alpha), and a `transforms.json` with per-frame
//! intrinsics, `depth_kind` "none" and the placement recorded.

use std::path::{Path, PathBuf};

use std::collections::BTreeMap;

use glam::{DMat3, DMat4, DVec3};
use serde_json::json;

use super::up::{rotation_between, up_direction, UpFrom};
use super::{model_error, CameraModel, ColmapCamera, ColmapModel};
use crate::error::{invalid, io_error, Error, Result};
use crate::io::{create_dir, write_bytes};
use crate::lens::Undistortion;

/// Where the capture's points go: all but the outermost 1% on each side per axis (between
/// these percentiles) fill this much of the model's half side, as `--bounds auto` places a scene
/// from its depth maps (1st to 99th percentile, 5% margin each side): stray points far out do
/// not shrink the scene, and its edges stay inside the cube. (The 5th to 95th percentiles filling
/// 0.9 cut off the ground of a Blender scene: a fit of its views reached 18.4 dB.)
const POINT_PERCENTILES: (f64, f64) = (0.01, 0.99);
const FILLED_HALF_SIDE: f64 = 1.0 / 1.1;

/// The similarity from a capture's frame to the dataset's: `p' = scale * rotation * (p -
/// centre)`. The rotation turns the up direction to +z (the ground plane's normal or the
/// cameras' mean up, [`up_direction`]); the centre and scale put the middle of the scene's box at the
/// origin and its largest half side at 1 / 1.1 of the cube's, as `--bounds auto` places a scene
/// from its depth maps. The scene's box is the box of the foreground's visual hull when the
/// photos' foreground is known ([`Placement::of_foreground`]) across, the sparse points'
/// central 98% up and down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    pub rotation: DMat3,
    pub centre: DVec3,
    pub scale: f64,
    /// Where the up direction the rotation turns to +z came from ([`up_direction`]).
    pub up: UpFrom,
}

impl Placement {
    /// The placement with the box of the foreground's visual hull: the points of space that
    /// every photo seeing them shows as foreground (`foreground[i]`, one per registered image,
    /// in order). Sparse points
    /// miss the parts of a scene where few features are found (a plain ground's far edges, seen
    /// obliquely); the masks do not. The hull bounds the scene across (x and y after turning it
    /// upright), searched on a grid over twice the points' box across and between their lowest
    /// and highest up and down, among the grid points at least half the photos frame; up and
    /// down the points' box bounds it (photos from around and above carve neither under the
    /// ground nor far above it).
    pub fn of_foreground(
        model: &ColmapModel,
        foreground: &[Foreground],
        up: UpFrom,
    ) -> Result<Self> {
        let (rotation, up) = upright(model, up)?;
        let (low, high) = points_box(model, rotation);
        // Across, the hull; up and down, the points: photos from around and above carve the
        // sides well, but not below the ground (which hides it: the hull there spreads wider
        // than the ground) nor far above it. So the hull is searched over twice the points' box
        // across, between their lowest and highest up and down.
        let (centre, half) = (0.5 * (low + high), (high - low).max(DVec3::splat(1e-9)));
        let search = (
            DVec3::new(centre.x - half.x, centre.y - half.y, low.z),
            DVec3::new(centre.x + half.x, centre.y + half.y, high.z),
        );
        let Some((hull_low, hull_high)) = hull_box(model, foreground, rotation, search) else {
            return Self::around((rotation, up), (low, high));
        };
        let low = DVec3::new(hull_low.x, hull_low.y, low.z);
        let high = DVec3::new(hull_high.x, hull_high.y, high.z);
        Self::around((rotation, up), (low, high))
    }

    /// Centres and scales the box `(low, high)` of the turned frame.
    fn around((rotation, up): (DMat3, UpFrom), (low, high): (DVec3, DVec3)) -> Result<Self> {
        let half = 0.5 * (high - low);
        if half.max_element() <= 0.0 {
            return Err(invalid(
                "COLMAP model",
                "the scene's box has no extent: too few or identical points",
            ));
        }
        Ok(Self {
            rotation,
            centre: rotation.transpose() * (0.5 * (low + high)),
            scale: FILLED_HALF_SIDE / half.max_element(),
            up,
        })
    }

    /// The placement as a 4x4 matrix acting on points.
    pub fn matrix(&self) -> DMat4 {
        DMat4::from_scale(DVec3::splat(self.scale))
            * DMat4::from_mat3(self.rotation)
            * DMat4::from_translation(-self.centre)
    }

    /// A camera-to-world matrix (rigid) of the capture as one of the dataset: rotated, its
    /// centre placed; still rigid (the scale moves centres only).
    pub fn place_camera(&self, c2w: DMat4) -> DMat4 {
        let rotation = self.rotation * DMat3::from_mat4(c2w);
        let centre = self.matrix().transform_point3(c2w.w_axis.truncate());
        let mut placed = DMat4::from_mat3(rotation);
        placed.w_axis = centre.extend(1.0);
        placed
    }
}

/// The rotation turning the up direction `up` asks for to +z, and where up came from; errors
/// without images or points.
fn upright(model: &ColmapModel, up: UpFrom) -> Result<(DMat3, UpFrom)> {
    if model.images.is_empty() || model.points.is_empty() {
        return Err(invalid(
            "COLMAP model",
            format!(
                "needs registered images and 3D points to place the scene, has {} images and {} \
                 points",
                model.images.len(),
                model.points.len()
            ),
        ));
    }
    Ok(match up_direction(model, up) {
        Some((direction, used)) => (rotation_between(direction, DVec3::Z), used),
        None => (DMat3::IDENTITY, UpFrom::Cameras),
    })
}

/// The box of the points turned by `rotation`, between the [`POINT_PERCENTILES`].
fn points_box(model: &ColmapModel, rotation: DMat3) -> (DVec3, DVec3) {
    let turned: Vec<DVec3> = model
        .points
        .iter()
        .map(|p| rotation * DVec3::from(p.position))
        .collect();
    central_box(&turned)
}

/// Cells per axis of the grid the visual hull is searched on.
const HULL_GRID: usize = 64;

/// The box (in the turned frame) of the grid points of `search` that every photo framing them
/// shows as foreground, and that at least half the photos (and two) frame; `None` when no point
/// is kept.
fn hull_box(
    model: &ColmapModel,
    foreground: &[Foreground],
    rotation: DMat3,
    (low, high): (DVec3, DVec3),
) -> Option<(DVec3, DVec3)> {
    let views: Vec<MaskedView<'_>> = model
        .images
        .iter()
        .zip(foreground)
        .map(|(image, photo)| {
            let camera = &model.cameras[&image.camera_id];
            MaskedView {
                rotation: image.world_to_camera_rotation(),
                translation: DVec3::from(image.translation),
                intrinsics: photo.intrinsics,
                size: (camera.width as usize, camera.height as usize),
                alpha: &photo.alpha,
            }
        })
        .collect();
    // A point of the scene is in most photos' frame; points that few photos frame are not
    // carved by the others and would otherwise stay.
    let min_framed = (views.len() / 2).max(2);
    let step = (high - low) / HULL_GRID as f64;
    let mut kept: Option<(DVec3, DVec3)> = None;
    for k in 0..HULL_GRID {
        for j in 0..HULL_GRID {
            for i in 0..HULL_GRID {
                let turned =
                    low + step * DVec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5);
                let world = rotation.transpose() * turned;
                let mut framed = 0;
                let inside = views.iter().all(|view| match view.shows(world) {
                    None => true,
                    Some(foreground) => {
                        framed += 1;
                        foreground
                    }
                });
                if inside && framed >= min_framed {
                    let (lo, hi) = kept.get_or_insert((turned, turned));
                    *lo = lo.min(turned - 0.5 * step);
                    *hi = hi.max(turned + 0.5 * step);
                }
            }
        }
    }
    kept
}

/// A registered photo's foreground, as [`Placement::of_foreground`] reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Foreground {
    /// `fx, fy, cx, cy` of the photo's pinhole camera (after undistortion), in pixels.
    pub intrinsics: [f64; 4],
    /// Opacity bytes, row-major at the camera's size; above half is foreground.
    pub alpha: Vec<u8>,
}

/// A registered photo as the visual hull sees it: its pose, pinhole intrinsics and foreground.
struct MaskedView<'a> {
    rotation: DMat3,
    translation: DVec3,
    intrinsics: [f64; 4],
    size: (usize, usize),
    /// Opacity bytes, row-major.
    alpha: &'a [u8],
}

impl MaskedView<'_> {
    /// Whether the photo shows the world point as foreground (opacity above half), or `None`
    /// when the point is behind the camera or outside the frame.
    fn shows(&self, world: DVec3) -> Option<bool> {
        let c = self.rotation * world + self.translation;
        let [fx, fy, cx, cy] = self.intrinsics;
        let (w, h) = self.size;
        let (u, v) = (fx * c.x / c.z + cx, fy * c.y / c.z + cy);
        let framed = c.z > 0.0 && u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64;
        framed.then(|| self.alpha[v as usize * w + u as usize] > u8::MAX / 2)
    }
}

/// Per axis the [`POINT_PERCENTILES`] of `points`.
pub(super) fn central_box(points: &[DVec3]) -> (DVec3, DVec3) {
    let mut low = DVec3::ZERO;
    let mut high = DVec3::ZERO;
    for axis in 0..3 {
        let mut values: Vec<f64> = points.iter().map(|p| p[axis]).collect();
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        low[axis] = at(POINT_PERCENTILES.0);
        high[axis] = at(POINT_PERCENTILES.1);
    }
    (low, high)
}

/// Where a capture's pictures are.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// The photos the reconstruction was made from (`colmap feature_extractor --image_path`).
    pub images: PathBuf,
    /// Masks of the foreground, one per photo with the photo's file name (PNG: `.png` appended
    /// when the name has another extension), white on the scene, black elsewhere; `None`: the
    /// photos' own alpha channel.
    pub masks: Option<PathBuf>,
    /// Which way is up ([`up_direction`]): the ground plane's normal where credible (the
    /// default), or the cameras' mean up.
    pub up: UpFrom,
}

/// What [`import`] wrote.
#[derive(Debug, Clone)]
pub struct ImportSummary {
    pub transforms: PathBuf,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub placement: Placement,
    /// The cameras whose photos were undistorted (lens models other than the pinholes).
    pub undistorted: Vec<UndistortedCamera>,
}

/// A camera whose photos [`import`] undistorted.
#[derive(Debug, Clone, PartialEq)]
pub struct UndistortedCamera {
    pub id: u32,
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
            alpha: photo.pixels().map(|p| p[3]).collect(),
        })
        .collect();
    let placement = Placement::of_foreground(&model, &foreground, options.up)?;
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
