//! Ray bundles: one per pixel of a camera, or a seeded random subset of its pixels.

use std::sync::Arc;

use rand::seq::index::sample;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::camera::Camera;
use crate::config::{MAX_COORDINATE, MIN_DIRECTION_LENGTH};
use crate::error::{invalid, Result};

/// A bundle of rays: origins and directions in world space, `R` of each. Directions need not
/// be unit length (the renderer normalises them: depth is a distance from the origin), but
/// must be non-zero. Storage is shared, so cloning is cheap.
///
/// ```
/// use volrender::{Camera, Rays};
/// use glam::Vec3;
/// let cam = Camera::look_at(Vec3::new(0.0, -4.0, 1.0), Vec3::ZERO, Vec3::Z, 16, 8, 0.7)?;
/// let all = Rays::from_camera(&cam);
/// assert_eq!(all.len(), 16 * 8);
/// let (some, pixels) = Rays::random_pixels(&cam, 10, 42)?;
/// assert_eq!(some.len(), 10);
/// assert_eq!(some.dirs()[3], all.dirs()[pixels[3] as usize]);
/// # Ok::<(), volrender::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Rays {
    origins: Arc<[[f32; 3]]>,
    dirs: Arc<[[f32; 3]]>,
}

impl Rays {
    /// Creates a bundle, checking equal lengths, finite values and non-zero directions.
    pub fn new(origins: Vec<[f32; 3]>, dirs: Vec<[f32; 3]>) -> Result<Self> {
        if origins.len() != dirs.len() {
            return Err(invalid(
                "rays",
                format!("{} origins but {} directions", origins.len(), dirs.len()),
            ));
        }
        let far = |v: &[f32; 3]| !v.iter().all(|x| x.abs() <= MAX_COORDINATE);
        if let Some(i) = origins.iter().position(far) {
            return Err(invalid(
                "rays",
                format!(
                    "origin {i} must be finite and within {MAX_COORDINATE:e} of the origin, got {:?}",
                    origins[i]
                ),
            ));
        }
        let short = |d: &[f32; 3]| {
            let length = d.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt();
            !(length >= f64::from(MIN_DIRECTION_LENGTH) && length <= f64::from(MAX_COORDINATE))
        };
        if let Some(i) = dirs.iter().position(short) {
            return Err(invalid(
                "rays",
                format!(
                    "direction {i} must be finite, at least {MIN_DIRECTION_LENGTH:e} and at most \
                     {MAX_COORDINATE:e} long, got {:?}",
                    dirs[i]
                ),
            ));
        }
        Ok(Self {
            origins: origins.into(),
            dirs: dirs.into(),
        })
    }

    /// Returns the rays through every pixel centre of `camera`, row-major (index `row * width +
    /// col`), with unit directions.
    #[must_use]
    pub fn from_camera(camera: &Camera) -> Self {
        let pixels: Vec<u32> = (0..(camera.width * camera.height) as u32).collect();
        Self::through_pixels(camera, &pixels)
    }

    /// Returns rays through `n` distinct pixels of `camera` drawn uniformly without replacement
    /// with `seed`, and the pixels' row-major indices.
    pub fn random_pixels(camera: &Camera, n: usize, seed: u64) -> Result<(Self, Vec<u32>)> {
        let total = camera.width * camera.height;
        if n > total {
            return Err(invalid(
                "n",
                format!("asked for {n} distinct pixels of a {total}-pixel image"),
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let pixels: Vec<u32> = sample(&mut rng, total, n)
            .into_iter()
            .map(|p| p as u32)
            .collect();
        Ok((Self::through_pixels(camera, &pixels), pixels))
    }

    /// Returns the rays through the centres of the given row-major pixels.
    fn through_pixels(camera: &Camera, pixels: &[u32]) -> Self {
        let (origins, dirs) = pixels
            .iter()
            .map(|&p| {
                let (row, col) = (p as usize / camera.width, p as usize % camera.width);
                let (o, d) = camera.ray(row as f32 + 0.5, col as f32 + 0.5);
                (o.to_array(), d.to_array())
            })
            .unzip::<_, _, Vec<_>, Vec<_>>();
        Self {
            origins: origins.into(),
            dirs: dirs.into(),
        }
    }

    /// Returns the number of rays.
    #[must_use]
    pub fn len(&self) -> usize {
        self.origins.len()
    }

    /// Tells whether there are no rays.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }

    /// Returns the origins.
    #[must_use]
    pub fn origins(&self) -> &[[f32; 3]] {
        &self.origins
    }

    /// Returns the directions.
    #[must_use]
    pub fn dirs(&self) -> &[[f32; 3]] {
        &self.dirs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn rejects_bad_rays() {
        assert!(Rays::new(vec![[0.0; 3]], vec![]).is_err());
        assert!(Rays::new(vec![[0.0; 3]], vec![[0.0; 3]]).is_err());
        assert!(Rays::new(vec![[f32::NAN, 0.0, 0.0]], vec![[1.0, 0.0, 0.0]]).is_err());
        assert!(Rays::new(vec![[0.0; 3]], vec![[0.0, 0.0, 2.0]]).is_ok());
    }

    #[test]
    fn random_pixels_are_distinct_and_seeded() {
        let cam =
            Camera::look_at(Vec3::new(3.0, 0.0, 0.0), Vec3::ZERO, Vec3::Z, 7, 5, 0.5).unwrap();
        let (_, a) = Rays::random_pixels(&cam, 35, 3).unwrap();
        let mut sorted = a.clone();
        sorted.sort();
        assert_eq!(sorted, (0..35).collect::<Vec<u32>>());
        assert_eq!(
            Rays::random_pixels(&cam, 9, 3).unwrap(),
            Rays::random_pixels(&cam, 9, 3).unwrap()
        );
        assert!(Rays::random_pixels(&cam, 36, 3).is_err());
    }
}
