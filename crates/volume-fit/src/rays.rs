//! Every training pixel as a ray with its targets, and random batches of them.

use candle_core::{Device, Tensor};
use rand::Rng;
use volrender::Rays;

use crate::error::{invalid, Result};
use rgbd_dataset::DatasetLevel;

/// The rays through every pixel of a set of views, with each pixel's colour (composited on the
/// dataset's background), expected depth and opacity.
#[derive(Debug, Clone)]
pub(super) struct RayBank {
    origins: Vec<[f32; 3]>,
    dirs: Vec<[f32; 3]>,
    rgb: Vec<[f32; 3]>,
    depth: Vec<f32>,
    /// How much each pixel's depth counts (0 where the dataset's depth is a hole).
    depth_weight: Vec<f32>,
    opacity: Vec<f32>,
}

/// A random batch of rays and their targets: colour `(B, 3)`, depth, depth weight and opacity
/// `(B)`.
pub(super) struct RayBatch {
    pub rays: Rays,
    pub rgb: Tensor,
    pub depth: Tensor,
    pub depth_weight: Tensor,
    pub opacity: Tensor,
}

impl RayBank {
    /// The rays and targets of every view of `level`, pixel by pixel in row-major order.
    pub fn from_level(level: &DatasetLevel) -> Result<Self> {
        let images: Vec<f32> = level.images.flatten_all()?.to_vec1()?;
        let depth: Vec<f32> = level.depths.flatten_all()?.to_vec1()?;
        let opacity: Vec<f32> = level.opacity.flatten_all()?.to_vec1()?;
        let depth_weight: Vec<f32> = match &level.depth_mask {
            Some(mask) => mask.flatten_all()?.to_vec1()?,
            None => vec![1.0; depth.len()],
        };
        let mut bank = Self {
            origins: Vec::with_capacity(depth.len()),
            dirs: Vec::with_capacity(depth.len()),
            rgb: Vec::with_capacity(depth.len()),
            depth,
            depth_weight,
            opacity,
        };
        for (view, camera) in level.cameras.iter().enumerate() {
            let rays = Rays::from_camera(camera);
            bank.origins.extend_from_slice(rays.origins());
            bank.dirs.extend_from_slice(rays.dirs());
            let plane = camera.width * camera.height;
            let image = &images[view * 3 * plane..(view + 1) * 3 * plane];
            bank.rgb
                .extend((0..plane).map(|p| [image[p], image[plane + p], image[2 * plane + p]]));
        }
        if bank.origins.is_empty() {
            return Err(invalid(
                "views",
                "a fit needs at least one view with pixels",
            ));
        }
        Ok(bank)
    }

    /// `count` rays drawn uniformly (with replacement) from every view's pixels.
    pub fn batch(&self, rng: &mut impl Rng, count: usize) -> Result<RayBatch> {
        let picks: Vec<usize> = (0..count)
            .map(|_| rng.random_range(0..self.origins.len()))
            .collect();
        let gather = |v: &[f32]| picks.iter().map(|&i| v[i]).collect::<Vec<f32>>();
        let rgb: Vec<f32> = picks.iter().flat_map(|&i| self.rgb[i]).collect();
        Ok(RayBatch {
            rays: Rays::new(
                picks.iter().map(|&i| self.origins[i]).collect(),
                picks.iter().map(|&i| self.dirs[i]).collect(),
            )?,
            rgb: Tensor::from_vec(rgb, (count, 3), &Device::Cpu)?,
            depth: Tensor::from_vec(gather(&self.depth), count, &Device::Cpu)?,
            depth_weight: Tensor::from_vec(gather(&self.depth_weight), count, &Device::Cpu)?,
            opacity: Tensor::from_vec(gather(&self.opacity), count, &Device::Cpu)?,
        })
    }
}
