//! Pinhole cameras in the NeRF / Blender convention, look-at, and hemisphere sampling.
//!
//! A camera is a 4x4 camera-to-world matrix (`c2w`) and pinhole intrinsics in pixels. In camera
//! space the camera looks down -Z with +Y up and +X right (OpenGL / Blender / NeRF), so pixel
//! `(row, col)` maps to the camera-space direction `((col + 0.5 - cx) / fx, -(row + 0.5 - cy) /
//! fy, -1)`: rows grow downwards, as in an image file.

use glam::{Mat4, Vec3, Vec4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{invalid, Result};

/// The paper's data cameras: distance from the origin.
pub const PAPER_RADIUS: f32 = 3.5;
/// The paper's data cameras: horizontal field of view in degrees.
pub const PAPER_FOV_DEG: f32 = 33.4;

/// A pinhole camera: camera-to-world matrix plus intrinsics in pixels.
///
/// ```
/// use volrender::Camera;
/// use glam::Vec3;
/// let cam = Camera::look_at(Vec3::new(0.0, -4.0, 0.0), Vec3::ZERO, Vec3::Z, 64, 48, 40f32.to_radians())?;
/// // The centre of the image looks at the target.
/// let (o, d) = cam.ray(24.0, 32.0);
/// assert!((o - Vec3::new(0.0, -4.0, 0.0)).length() < 1e-6);
/// assert!((d - Vec3::Y).length() < 1e-6);
/// # Ok::<(), volrender::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Camera-to-world transform (rotation columns: right, up, back; translation: position).
    pub c2w: Mat4,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x (pixels from the left edge).
    pub cx: f32,
    /// Principal point y (pixels from the top edge).
    pub cy: f32,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
}

impl Camera {
    /// Creates a camera from intrinsics, checking that they are finite and positive and that the
    /// matrix is finite.
    pub fn from_intrinsics(
        c2w: Mat4,
        width: usize,
        height: usize,
        [fx, fy, cx, cy]: [f32; 4],
    ) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(invalid(
                "image size",
                format!("expected width and height >= 1, got {width} x {height}"),
            ));
        }
        if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite()) {
            return Err(invalid(
                "focal length",
                format!("expected finite fx, fy > 0, got ({fx}, {fy})"),
            ));
        }
        if !(cx.is_finite() && cy.is_finite() && c2w.is_finite()) {
            return Err(invalid(
                "camera",
                "principal point and camera-to-world matrix must be finite",
            ));
        }
        Ok(Self {
            c2w,
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        })
    }

    /// Creates a camera from the horizontal field of view `fov_x` (radians, NeRF's
    /// `camera_angle_x`); square pixels, principal point at the image centre.
    pub fn from_fov(c2w: Mat4, width: usize, height: usize, fov_x: f32) -> Result<Self> {
        if !(fov_x > 0.0 && fov_x < std::f32::consts::PI) {
            return Err(invalid(
                "fov_x",
                format!("expected a field of view in (0, pi) radians, got {fov_x}"),
            ));
        }
        let f = 0.5 * width as f32 / (0.5 * fov_x).tan();
        Self::from_intrinsics(
            c2w,
            width,
            height,
            [f, f, 0.5 * width as f32, 0.5 * height as f32],
        )
    }

    /// Creates a camera at `eye` looking at `target`, with `up` giving the image's up direction,
    /// and horizontal field of view `fov_x` (radians). When `up` is (nearly) parallel to the view
    /// direction, world +Y is used instead (+X if that is parallel too), so the hemisphere's pole
    /// still gets a camera.
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        width: usize,
        height: usize,
        fov_x: f32,
    ) -> Result<Self> {
        Self::from_fov(look_at_c2w(eye, target, up)?, width, height, fov_x)
    }

    /// Returns the camera position in world space.
    #[must_use]
    pub fn position(&self) -> Vec3 {
        self.c2w.w_axis.truncate()
    }

    /// Returns the ray through image point `(row, col)` (continuous pixel coordinates: the centre
    /// of pixel `(a, b)` is `(a + 0.5, b + 0.5)`) as (origin, unit direction).
    #[must_use]
    pub fn ray(&self, row: f32, col: f32) -> (Vec3, Vec3) {
        let d_cam = Vec3::new((col - self.cx) / self.fx, -(row - self.cy) / self.fy, -1.0);
        let d = self.c2w.transform_vector3(d_cam).normalize();
        (self.position(), d)
    }

    /// Samples `n` cameras uniformly (by area) on the upper hemisphere `z >= 0` of radius
    /// `radius`, each looking at the origin with +Z as up; the paper's data uses
    /// [`PAPER_RADIUS`] and [`PAPER_FOV_DEG`]. The same seed gives the same cameras.
    ///
    /// ```
    /// use volrender::Camera;
    /// let cams = Camera::hemisphere(8, 3.5, 33.4f32.to_radians(), 32, 32, 7)?;
    /// assert!(cams.iter().all(|c| c.position().z >= 0.0 && (c.position().length() - 3.5).abs() < 1e-5));
    /// # Ok::<(), volrender::Error>(())
    /// ```
    pub fn hemisphere(
        n: usize,
        radius: f32,
        fov_x: f32,
        width: usize,
        height: usize,
        seed: u64,
    ) -> Result<Vec<Self>> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(invalid(
                "radius",
                format!("expected a finite radius > 0, got {radius}"),
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                // Uniform on the hemisphere's area: z uniform in [0, 1], azimuth uniform.
                let z: f32 = rng.random();
                let phi = rng.random::<f32>() * std::f32::consts::TAU;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let eye = radius * Vec3::new(r * phi.cos(), r * phi.sin(), z);
                Self::look_at(eye, Vec3::ZERO, Vec3::Z, width, height, fov_x)
            })
            .collect()
    }
}

/// Builds a NeRF/Blender camera-to-world matrix at `eye` looking at `target`.
fn look_at_c2w(eye: Vec3, target: Vec3, up: Vec3) -> Result<Mat4> {
    if !(eye.is_finite() && target.is_finite() && up.is_finite()) {
        return Err(invalid("look_at", "eye, target and up must be finite"));
    }
    let forward = (target - eye).try_normalize().ok_or_else(|| {
        invalid(
            "look_at",
            format!("eye and target coincide at {eye}: no view direction"),
        )
    })?;
    let right = [up, Vec3::Y, Vec3::X]
        .into_iter()
        .find_map(|u| {
            let r = forward.cross(u);
            (r.length() > 1e-6).then(|| r.normalize())
        })
        .ok_or_else(|| invalid("look_at", "no up direction is usable"))?;
    let cam_up = right.cross(forward);
    Ok(Mat4::from_cols(
        right.extend(0.0),
        cam_up.extend(0.0),
        (-forward).extend(0.0),
        Vec4::new(eye.x, eye.y, eye.z, 1.0),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_is_orthonormal_and_right_handed() {
        let c2w = look_at_c2w(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Z).unwrap();
        let (x, y, z) = (
            c2w.x_axis.truncate(),
            c2w.y_axis.truncate(),
            c2w.z_axis.truncate(),
        );
        assert!((x.cross(y) - z).length() < 1e-6);
        assert!(x.dot(y).abs() < 1e-6 && x.length() - 1.0 < 1e-6);
        // Z-up world: the camera's up vector points upwards, its right vector is horizontal.
        assert!(y.z > 0.0 && x.z.abs() < 1e-6);
    }

    #[test]
    fn pole_and_degenerate_inputs() {
        // Straight above the origin: +Z is parallel to the view, +Y is used as up.
        let cam = Camera::look_at(Vec3::Z * 3.0, Vec3::ZERO, Vec3::Z, 8, 8, 0.5).unwrap();
        assert!((cam.ray(4.0, 4.0).1 + Vec3::Z).length() < 1e-6);
        assert!(Camera::look_at(Vec3::ONE, Vec3::ONE, Vec3::Z, 8, 8, 0.5).is_err());
        assert!(Camera::look_at(Vec3::ONE, Vec3::ZERO, Vec3::Z, 0, 8, 0.5).is_err());
        assert!(Camera::look_at(Vec3::ONE, Vec3::ZERO, Vec3::Z, 8, 8, 4.0).is_err());
    }

    #[test]
    fn fov_reaches_the_image_edges() {
        let fov = 60f32.to_radians();
        let cam =
            Camera::look_at(Vec3::new(0.0, -5.0, 0.0), Vec3::ZERO, Vec3::Z, 100, 50, fov).unwrap();
        // The left edge of the image (col 0, continuous) is half the FOV away from the axis.
        let (_, d) = cam.ray(25.0, 0.0);
        assert!((d.angle_between(Vec3::Y) - fov / 2.0).abs() < 1e-5);
        // Image right is world +X when looking along +Y with Z up; image top is +Z.
        assert!(cam.ray(25.0, 100.0).1.x > 0.0 && cam.ray(0.0, 50.0).1.z > 0.0);
    }

    #[test]
    fn hemisphere_is_seeded() {
        let a = Camera::hemisphere(5, 3.5, 0.6, 4, 4, 1).unwrap();
        let b = Camera::hemisphere(5, 3.5, 0.6, 4, 4, 1).unwrap();
        let c = Camera::hemisphere(5, 3.5, 0.6, 4, 4, 2).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
        for cam in &a {
            // Every camera looks at the origin.
            let (o, d) = cam.ray(2.0, 2.0);
            assert!((o + d * o.length()).length() < 1e-4);
        }
    }
}
