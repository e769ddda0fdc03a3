//! The generator pyramid: 3D generators G_1..G_{N-1} (G_1 on noise plus the CSG grid, the others
//! residual on the upsampled coarser volume), the 2D upsampler G_N, the per-scale noise
//! amplitudes and the fixed reconstruction noise z*_1.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use candle_core::{DType, Device, ModuleT, Tensor, Var};
use candle_nn::{Module, VarBuilder, VarMap};
use patch_gan::{Generator3d, Generator3dConfig, Upsampler2d, Upsampler2dConfig};
use radiance_volume::resample_tensor;

use crate::active_set::active_sites;
use crate::checkpoint::{Checkpoint, TrainState};
use crate::config::TrainConfig;
use crate::error::{invalid, Error, Result};
use crate::extent::Extended;
use crate::noise::{gaussian_grid, gaussian_volume};

/// Channels of the coarsest noise volume z_1 (it is added to the 3-channel CSG grid).
pub const FIRST_NOISE_CHANNELS: usize = 3;
/// Channels of a raw volume (density and RGB), and of the noise at finer scales.
pub const VOLUME_CHANNELS: usize = 4;

/// A trained (or training) SinGRAV pyramid.
///
/// Generators always normalise with the statistics of the volume they are given (BatchNorm in
/// training mode, as SinGAN's code runs it), so generation does not depend on running averages.
pub struct SinGrav {
    config: TrainConfig,
    device: Device,
    generators: Vec<(Generator3d, VarMap)>,
    upsampler: Option<(Upsampler2d, VarMap)>,
    noise_amps: Vec<f64>,
    z_star: Tensor,
    /// The reconstruction noise z*_n of the 3D scales n >= 2 built so far (index n - 2), when
    /// the configuration optimises it (`reconstruction_noise_lr > 0`); zeros otherwise.
    fine_z_star: Vec<Var>,
    /// Added to the finest 3D scale's reconstruction once training has fitted it to the views
    /// ([`Schedule::reconstruction_fit_steps`](crate::config::Schedule::reconstruction_fit_steps)): `(1, 4, s, s, s)` raw values.
    reconstruction_detail: Option<Tensor>,
    csg: Option<Tensor>,
    /// The grids of scenes generated at an extent other than one ([`SinGrav::set_extent`]).
    pub(crate) extended: Option<Extended>,
}

/// Checkpoint name of [`SinGrav::reconstruction_detail`].
pub const RECONSTRUCTION_DETAIL_TENSOR: &str = "reconstruction_detail";

/// Names of a VarMap's trainable variables (BatchNorm running statistics excluded), sorted so
/// optimisers and checkpoints see them in a fixed order.
pub(crate) fn named_vars(map: &VarMap) -> Vec<(String, Var)> {
    let data = map.data().lock().unwrap_or_else(|e| e.into_inner());
    let mut vars: Vec<(String, Var)> = data
        .iter()
        .filter(|(name, _)| !name.contains("running_"))
        .map(|(n, v)| (n.clone(), v.clone()))
        .collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    vars
}

/// A VarMap's trainable variables as named tensors.
pub(crate) fn var_tensors(map: &VarMap) -> HashMap<String, Tensor> {
    named_vars(map)
        .into_iter()
        .map(|(name, var)| (name, var.as_tensor().clone()))
        .collect()
}

/// Copies every tensor of `from` into the variable of the same name and shape in `to` (the
/// paper initialises G_n, D_n from G_{n-1}, D_{n-1}); differently shaped ones keep their values.
pub(crate) fn copy_matching(from: &HashMap<String, Tensor>, to: &VarMap) -> Result<()> {
    for (name, var) in named_vars(to) {
        if let Some(src) = from.get(&name) {
            if src.shape() == var.as_tensor().shape() {
                var.set(src)?;
            }
        }
    }
    Ok(())
}

/// Zeroes the last layer (`tail.weight`, `tail.bias`) of a residual network, so it starts as
/// the identity on what it refines: a new G_n (n >= 2) outputs exactly the upsampled coarser
/// volume, and the upsampler exactly the bilinear upsample. With few iterations per scale this
/// keeps the coarser scale's layout from the first step, instead of spending the scale on
/// undoing the disturbance that a residual copied from the previous scale (or drawn at random)
/// adds; the layers before the tail keep their initialisation and start learning after the
/// tail's first update.
pub(crate) fn zero_residual(map: &VarMap) -> Result<()> {
    for (name, var) in named_vars(map) {
        if name.starts_with("tail.") {
            var.set(&var.as_tensor().zeros_like()?)?;
        }
    }
    Ok(())
}

/// Re-draws every convolution's weight and bias from `rng` with PyTorch's default bounds
/// `U(-1/sqrt(fan_in), 1/sqrt(fan_in))` (what patch-gan's layers use), so a run's initial
/// weights follow from its seed; candle's own initialisers draw from an unseeded generator.
/// Normalisation parameters keep their constant start (scale 1, shift 0).
pub(crate) fn seeded_init(map: &VarMap, rng: &mut impl rand::Rng) -> Result<()> {
    let vars: HashMap<String, Var> = named_vars(map).into_iter().collect();
    for (name, var) in named_vars(map) {
        let weight_name = match name.strip_suffix("bias") {
            Some(stem) => format!("{stem}weight"),
            None => name.clone(),
        };
        let Some(weight) = vars.get(&weight_name) else {
            continue;
        };
        let dims = weight.as_tensor().dims();
        if dims.len() < 3 {
            continue; // a normalisation layer's scale or shift
        }
        let fan_in: usize = dims[1..].iter().product();
        let bound = 1.0 / (fan_in as f64).sqrt();
        let count = var.as_tensor().elem_count();
        let values: Vec<f32> = (0..count)
            .map(|_| rng.random_range(-bound..bound) as f32)
            .collect();
        let shape = var.as_tensor().shape().clone();
        var.set(&Tensor::from_vec(values, shape, var.as_tensor().device())?)?;
    }
    Ok(())
}

impl SinGrav {
    /// A pyramid with no trained scale yet; `z*_1` is drawn from `rng`.
    pub fn new(config: &TrainConfig, device: &Device, rng: &mut impl rand::Rng) -> Result<Self> {
        config.validate()?;
        let z_star = gaussian_volume(
            rng,
            FIRST_NOISE_CHANNELS,
            config.pyramid.volume_sizes[0],
            config.noise.first_amplitude,
            device,
        )?;
        Self::with_z_star(config, device, z_star)
    }

    /// A pyramid with no trained scale and the given reconstruction noise.
    fn with_z_star(config: &TrainConfig, device: &Device, z_star: Tensor) -> Result<Self> {
        config.validate()?;
        let size = config.pyramid.volume_sizes[0];
        if z_star.dims() != [1, FIRST_NOISE_CHANNELS, size, size, size] {
            return Err(invalid(
                "z_star",
                format!(
                    "expected shape [1, {FIRST_NOISE_CHANNELS}, {size}, {size}, {size}], got {:?}",
                    z_star.dims()
                ),
            ));
        }
        let csg = if config.ablations.use_csg {
            Some(csg_embed::csg_grid_3d(size, size, size, device)?.unsqueeze(0)?)
        } else {
            None
        };
        Ok(Self {
            config: config.clone(),
            device: device.clone(),
            generators: Vec::new(),
            upsampler: None,
            noise_amps: Vec::new(),
            z_star,
            fine_z_star: Vec::new(),
            reconstruction_detail: None,
            csg,
            extended: None,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The device the networks live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The number of 3D scales built so far.
    pub fn volume_scales(&self) -> usize {
        self.generators.len()
    }

    /// Whether the upsampler G_N is built.
    pub fn has_upsampler(&self) -> bool {
        self.upsampler.is_some()
    }

    /// The noise amplitudes of the 3D scales built so far.
    pub fn noise_amps(&self) -> &[f64] {
        &self.noise_amps
    }

    /// The fixed reconstruction noise z*_1 (amplitude included).
    pub fn z_star(&self) -> &Tensor {
        &self.z_star
    }

    /// Adds the next 3D generator with noise amplitude `amp`, initialised from `rng`, then from
    /// the previous generator where shapes agree; returns its variables.
    pub fn push_generator(&mut self, amp: f64, rng: &mut impl rand::Rng) -> Result<VarMap> {
        let n = self.generators.len() + 1;
        if n > self.config.pyramid.volume_sizes.len() {
            return Err(invalid(
                "scale",
                format!("the pyramid has only {} 3D scales", n - 1),
            ));
        }
        let map = VarMap::new();
        let cfg = Generator3dConfig::for_scale(n, self.config.pyramid.layers).with_in_channels(
            if n == 1 {
                FIRST_NOISE_CHANNELS
            } else {
                VOLUME_CHANNELS
            },
        );
        let cfg = Generator3dConfig {
            channels: self.config.pyramid.channels,
            ..cfg
        };
        let generator = Generator3d::new(
            &cfg,
            VarBuilder::from_varmap(&map, DType::F32, &self.device),
        )?;
        seeded_init(&map, rng)?;
        if let Some((_, previous)) = self.generators.last() {
            copy_matching(&var_tensors(previous), &map)?;
            zero_residual(&map)?;
        }
        if n >= 2 && self.config.noise.reconstruction_lr > 0.0 {
            let size = self.config.pyramid.volume_sizes[n - 1];
            self.fine_z_star.push(Var::zeros(
                (1, VOLUME_CHANNELS, size, size, size),
                DType::F32,
                &self.device,
            )?);
        }
        self.generators.push((generator, map.clone()));
        self.noise_amps.push(amp);
        // A detail belongs to the scale that was finest when it was fitted.
        self.reconstruction_detail = None;
        Ok(map)
    }

    /// Adds the upsampler G_N, initialised from `rng`; returns its variables.
    pub fn push_upsampler(&mut self, rng: &mut impl rand::Rng) -> Result<VarMap> {
        let map = VarMap::new();
        let cfg = Upsampler2dConfig {
            channels: 3,
            widths: self.config.pyramid.upsampler_widths,
        };
        let upsampler = Upsampler2d::new(
            &cfg,
            VarBuilder::from_varmap(&map, DType::F32, &self.device),
        )?;
        seeded_init(&map, rng)?;
        zero_residual(&map)?;
        self.upsampler = Some((upsampler, map.clone()));
        Ok(map)
    }

    /// The variables of 3D scale `n` (1-based).
    pub fn generator_vars(&self, n: usize) -> Option<&VarMap> {
        self.generators.get(n.checked_sub(1)?).map(|(_, m)| m)
    }

    /// The upsampler's variables.
    pub fn upsampler_vars(&self) -> Option<&VarMap> {
        self.upsampler.as_ref().map(|(_, m)| m)
    }

    /// Fresh noise for 3D scales `1..=scales`, each at its amplitude.
    pub fn draw_noise(&self, scales: usize, rng: &mut impl rand::Rng) -> Result<Vec<Tensor>> {
        (1..=scales)
            .map(|n| {
                let channels = if n == 1 {
                    FIRST_NOISE_CHANNELS
                } else {
                    VOLUME_CHANNELS
                };
                let amp = self.noise_amps.get(n - 1).copied().unwrap_or(0.0);
                gaussian_grid(rng, channels, self.scale_dims(n), amp, &self.device)
            })
            .collect()
    }

    /// Noise for 3D scales `1..=scales` that varies only from scale `vary_from` on: the
    /// coarser scales take the reconstruction noise ([`SinGrav::reconstruction_noise`]), so
    /// they keep V*'s layout, and the finer ones fresh noise from `rng` (SinGAN's generation
    /// from a given scale: only finer structure varies). Every scale's noise is drawn from
    /// `rng` either way, so a seed gives the same finer noise whatever `vary_from`;
    /// `vary_from` 1 is [`SinGrav::draw_noise`]. Errors unless `vary_from` is one of the
    /// `scales`.
    pub fn draw_noise_from(
        &self,
        scales: usize,
        vary_from: usize,
        rng: &mut impl rand::Rng,
    ) -> Result<Vec<Tensor>> {
        check_vary_from(vary_from, scales)?;
        let mut noise = self.draw_noise(scales, rng)?;
        if vary_from > 1 {
            let kept = self.reconstruction_noise(vary_from - 1)?;
            noise.splice(..vary_from - 1, kept);
        }
        Ok(noise)
    }

    /// Errors unless `vary_from` is one of the 3D scales built, as [`SinGrav::draw_noise_from`]
    /// needs it (so callers can refuse it before any work), and, at an
    /// [extent](SinGrav::set_extent) other than one, unless it is 1.
    pub fn check_vary_from(&self, vary_from: usize) -> Result<()> {
        check_vary_from(vary_from, self.volume_scales())?;
        if vary_from > 1 {
            self.check_learned_size("the reconstruction noise the coarser scales keep")?;
        }
        Ok(())
    }

    /// The optimised reconstruction noise z*_n of 3D scale `n` >= 2, when the configuration
    /// optimises it and the scale is built.
    pub fn reconstruction_noise_var(&self, n: usize) -> Option<&Var> {
        self.fine_z_star.get(n.checked_sub(2)?)
    }

    /// The reconstruction noise for 3D scales `1..=scales`: {z*_1, 0, ..., 0} as in SinGAN, or
    /// with `reconstruction_noise_lr > 0` the optimised z*_n at the scales n >= 2.
    pub fn reconstruction_noise(&self, scales: usize) -> Result<Vec<Tensor>> {
        self.check_learned_size("the reconstruction noise")?;
        let mut noise = vec![self.z_star.clone()];
        for n in 2..=scales {
            let z = match self.reconstruction_noise_var(n) {
                Some(var) => var.as_tensor().clone(),
                None => {
                    let s = self.config.pyramid.volume_sizes[n - 1];
                    Tensor::zeros((1, VOLUME_CHANNELS, s, s, s), DType::F32, &self.device)?
                }
            };
            noise.push(z);
        }
        Ok(noise)
    }

    /// What training's fit of the reconstruction to the views added to the finest 3D scale's
    /// V* ([`Schedule::reconstruction_fit_steps`](crate::config::Schedule::reconstruction_fit_steps)), if it ran: raw values `(1, 4, s, s, s)`.
    /// [`SinGrav::reconstruct`] includes it; generated scenes never see it.
    pub fn reconstruction_detail(&self) -> Option<&Tensor> {
        self.reconstruction_detail.as_ref()
    }

    /// Sets the detail [`SinGrav::reconstruct`] adds to the finest 3D scale's reconstruction.
    ///
    /// Errors unless `detail` has that scale's raw shape `(1, 4, s, s, s)`, and while no 3D
    /// scale is built.
    pub fn set_reconstruction_detail(&mut self, detail: Tensor) -> Result<()> {
        let scales = self.volume_scales();
        let Some(&s) = self.config.pyramid.volume_sizes.get(scales.wrapping_sub(1)) else {
            return Err(invalid("reconstruction detail", "no 3D scale is built"));
        };
        let expected = [1, VOLUME_CHANNELS, s, s, s];
        if detail.dims() != expected {
            return Err(invalid(
                "reconstruction detail",
                format!(
                    "expected shape {expected:?} (3D scale {scales}), got {:?}",
                    detail.dims()
                ),
            ));
        }
        self.reconstruction_detail = Some(
            detail
                .to_device(&self.device)?
                .to_dtype(DType::F32)?
                .detach(),
        );
        Ok(())
    }

    /// Runs the 3D generators 1..=noise.len() and returns the raw volume `(1, 4, s, s, s)` of
    /// the last; differentiable with respect to every generator it runs.
    pub fn generate(&self, noise: &[Tensor]) -> Result<Tensor> {
        let Some(first) = noise.first() else {
            return Err(invalid("noise", "need the noise of at least one scale"));
        };
        if noise.len() > self.generators.len() {
            return Err(invalid(
                "noise",
                format!(
                    "{} scales of noise for {} trained 3D scales",
                    noise.len(),
                    self.generators.len()
                ),
            ));
        }
        let mut volume = self.coarsest(first)?;
        for (i, z) in noise.iter().enumerate().skip(1) {
            volume = self.refine(i + 1, z, &volume)?;
        }
        Ok(volume)
    }

    /// G_1: the coarsest raw volume from noise z_1 (plus the CSG grid unless ablated).
    pub fn coarsest(&self, z: &Tensor) -> Result<Tensor> {
        let (generator, _) = self
            .generators
            .first()
            .ok_or_else(|| invalid("scale", "no 3D scale is built"))?;
        let csg = match &self.extended {
            Some(extended) => &extended.csg,
            None => &self.csg,
        };
        let input = match csg {
            Some(csg) => (z + csg)?,
            None => z.clone(),
        };
        Ok(generator.forward_t(&input, true)?)
    }

    /// G_n for n >= 2: `up(prev) + G_n(z + up(prev))` with `prev` the raw volume of scale n - 1;
    /// from the configuration's `active_set.from_scale` on, the residual only in the active set
    /// of `up(prev)` (see [`crate::active_set`]).
    pub fn refine(&self, n: usize, z: &Tensor, prev: &Tensor) -> Result<Tensor> {
        let (generator, _) = self
            .generators
            .get(n.wrapping_sub(1))
            .filter(|_| n >= 2)
            .ok_or_else(|| invalid("scale", format!("3D scale {n} is not built")))?;
        let up = self.upsample_to_scale(prev, n)?;
        match self.config.active_set.from_scale {
            Some(from) if n >= from => {
                let sites = Arc::new(active_sites(
                    &up,
                    &self.config.activation(),
                    &self.config.active_set_rule(),
                    generator.config().kernel,
                )?);
                Ok(generator.forward_residual_active(z, &up, &sites, true)?)
            }
            _ => Ok(generator.forward_residual(z, &up, true)?),
        }
    }

    /// Resamples a raw volume to the size of 3D scale `n` (trilinear, differentiable).
    pub fn upsample_to_scale(&self, volume: &Tensor, n: usize) -> Result<Tensor> {
        Ok(resample_tensor(volume, self.scale_dims(n))?)
    }

    /// Applies G_N to renderings `(B, 3, h, w)`, giving `(B, 3, 2h, 2w)`.
    pub fn upsample_images(&self, images: &Tensor) -> Result<Tensor> {
        let (upsampler, _) = self
            .upsampler
            .as_ref()
            .ok_or_else(|| invalid("upsampler", "the last scale is not trained yet"))?;
        Ok(upsampler.forward(images)?)
    }

    /// Every generator's and the upsampler's trainable tensors, named `g{n}.{var}` and
    /// `up.{var}`, plus `z_star`, the optimised `z_star.{n}` and the fitted
    /// `reconstruction_detail` where the model has them.
    pub fn tensors(&self) -> HashMap<String, Tensor> {
        let mut out = HashMap::new();
        for (i, (_, map)) in self.generators.iter().enumerate() {
            for (name, t) in var_tensors(map) {
                out.insert(format!("g{}.{name}", i + 1), t);
            }
        }
        if let Some((_, map)) = &self.upsampler {
            for (name, t) in var_tensors(map) {
                out.insert(format!("up.{name}"), t);
            }
        }
        out.insert("z_star".into(), self.z_star.clone());
        for (i, z) in self.fine_z_star.iter().enumerate() {
            out.insert(format!("z_star.{}", i + 2), z.as_tensor().clone());
        }
        if let Some(detail) = &self.reconstruction_detail {
            out.insert(RECONSTRUCTION_DETAIL_TENSOR.into(), detail.clone());
        }
        out
    }

    /// Loads a trained pyramid from a run directory or checkpoint file, with its state (to
    /// report, for example, whether training finished).
    pub fn load(model: &Path, device: &Device) -> Result<(Self, TrainState)> {
        let path = crate::RunDir::checkpoint_of(model);
        let checkpoint = Checkpoint::load(&path, device)?;
        let state = checkpoint.state;
        if state.noise_amps.is_empty() {
            return Err(Error::Checkpoint {
                path,
                why: "no scale has been trained yet".into(),
            });
        }
        let model = Self::from_tensors(
            &checkpoint.config,
            &checkpoint.tensors,
            &state.noise_amps,
            state.upsampler && state.finished(&checkpoint.config),
            device,
        )
        .map_err(|why| Error::Checkpoint { path, why })?;
        Ok((model, state))
    }

    /// Rebuilds a pyramid with `scales` 3D scales (and the upsampler when `upsampler` is set)
    /// from tensors written by [`SinGrav::tensors`].
    pub fn from_tensors(
        config: &TrainConfig,
        tensors: &HashMap<String, Tensor>,
        noise_amps: &[f64],
        upsampler: bool,
        device: &Device,
    ) -> std::result::Result<Self, String> {
        let z_star = tensors
            .get("z_star")
            .ok_or("tensor `z_star` is missing")?
            .to_device(device)
            .map_err(|e| e.to_string())?;
        let mut model = Self::with_z_star(config, device, z_star).map_err(|e| e.to_string())?;
        // Every weight is overwritten below; the draw only fills them in the meantime.
        let mut rng = crate::noise::step_rng(0, 0, 0);
        for &amp in noise_amps {
            let map = model
                .push_generator(amp, &mut rng)
                .map_err(|e| e.to_string())?;
            let n = model.generators.len();
            load_into(&map, tensors, &format!("g{n}."), device)?;
            if let Some(var) = model.reconstruction_noise_var(n) {
                let key = format!("z_star.{n}");
                let saved = tensors
                    .get(&key)
                    .ok_or_else(|| format!("tensor `{key}` is missing"))?;
                set_checked(var, saved, &key, device)?;
            }
        }
        if upsampler {
            let map = model.push_upsampler(&mut rng).map_err(|e| e.to_string())?;
            load_into(&map, tensors, "up.", device)?;
        }
        if let Some(detail) = tensors.get(RECONSTRUCTION_DETAIL_TENSOR) {
            let detail = detail.to_device(device).map_err(|e| e.to_string())?;
            model
                .set_reconstruction_detail(detail)
                .map_err(|e| format!("tensor `{RECONSTRUCTION_DETAIL_TENSOR}`: {e}"))?;
        }
        Ok(model)
    }
}

/// Errors unless `vary_from` is one of `scales` 3D scales (1-based), naming the setting: what
/// [`SinGrav::draw_noise_from`], the evaluation and the animation accept.
pub(crate) fn check_vary_from(vary_from: usize, scales: usize) -> Result<()> {
    if (1..=scales).contains(&vary_from) {
        return Ok(());
    }
    Err(invalid(
        "vary_from",
        format!("expected one of the model's 3D scales 1 to {scales}, got {vary_from}"),
    ))
}

/// Sets every trainable variable of `map` from `tensors[prefix + name]`.
pub(crate) fn load_into(
    map: &VarMap,
    tensors: &HashMap<String, Tensor>,
    prefix: &str,
    device: &Device,
) -> std::result::Result<(), String> {
    for (name, var) in named_vars(map) {
        let key = format!("{prefix}{name}");
        let saved = tensors
            .get(&key)
            .ok_or_else(|| format!("tensor `{key}` is missing"))?;
        set_checked(&var, saved, &key, device)?;
    }
    Ok(())
}

/// Sets `var` to the saved tensor `key`, which must have its shape.
fn set_checked(
    var: &Var,
    saved: &Tensor,
    key: &str,
    device: &Device,
) -> std::result::Result<(), String> {
    if saved.shape() != var.as_tensor().shape() {
        return Err(format!(
            "tensor `{key}` has shape {:?}, the model expects {:?}",
            saved.shape(),
            var.as_tensor().shape()
        ));
    }
    let saved = saved.to_device(device).map_err(|e| e.to_string())?;
    var.set(&saved).map_err(|e| e.to_string())
}
