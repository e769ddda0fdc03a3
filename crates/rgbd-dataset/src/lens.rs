//! Lens distortion as COLMAP and nerfstudio model it, and undistorting photos into pinhole ones.
//!
//! The renderer's cameras are ideal pinholes. A photo taken through a real lens is distorted:
//! the ideal normalised image point `(x, y) = ((u - cx) / fx, (v - cy) / fy)` shows up at
//! [`Lens::distort`]`(x, y)`. [`Undistortion`] resamples such a photo into a pinhole camera
//! of the same size and principal point whose focal length is chosen so that every output
//! pixel is seen by the photo (COLMAP's `image_undistorter` with `--blank_pixels 0` does the
//! same): no blank border that training would read as empty space.
//!
//! ```
//! use rgbd_dataset::lens::{Lens, Undistortion};
//! let lens = Lens::BrownConrady { radial: [-0.2, 0.0, 0.0, 0.0], tangential: [0.0; 2] };
//! // Barrel distortion pulls the image's corners in ...
//! let (xd, yd) = lens.distort(0.5, 0.5);
//! assert!(xd < 0.5 && yd < 0.5);
//! // ... and `undistort` finds the ideal point again.
//! let (x, y) = lens.undistort(xd, yd).unwrap();
//! assert!((x - 0.5).abs() < 1e-9 && (y - 0.5).abs() < 1e-9);
//! let undistortion = Undistortion::new(lens, [100.0, 100.0, 64.0, 48.0], (128, 96))?;
//! // The pinhole camera sees a little more than the photo's focal length would: barrel
//! // distortion squeezed a wider view into the frame.
//! assert!(undistortion.pinhole()[0] < 100.0);
//! let photo = image::RgbaImage::from_pixel(128, 96, image::Rgba([200, 100, 50, 255]));
//! let pinhole_photo = undistortion.apply(&photo);
//! assert_eq!(pinhole_photo.get_pixel(0, 0), &image::Rgba([200, 100, 50, 255]));
//! # Ok::<(), String>(())
//! ```

use rayon::prelude::*;

/// A lens's distortion of ideal normalised image coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lens {
    /// No distortion.
    Pinhole,
    /// Radial and tangential (Brown-Conrady, OpenCV's): with `r2 = x^2 + y^2`, the point is
    /// scaled by `1 + k1 r2 + k2 r2^2 + k3 r2^3 + k4 r2^4` and shifted by the tangential terms
    /// `p1, p2`. COLMAP's SIMPLE_RADIAL (`k1`), RADIAL (`k1, k2`) and OPENCV (`k1, k2, p1,
    /// p2`); nerfstudio's OPENCV (`k1` to `k4`, `p1, p2`).
    BrownConrady {
        /// `k1` to `k4` (0 where the model has fewer).
        radial: [f64; 4],
        /// `p1, p2`.
        tangential: [f64; 2],
    },
    /// The equidistant fisheye (COLMAP's and nerfstudio's OPENCV_FISHEYE): the angle `theta`
    /// from the axis lands at radius `theta (1 + k1 theta^2 + ... + k4 theta^8)`.
    Fisheye {
        /// `k1` to `k4`.
        radial: [f64; 4],
    },
}

impl Lens {
    /// Whether the lens leaves every point where it is.
    pub fn is_pinhole(self) -> bool {
        match self {
            Lens::Pinhole => true,
            Lens::BrownConrady { radial, tangential } => {
                radial == [0.0; 4] && tangential == [0.0; 2]
            }
            Lens::Fisheye { .. } => false,
        }
    }

    /// Where the ideal normalised point `(x, y)` appears in the distorted photo (normalised).
    pub fn distort(self, x: f64, y: f64) -> (f64, f64) {
        match self {
            Lens::Pinhole => (x, y),
            Lens::BrownConrady {
                radial: [k1, k2, k3, k4],
                tangential: [p1, p2],
            } => {
                let r2 = x * x + y * y;
                let scale = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)));
                (
                    x * scale + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * scale + 2.0 * p2 * x * y + p1 * (r2 + 2.0 * y * y),
                )
            }
            Lens::Fisheye { radial } => {
                let r = x.hypot(y);
                if r < 1e-12 {
                    return (x, y);
                }
                let theta = r.atan();
                let scale = fisheye_radius(radial, theta) / r;
                (x * scale, y * scale)
            }
        }
    }

    /// The ideal point that [`Lens::distort`] takes to `(xd, yd)`, by Newton's method from the
    /// distorted point itself; `None` when it does not converge (beyond where the lens folds).
    pub fn undistort(self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        const STEP: f64 = 1e-7;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..100 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex.hypot(ey) < 1e-12 {
                return Some((x, y));
            }
            // The Jacobian by central differences: exact enough for Newton's steps.
            let (ax, ay) = self.distort(x + STEP, y);
            let (bx, by) = self.distort(x - STEP, y);
            let (cx, cy) = self.distort(x, y + STEP);
            let (dx, dy) = self.distort(x, y - STEP);
            let (j11, j21) = ((ax - bx) / (2.0 * STEP), (ay - by) / (2.0 * STEP));
            let (j12, j22) = ((cx - dx) / (2.0 * STEP), (cy - dy) / (2.0 * STEP));
            let det = j11 * j22 - j12 * j21;
            if det.abs() < 1e-12 || !det.is_finite() {
                return None;
            }
            x -= (j22 * ex - j12 * ey) / det;
            y -= (j11 * ey - j21 * ex) / det;
        }
        let (fx, fy) = self.distort(x, y);
        ((fx - xd).hypot(fy - yd) < 1e-9).then_some((x, y))
    }

    /// Whether the distorted radius grows with the ideal one out to ideal radius `r_max`: beyond
    /// the first turning point strong distortion folds the image back onto itself, and points
    /// there would be read twice.
    fn unfolded_to(self, r_max: f64) -> bool {
        const SAMPLES: usize = 256;
        const DIRECTIONS: usize = 8;
        (0..DIRECTIONS).all(|d| {
            let angle = std::f64::consts::TAU * d as f64 / DIRECTIONS as f64;
            let (dx, dy) = (angle.cos(), angle.sin());
            let mut previous = 0.0;
            (1..=SAMPLES).all(|i| {
                let r = r_max * i as f64 / SAMPLES as f64;
                let (xd, yd) = self.distort(r * dx, r * dy);
                let radius = xd.hypot(yd);
                let grows = radius > previous;
                previous = radius;
                grows
            })
        })
    }
}

/// The fisheye's image radius of the angle `theta`.
fn fisheye_radius([k1, k2, k3, k4]: [f64; 4], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
}

/// A photo's resampling into an undistorted pinhole camera of the same size.
#[derive(Debug, Clone, PartialEq)]
pub struct Undistortion {
    lens: Lens,
    /// `fx, fy, cx, cy` of the distorted photo, in pixels.
    photo: [f64; 4],
    /// `fx, fy, cx, cy` of the pinhole camera written.
    pinhole: [f64; 4],
    size: (u32, u32),
}

impl Undistortion {
    /// The undistortion of photos of `size` taken with `lens` and intrinsics `fx, fy, cx, cy`
    /// (pixels; pixel `(i, j)`'s centre at `(i + 0.5, j + 0.5)`, as COLMAP and volgen's cameras
    /// have it). The pinhole camera keeps the size and principal point; its focal lengths are
    /// the photo's times the smallest factor (to 1e-6) at which every pixel along the output's
    /// border is seen by the photo and the lens does not fold. Errors (as text, for the caller
    /// to name the camera) when no factor up to 16 does.
    pub fn new(lens: Lens, photo: [f64; 4], size: (u32, u32)) -> Result<Self, String> {
        let [fx, fy, ..] = photo;
        if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) || size.0 == 0 || size.1 == 0
        {
            return Err(format!(
                "focal lengths {fx} x {fy} and size {} x {} do not make a camera",
                size.0, size.1
            ));
        }
        let mut undistortion = Self {
            lens,
            photo,
            pinhole: photo,
            size,
        };
        if lens.is_pinhole() {
            return Ok(undistortion);
        }
        let (mut low, mut high) = (1.0 / 16.0, 16.0);
        if !undistortion.covered_at(high) {
            return Err(format!(
                "the lens ({lens:?}) folds the picture even at its centre: not a lens COLMAP or \
                 nerfstudio would calibrate"
            ));
        }
        if undistortion.covered_at(low) {
            high = low;
        }
        while high / low > 1.0 + 1e-6 {
            let middle = (low * high).sqrt();
            if undistortion.covered_at(middle) {
                high = middle;
            } else {
                low = middle;
            }
        }
        undistortion.pinhole = [fx * high, fy * high, photo[2], photo[3]];
        Ok(undistortion)
    }

    /// Whether pictures pass unchanged (a pinhole lens).
    pub fn is_identity(&self) -> bool {
        self.lens.is_pinhole()
    }

    /// The lens of the photos.
    pub fn lens(&self) -> Lens {
        self.lens
    }

    /// The photos' size in pixels.
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// `fx, fy, cx, cy` of the distorted photos' camera.
    pub fn photo(&self) -> [f64; 4] {
        self.photo
    }

    /// `fx, fy, cx, cy` of the undistorted pictures' pinhole camera.
    pub fn pinhole(&self) -> [f64; 4] {
        self.pinhole
    }

    /// Where (continuous pixel coordinates of the photo) the pinhole picture's point `(u, v)`
    /// comes from.
    pub fn source_of(&self, u: f64, v: f64) -> (f64, f64) {
        let [px, py, pcx, pcy] = self.pinhole;
        let [fx, fy, cx, cy] = self.photo;
        let (xd, yd) = self.lens.distort((u - pcx) / px, (v - pcy) / py);
        (fx * xd + cx, fy * yd + cy)
    }

    /// Whether, with the focal lengths times `factor`, every border pixel's source lies in the
    /// photo and the lens does not fold on the way out there.
    fn covered_at(&self, factor: f64) -> bool {
        let [fx, fy, cx, cy] = self.photo;
        let trial = Self {
            pinhole: [fx * factor, fy * factor, cx, cy],
            ..*self
        };
        let (w, h) = (self.size.0 as f64, self.size.1 as f64);
        let mut border: Vec<(f64, f64)> = Vec::new();
        for i in 0..self.size.0 {
            let u = i as f64 + 0.5;
            border.extend([(u, 0.5), (u, h - 0.5)]);
        }
        for j in 0..self.size.1 {
            let v = j as f64 + 0.5;
            border.extend([(0.5, v), (w - 0.5, v)]);
        }
        let r_max = border
            .iter()
            .map(|&(u, v)| ((u - cx) / (fx * factor)).hypot((v - cy) / (fy * factor)))
            .fold(0.0, f64::max);
        self.lens.unfolded_to(r_max)
            && border.iter().all(|&(u, v)| {
                let (su, sv) = trial.source_of(u, v);
                (0.0..=w).contains(&su) && (0.0..=h).contains(&sv)
            })
    }

    /// The photo resampled into the pinhole camera: bilinear in premultiplied colour (so that
    /// transparent pixels' colours do not bleed into the foreground's edges).
    ///
    /// # Panics
    ///
    /// When the photo is not of the size the undistortion was made for.
    pub fn apply(&self, photo: &image::RgbaImage) -> image::RgbaImage {
        let straight: Vec<[f32; 4]> = photo
            .pixels()
            .map(|p| p.0.map(|v| f32::from(v) / 255.0))
            .collect();
        let (w, h) = self.size;
        let bytes = self
            .apply_straight(&straight)
            .into_iter()
            .flat_map(|p| p.map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8))
            .collect();
        image::RgbaImage::from_raw(w, h, bytes).expect("one pixel per pixel")
    }

    /// [`Undistortion::apply`] on row-major straight-alpha RGBA in [0, 1].
    ///
    /// # Panics
    ///
    /// When there are not width x height pixels.
    pub fn apply_straight(&self, photo: &[[f32; 4]]) -> Vec<[f32; 4]> {
        let (w, h) = (self.size.0 as usize, self.size.1 as usize);
        assert_eq!(
            photo.len(),
            w * h,
            "the photo must have the size the undistortion was made for"
        );
        let premultiplied = premultiply(photo);
        let mut out = vec![[0f32; 4]; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for (i, pixel) in row.iter_mut().enumerate() {
                let (su, sv) = self.source_of(i as f64 + 0.5, j as f64 + 0.5);
                *pixel = unpremultiply(bilinear(&premultiplied, (w, h), su, sv));
            }
        });
        out
    }
}

/// What a camera with `lens` and intrinsics `fx, fy, cx, cy` (pixels) photographs of the scene
/// that `pinhole` shows through a pinhole camera with the same intrinsics and size: each pixel
/// shows what the pinhole's ray through its ideal point ([`Lens::undistort`]) sees, bilinear in
/// premultiplied colour. The inverse of [`Undistortion::apply`] up to its focal length: for
/// simulating a lens (tests, checks through structure from motion). Pixels whose ideal point
/// cannot be found (beyond where the lens folds) are transparent.
pub fn photo_through_lens(
    pinhole: &image::RgbaImage,
    [fx, fy, cx, cy]: [f64; 4],
    lens: Lens,
) -> image::RgbaImage {
    let (w, h) = (pinhole.width() as usize, pinhole.height() as usize);
    let straight: Vec<[f32; 4]> = pinhole
        .pixels()
        .map(|p| p.0.map(|v| f32::from(v) / 255.0))
        .collect();
    let premultiplied = premultiply(&straight);
    image::RgbaImage::from_fn(pinhole.width(), pinhole.height(), |i, j| {
        let xd = (f64::from(i) + 0.5 - cx) / fx;
        let yd = (f64::from(j) + 0.5 - cy) / fy;
        let Some((x, y)) = lens.undistort(xd, yd) else {
            return image::Rgba([0; 4]);
        };
        let pixel = unpremultiply(bilinear(&premultiplied, (w, h), fx * x + cx, fy * y + cy));
        image::Rgba(pixel.map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8))
    })
}

fn premultiply(straight: &[[f32; 4]]) -> Vec<[f32; 4]> {
    straight
        .iter()
        .map(|&[r, g, b, a]| [r * a, g * a, b * a, a])
        .collect()
}

fn unpremultiply([r, g, b, alpha]: [f32; 4]) -> [f32; 4] {
    let straight = |c: f32| {
        if alpha > 0.0 {
            (c / alpha).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    [straight(r), straight(g), straight(b), alpha]
}

/// The bilinear sample of row-major `pixels` of `size` at continuous pixel coordinates `(u,
/// v)` (pixel centres at +0.5; beyond the edge pixels' centres the edge is repeated).
fn bilinear(pixels: &[[f32; 4]], (w, h): (usize, usize), u: f64, v: f64) -> [f32; 4] {
    let (x, y) = (u - 0.5, v - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (tx, ty) = ((x - x0) as f32, (y - y0) as f32);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let at = |i: i64, j: i64| {
        let i = i.clamp(0, w as i64 - 1) as usize;
        let j = j.clamp(0, h as i64 - 1) as usize;
        pixels[j * w + i]
    };
    let mut sum = [0f32; 4];
    for (di, dj, weight) in [
        (0, 0, (1.0 - tx) * (1.0 - ty)),
        (1, 0, tx * (1.0 - ty)),
        (0, 1, (1.0 - tx) * ty),
        (1, 1, tx * ty),
    ] {
        let p = at(x0 + di, y0 + dj);
        for c in 0..4 {
            sum[c] += weight * p[c];
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lenses() -> [Lens; 4] {
        [
            // COLMAP's SIMPLE_RADIAL of a phone, RADIAL, OPENCV, and a fisheye.
            Lens::BrownConrady {
                radial: [-0.08, 0.0, 0.0, 0.0],
                tangential: [0.0; 2],
            },
            Lens::BrownConrady {
                radial: [0.12, -0.03, 0.0, 0.0],
                tangential: [0.0; 2],
            },
            Lens::BrownConrady {
                radial: [-0.25, 0.07, 0.0, 0.0],
                tangential: [0.002, -0.001],
            },
            Lens::Fisheye {
                radial: [0.05, -0.01, 0.002, 0.0],
            },
        ]
    }

    #[test]
    fn undistort_inverts_distort() {
        for lens in lenses() {
            for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.45), (0.61, 0.02)] {
                let (xd, yd) = lens.distort(x, y);
                let (ux, uy) = lens.undistort(xd, yd).unwrap();
                assert!((ux - x).abs() < 1e-9 && (uy - y).abs() < 1e-9, "{lens:?}");
            }
        }
    }

    #[test]
    fn distortion_matches_hand_derived_values() {
        // OPENCV at (0.5, 0.25): r2 = 0.3125, radial 1 - 0.25 r2 + 0.07 r2^2 = 0.928711...
        let lens = lenses()[2];
        let (xd, yd) = lens.distort(0.5, 0.25);
        let r2: f64 = 0.3125;
        let scale = 1.0 - 0.25 * r2 + 0.07 * r2 * r2;
        let expected_x = 0.5 * scale + 2.0 * 0.002 * 0.125 + -0.001 * (r2 + 0.5);
        let expected_y = 0.25 * scale + 2.0 * -0.001 * 0.125 + 0.002 * (r2 + 0.125);
        assert!((xd - expected_x).abs() < 1e-15 && (yd - expected_y).abs() < 1e-15);
        // A fisheye without terms is equidistant: radius = atan(r).
        let (xd, _) = Lens::Fisheye { radial: [0.0; 4] }.distort(1.0, 0.0);
        assert!((xd - std::f64::consts::FRAC_PI_4).abs() < 1e-15);
    }

    #[test]
    fn the_pinhole_camera_is_covered_by_the_photo_and_no_more_focal_than_needed() {
        let size = (160, 120);
        let photo = [150.0, 140.0, 83.0, 58.0];
        for lens in lenses() {
            let undistortion = Undistortion::new(lens, photo, size).unwrap();
            let inside = |u: f64, v: f64| {
                let (su, sv) = undistortion.source_of(u, v);
                (0.0..=160.0).contains(&su) && (0.0..=120.0).contains(&sv)
            };
            let border = (0..160)
                .flat_map(|i| [(i as f64 + 0.5, 0.5), (i as f64 + 0.5, 119.5)])
                .chain((0..120).flat_map(|j| [(0.5, j as f64 + 0.5), (159.5, j as f64 + 0.5)]));
            assert!(border.clone().all(|(u, v)| inside(u, v)), "{lens:?}");
            // One percent less focal length and some border pixel leaves the photo.
            let [fx, fy, cx, cy] = undistortion.pinhole();
            let wider = Undistortion {
                pinhole: [fx * 0.99, fy * 0.99, cx, cy],
                ..undistortion.clone()
            };
            assert!(
                !border.into_iter().all(|(u, v)| {
                    let (su, sv) = wider.source_of(u, v);
                    (0.0..=160.0).contains(&su) && (0.0..=120.0).contains(&sv)
                }),
                "{lens:?}"
            );
            assert_eq!(&undistortion.pinhole()[2..], &photo[2..]);
        }
    }

    /// A smooth picture of the ideal normalised coordinates.
    fn pattern(x: f64, y: f64) -> [f64; 3] {
        [
            127.5 + 100.0 * (3.0 * x).sin(),
            127.5 + 100.0 * (2.5 * y).cos(),
            127.5 + 80.0 * (2.0 * (x + y)).sin(),
        ]
    }

    #[test]
    fn undistorted_photos_show_the_ideal_picture() {
        let (w, h) = (96u32, 72u32);
        let photo_k = [80.0, 80.0, 48.0, 36.0];
        for lens in lenses() {
            // The photo: each pixel shows the pattern where its ray really points.
            let photo = image::RgbaImage::from_fn(w, h, |i, j| {
                let xd = (i as f64 + 0.5 - photo_k[2]) / photo_k[0];
                let yd = (j as f64 + 0.5 - photo_k[3]) / photo_k[1];
                let (x, y) = lens.undistort(xd, yd).unwrap();
                let [r, g, b] = pattern(x, y).map(|c| c.round() as u8);
                image::Rgba([r, g, b, 255])
            });
            let undistortion = Undistortion::new(lens, photo_k, (w, h)).unwrap();
            let out = undistortion.apply(&photo);
            let [fx, fy, cx, cy] = undistortion.pinhole();
            let mut worst = 0f64;
            for (i, j, pixel) in out.enumerate_pixels() {
                let ideal = pattern((i as f64 + 0.5 - cx) / fx, (j as f64 + 0.5 - cy) / fy);
                for c in 0..3 {
                    worst = worst.max((f64::from(pixel[c]) - ideal[c]).abs());
                }
                assert_eq!(pixel[3], 255, "blank pixel at {i}, {j} ({lens:?})");
            }
            // Bilinear interpolation of a pattern changing at most ~4 levels per pixel, plus
            // rounding twice.
            assert!(worst <= 4.0, "{lens:?}: off by {worst} levels");
        }
    }

    #[test]
    fn folding_lenses_are_refused() {
        let folding = Lens::BrownConrady {
            radial: [-40.0, 0.0, 0.0, 0.0],
            tangential: [0.0; 2],
        };
        let err = Undistortion::new(folding, [10.0, 10.0, 32.0, 32.0], (64, 64)).unwrap_err();
        assert!(err.contains("folds"), "{err}");
        assert!(Undistortion::new(Lens::Pinhole, [0.0, 1.0, 0.0, 0.0], (4, 4)).is_err());
    }
}
