//! Render options: the sampler, early termination, empty-space skipping, background, outputs.

use radiance_volume::Aabb;

use crate::error::{invalid, Result};

/// Where along a ray the samples go. Every sampler splits the ray's segment inside the box,
/// `[t_entry, t_exit]` with `t_entry = max(t_near, 0)`, into `n` equal steps of length `dt`, and
/// every sample `i` weighs `delta_i = dt`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sampler {
    /// The paper's sampler: `n = samples` steps, sample at each step's midpoint,
    /// `t_i = t_entry + (i + 0.5) dt` (second-order accurate).
    Uniform {
        /// Samples per ray, M.
        samples: usize,
    },
    /// Like `Uniform` but at each step's left end, `t_i = t_entry + i dt` (first order; kept to
    /// compare with renderers that use it).
    UniformLeft {
        /// Samples per ray, M.
        samples: usize,
    },
    /// A voxel-aware midpoint sampler: the step is at most `voxel / per_voxel` (the smallest
    /// voxel edge), so `n = ceil((t_exit - t_entry) * per_voxel / voxel)` varies per ray and the
    /// error is controlled independently of the grid's size.
    PerVoxel {
        /// Samples per voxel crossed, k.
        per_voxel: usize,
    },
}

impl Sampler {
    /// Returns the offset of a sample inside its step: 0.5 for the midpoint rules, 0 for left.
    #[must_use]
    pub(crate) fn offset(&self) -> f64 {
        match self {
            Self::UniformLeft { .. } => 0.0,
            Self::Uniform { .. } | Self::PerVoxel { .. } => 0.5,
        }
    }
}

/// The most samples a ray may take: sample positions are computed from the sample's index in
/// the kernel's precision, which is exact for f32 up to `2^24`.
pub const MAX_SAMPLES_PER_RAY: usize = 1 << 24;

/// The range the renderer accepts, so that every product in the forward and backward passes
/// stays finite in f32 (found by fuzzing: a box 1e37 wide rendered finite images whose
/// gradients overflowed): colours, the volume's and the background's, and post-activated raw
/// density at most this in magnitude (physical density may be any finite value >= 0), ...
pub const MAX_VOLUME_VALUE: f32 = 1e10;
/// ... box corners and ray origins within this of the origin in every coordinate, ...
pub const MAX_COORDINATE: f32 = 1e8;
/// ... and ray directions at least this long (a ray's parameter t grows as 1 / |d|).
pub const MIN_DIRECTION_LENGTH: f32 = 1e-4;

/// Which outputs besides colour to compute (the others are not computed at all).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outputs {
    /// Expected depth `sum_i w_i t_i` (distance along the ray, not divided by opacity).
    pub depth: bool,
    /// Opacity `sum_i w_i`, in [0, 1].
    pub opacity: bool,
}

/// What a sample's density is made of: the volume's channel 0 interpolated as it is, or
/// interpolated raw values put through an activation at every sample.
///
/// ```
/// use volrender::{DensityInterpolation, RenderConfig};
/// let raw = DensityInterpolation::PostActivated { scale: 25.0, shift: -4.0 };
/// let cfg = RenderConfig::default().with_density(raw);
/// assert_eq!(RenderConfig::default().density, DensityInterpolation::Physical);
/// assert!(cfg.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum DensityInterpolation {
    /// Channel 0 is the physical density sigma (>= 0), interpolated trilinearly like colour (the
    /// paper's renderer): between a dense voxel and an empty one density falls off linearly
    /// over a whole voxel, so a grid cannot hold an edge sharper than its voxels.
    #[default]
    Physical,
    /// Channel 0 is raw density (any finite value): each sample interpolates it and then takes
    /// `sigma = scale * softplus(raw + shift)`, DVGO's post-activation (Sun et al. 2022). Where
    /// the interpolated raw value crosses the activation's knee inside a voxel, density jumps
    /// from nearly 0 to high within a fraction of the voxel, so a coarse grid holds sharp,
    /// sub-voxel surfaces. The gradient flows through the activation's slope
    /// `scale * sigmoid(raw + shift)`.
    PostActivated {
        /// Multiplies the softplus, in 1/world-length (> 0).
        scale: f32,
        /// Added to the interpolated raw density before the softplus.
        shift: f32,
    },
}

impl DensityInterpolation {
    /// The rule a yes/no switch names: post-activated with `scale` and `shift` for `true`,
    /// physical for `false`.
    ///
    /// ```
    /// use volrender::DensityInterpolation;
    /// let on = DensityInterpolation::post_activated_if(true, 25.0, -4.0);
    /// assert_eq!(on.post_activation(), Some([25.0, -4.0]));
    /// assert_eq!(DensityInterpolation::post_activated_if(false, 25.0, -4.0), DensityInterpolation::Physical);
    /// ```
    #[must_use]
    pub fn post_activated_if(switch: bool, scale: f32, shift: f32) -> Self {
        if switch {
            Self::PostActivated { scale, shift }
        } else {
            Self::Physical
        }
    }

    /// The activation's `[scale, shift]` when densities are post-activated.
    #[must_use]
    pub fn post_activation(self) -> Option<[f32; 2]> {
        match self {
            Self::Physical => None,
            Self::PostActivated { scale, shift } => Some([scale, shift]),
        }
    }
}

/// Options of [`render`](crate::render).
///
/// ```
/// use volrender::{RenderConfig, Sampler};
/// let cfg = RenderConfig::default()
///     .with_sampler(Sampler::PerVoxel { per_voxel: 2 })
///     .with_epsilon(1e-3)
///     .with_background([1.0, 1.0, 1.0])
///     .with_depth(true);
/// assert!(cfg.outputs.depth && !cfg.outputs.opacity);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderConfig {
    /// The sampler (default: the paper's uniform midpoint rule with 128 samples).
    pub sampler: Sampler,
    /// Early ray termination: a ray stops once its transmittance `T <= epsilon`. 0 (the default)
    /// is exact: it only stops rays whose transmittance is exactly 0. With colours and
    /// background in [0, 1] the error is at most `epsilon` in colour and opacity and `epsilon *
    /// t_exit` in depth.
    pub epsilon: f32,
    /// Skip samples in cells of an occupancy grid (radiance-volume's, threshold 0) that hold no
    /// density; a ray leaps over the whole cube of empty cells around it at once, using each
    /// cell's distance to the nearest occupied one. The forward pass is exactly unchanged; the backward then omits the terms of
    /// skipped samples, which only touch voxels of density 0: the density gradient of empty
    /// voxels loses those terms (it is no longer the full gradient), while colour gradients and
    /// the density gradient of voxels with density > 0 are exactly unchanged. Leave it off when
    /// training needs gradients that can grow density in empty space.
    pub skip_empty: bool,
    /// Voxels per occupancy cell and axis when `skip_empty` is on (default 4).
    pub occupancy_cell: usize,
    /// Colour seen through the volume, composited as `+ T_final * background`; `None` is black.
    pub background: Option<[f32; 3]>,
    /// Outputs besides colour.
    pub outputs: Outputs,
    /// The world box the volume's grid covers (default `[-1, 1]^3`).
    pub aabb: Aabb,
    /// What channel 0 holds and how samples get their density (default:
    /// [`DensityInterpolation::Physical`]).
    pub density: DensityInterpolation,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            sampler: Sampler::Uniform { samples: 128 },
            epsilon: 0.0,
            skip_empty: false,
            occupancy_cell: 4,
            background: None,
            outputs: Outputs::default(),
            aabb: Aabb::CUBE,
            density: DensityInterpolation::Physical,
        }
    }
}

impl RenderConfig {
    /// Sets the sampler.
    #[must_use]
    pub fn with_sampler(self, sampler: Sampler) -> Self {
        Self { sampler, ..self }
    }

    /// Sets the early-termination threshold.
    #[must_use]
    pub fn with_epsilon(self, epsilon: f32) -> Self {
        Self { epsilon, ..self }
    }

    /// Turns empty-space skipping on or off.
    #[must_use]
    pub fn with_skip_empty(self, skip_empty: bool) -> Self {
        Self { skip_empty, ..self }
    }

    /// Sets the background colour.
    #[must_use]
    pub fn with_background(self, background: [f32; 3]) -> Self {
        Self {
            background: Some(background),
            ..self
        }
    }

    /// Asks for the depth output or not.
    #[must_use]
    pub fn with_depth(self, depth: bool) -> Self {
        Self {
            outputs: Outputs {
                depth,
                ..self.outputs
            },
            ..self
        }
    }

    /// Asks for the opacity output or not.
    #[must_use]
    pub fn with_opacity(self, opacity: bool) -> Self {
        Self {
            outputs: Outputs {
                opacity,
                ..self.outputs
            },
            ..self
        }
    }

    /// Sets the world box of the volume.
    #[must_use]
    pub fn with_aabb(self, aabb: Aabb) -> Self {
        Self { aabb, ..self }
    }

    /// Sets what channel 0 holds and how samples get their density.
    #[must_use]
    pub fn with_density(self, density: DensityInterpolation) -> Self {
        Self { density, ..self }
    }

    /// Checks the options: at least one sample, `epsilon` in [0, 1), finite background, a valid
    /// box, at least one voxel per occupancy cell, and a post-activation of finite scale > 0 and
    /// finite shift.
    pub fn validate(&self) -> Result<()> {
        match self.sampler {
            Sampler::Uniform { samples: 0 } | Sampler::UniformLeft { samples: 0 } => {
                return Err(invalid("sampler", "expected at least 1 sample per ray"))
            }
            Sampler::PerVoxel { per_voxel: 0 } => {
                return Err(invalid("sampler", "expected at least 1 sample per voxel"))
            }
            Sampler::Uniform { samples } | Sampler::UniformLeft { samples }
                if samples > MAX_SAMPLES_PER_RAY =>
            {
                return Err(invalid(
                    "sampler",
                    format!(
                        "expected at most {MAX_SAMPLES_PER_RAY} samples per ray, got {samples}"
                    ),
                ))
            }
            _ => {}
        }
        if !(0.0..1.0).contains(&self.epsilon) {
            return Err(invalid(
                "epsilon",
                format!("expected 0 <= epsilon < 1, got {}", self.epsilon),
            ));
        }
        if self
            .background
            .is_some_and(|b| !b.iter().all(|c| c.abs() <= MAX_VOLUME_VALUE))
        {
            return Err(invalid(
                "background",
                format!(
                    "background colour must be finite and at most {MAX_VOLUME_VALUE:e} in \
                     magnitude, got {:?}",
                    self.background
                ),
            ));
        }
        if let Some([scale, shift]) = self.density.post_activation() {
            if !(scale.is_finite() && scale > 0.0 && shift.is_finite()) {
                return Err(invalid(
                    "density",
                    format!(
                        "post-activation needs a finite scale > 0 and a finite shift, got scale \
                         {scale} and shift {shift}"
                    ),
                ));
            }
        }
        if self.occupancy_cell == 0 {
            return Err(invalid(
                "occupancy_cell",
                "expected at least 1 voxel per cell",
            ));
        }
        Aabb::try_new(self.aabb.min, self.aabb.max)?;
        let reach = self.aabb.min.abs().max(self.aabb.max.abs()).max_element();
        if reach > MAX_COORDINATE {
            return Err(invalid(
                "aabb",
                format!(
                    "box corners must lie within {MAX_COORDINATE:e} of the origin, got {:?}..{:?}",
                    self.aabb.min, self.aabb.max
                ),
            ));
        }
        Ok(())
    }
}
