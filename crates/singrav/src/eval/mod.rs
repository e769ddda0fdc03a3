//! The evaluation protocol: every quality number of a trained model against its dataset.
//!
//! It renders the fixed-noise reconstruction V* and [`EvalConfig::scenes`] generated scenes
//! from cameras of the training dataset and compares them with the dataset's images from the
//! same cameras, as the paper evaluates SinGRAV (docs/metrics.md defines every number):
//!
//! - V* against the training views (and the held-out views of a run trained with a holdout):
//!   PSNR, SSIM and depth RMSE as the model outputs them, and V*'s volume itself as
//!   `volgen fit` scores its volumes ([`SinGrav::volume_psnr`]);
//! - the generated scenes against [`EvalConfig::views`] views spread over all frames: patch
//!   SWD-MV, colour SWD, floaters, Diversity-MV (each with its standard error over scenes) and,
//!   given InceptionV3's first block, SIFID-MV;
//! - the generated volumes' arrangement against the scene's volume, which is a direct fit of
//!   the training views ([`LayoutReference::Fit`]) or V* ([`LayoutReference::Reconstruction`]):
//!   their [`layout_distance`](scene_metrics::layout_distance) from it, and their share of
//!   matter out of place ([`MatterSupport::misplaced`](scene_metrics::MatterSupport::misplaced):
//!   standing where the scene has no matter of its colour nearby);
//! - for a dataset of a built-in scene, with [`EvalConfig::family`], the same sample metrics
//!   of the scene's other layouts seen from the same views ([`Family`]): what a perfect
//!   generator of that kind of scene scores.
//!
//! ```no_run
//! use singrav::eval::{evaluate, EvalConfig};
//! let (model, _) = singrav::SinGrav::load("out/demo/run".as_ref(), &candle_core::Device::Cpu)?;
//! let data = rgbd_dataset::Dataset::load("out/demo/dataset".as_ref(), model.config().rendering.background)?;
//! let numbers = evaluate(&model, &data, &EvalConfig::default(), None, &mut |_, _| {})?;
//! println!("V*: {:.2} dB, Diversity-MV {:?}", numbers.reconstruction_psnr, numbers.samples.diversity_mv);
//! # Ok::<(), singrav::Error>(())
//! ```

use candle_core::Tensor;
use rand::SeedableRng;
use rgbd_dataset::{Dataset, DepthKind};
use scene_metrics::{depth_rmse, mean_psnr, mean_ssim, InceptionBlock1};
use serde::Serialize;

use crate::error::{invalid, Result};
use crate::SinGrav;

mod arrangement;
mod family;
mod scores;

use arrangement::SceneMatter;

pub use arrangement::ObjectCount;
pub use family::Family;
pub use scores::SceneScores;
use scores::SeenScenes;

/// The scene's volume the generated volumes' arrangement is measured against.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum LayoutReference {
    /// A direct fit of the dataset's training views ([`crate::train::fit_training_target`]):
    /// the scene itself, as far as its views show it.
    #[default]
    Fit,
    /// The model's reconstruction V* (no fit; what the model learnt of the scene).
    Reconstruction,
}

impl std::str::FromStr for LayoutReference {
    type Err = crate::Error;

    fn from_str(name: &str) -> Result<Self> {
        match name {
            "fit" => Ok(Self::Fit),
            "vstar" | "reconstruction" => Ok(Self::Reconstruction),
            other => Err(invalid(
                "layout reference",
                format!("`{other}`: expected fit or vstar"),
            )),
        }
    }
}

/// How many scenes and views an evaluation compares, and the noise it draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EvalConfig {
    /// Scenes to generate (at least 2: Diversity-MV is a spread over scenes; the paper: 50).
    /// With 32 a `tiny` run's floaters vary by about 10% between noise seeds, with 8 by twice
    /// that (docs/metrics.md, "How precise the sample metrics are").
    pub scenes: usize,
    /// Dataset views to compare, evenly spaced over its frames (the paper: 40); as many of the
    /// training and of the held-out frames for the reconstruction.
    pub views: usize,
    /// Seed of the noise; the same seed gives the scenes `volgen sample --seed` gives.
    pub seed: u64,
    /// The scene's volume the layout distance is measured against.
    pub layout_reference: LayoutReference,
    /// The coarsest 3D scale whose noise varies ([`SinGrav::draw_noise_from`]; 1: every
    /// scale's).
    pub vary_from: usize,
    /// Other layouts of the dataset's built-in scene to score as a reference row
    /// ([`Family`]); 0: none. Needs a dataset that records its scene
    /// ([`Dataset::scene_source`]).
    pub family: usize,
}

impl Default for EvalConfig {
    /// `volgen eval`'s defaults: 32 scenes from 4 views, seed 0, layouts against a fit, every
    /// scale varying, no family.
    fn default() -> Self {
        Self {
            scenes: 32,
            views: 4,
            seed: 0,
            layout_reference: LayoutReference::Fit,
            vary_from: 1,
            family: 0,
        }
    }
}

/// Every number of one model (what `eval.json` holds besides the paths). Infinite PSNRs (exact
/// reconstructions) serialise as null.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// Scenes generated.
    pub scenes: usize,
    /// Seed of their noise.
    pub seed: u64,
    /// The dataset frames (their `file_path`) the generated scenes were seen from.
    pub views: Vec<String>,
    /// Edge of the compared colour images in pixels (the model's final size).
    pub image_size: usize,
    /// Edge of the depth and opacity maps (the last 3D scale's rendering size).
    pub depth_size: usize,
    /// The run's `--holdout N`, if it had one.
    pub holdout: Option<usize>,
    /// The training frames the reconstruction was seen from.
    pub reconstruction_views: Vec<String>,
    /// dB, higher is better.
    pub reconstruction_psnr: f64,
    /// 1 is a perfect reconstruction.
    pub reconstruction_ssim: f64,
    /// World units, lower is better; None for a dataset without depth maps (`depth_kind`
    /// none).
    pub reconstruction_depth_rmse: Option<f64>,
    /// The held-out frames (empty without a holdout).
    pub held_out_views: Vec<String>,
    /// V* on the held-out views, dB.
    pub held_out_psnr: Option<f64>,
    /// V* on the held-out views.
    pub held_out_ssim: Option<f64>,
    /// V* on the held-out views, world units (None also without depth maps).
    pub held_out_depth_rmse: Option<f64>,
    /// dB: V* itself, the finest 3D scale's volume, rendered from every training view at the
    /// dataset's resolution as `volgen fit` measures its volumes, by the run's density rule
    /// (post-activated runs: as `volgen fit --post-activation`), so the two compare on equal
    /// terms (no upsampler).
    pub volume_psnr: f64,
    /// How many training views `volume_psnr` averages.
    pub volume_views: usize,
    /// The same over every held-out view (None without a holdout).
    pub held_out_volume_psnr: Option<f64>,
    /// The coarsest 3D scale whose noise varied.
    pub vary_from: usize,
    /// The generated scenes' sample metrics.
    #[serde(flatten)]
    pub samples: SceneScores,
    /// V*'s layout distance from the fit (None when V* is the reference).
    pub reconstruction_layout_distance: Option<f64>,
    /// V*'s layout distance from the fit by position alone (None when V* is the reference).
    pub reconstruction_layout_distance_by_position: Option<f64>,
    /// V*'s share of matter out of place against the fit (None when V* is the reference).
    pub reconstruction_misplaced_matter: Option<f64>,
    /// What the layout distances are measured against: `fit` (a direct fit of the training
    /// views) or `vstar`.
    pub layout_reference: String,
    /// The colours of the kinds of the reference's matter, the order of every `by_kind` count.
    pub object_kinds: Vec<[f64; 3]>,
    /// The layout reference's own objects (a fit's neighbours may run together too).
    pub reference_objects: ObjectCount,
    /// For a dataset of a built-in scene, the objects of the scene itself (its layout baked at
    /// the finest 3D scale's grid): the count the samples should reach.
    pub true_objects: Option<ObjectCount>,
    /// The reference row of the built-in scene's other layouts, when asked for.
    pub family: Option<Family>,
}

/// How closely V* reproduces a set of real views.
struct Reproduction {
    views: Vec<String>,
    psnr: f64,
    ssim: f64,
    depth_rmse: Option<f64>,
}

/// Every number of `model` against `dataset` (in the scene's own coordinates, as loaded; a run
/// trained with `--bounds` is compared in its model cube). `inception` adds SIFID-MV;
/// `progress(i, scenes)` is called after each generated scene is rendered.
pub fn evaluate(
    model: &SinGrav,
    dataset: &Dataset,
    config: &EvalConfig,
    inception: Option<&InceptionBlock1>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Evaluation> {
    if config.scenes < 2 {
        return Err(invalid(
            "scenes",
            "must be at least 2: Diversity-MV is a spread over scenes",
        ));
    }
    if config.views < 1 {
        return Err(invalid("views", "must be at least 1"));
    }
    model.check_vary_from(config.vary_from)?;
    let scales = model.volume_scales();
    let source =
        match (config.family, dataset.scene_source()) {
            (0, _) => None,
            (_, Some(source)) => Some(source),
            (_, None) => return Err(invalid(
                "family",
                "the dataset records no built-in scene (`volgen_scene` in its transforms.json, \
                 which `volgen scene` and `volgen demo` write), so it has no family of layouts",
            )),
        };
    let device = model.device();
    // The model renders in its own cube: a run trained with --bounds sees the views there.
    // Kept apart from the scene's copy only when the two differ.
    let in_cube = match &model.config().run.bounds {
        Some(bounds) => Some(dataset.in_model_cube(bounds)?),
        None => None,
    };
    let scene_dataset = dataset;
    let dataset = in_cube.as_ref().unwrap_or(scene_dataset);
    if config.views > dataset.len() {
        return Err(invalid(
            "views",
            format!(
                "{} is more than the dataset's {} frames",
                config.views,
                dataset.len()
            ),
        ));
    }
    let holdout = model.config().run.holdout;
    let (training, held_out) = match holdout {
        Some(every) => dataset.holdout_split(every)?,
        None => ((0..dataset.len()).collect(), Vec::new()),
    };

    let v_star = model.reconstruct()?;
    let reference = scene_matter(model, &v_star, scene_dataset, config.layout_reference)?;
    let true_objects = scene_dataset
        .scene_source()
        .map(|source| {
            let finest = model.config().pyramid.volume_sizes[scales - 1];
            let truth = source
                .kind
                .build(source.seed)
                .to_volume(radiance_volume::GridDims::cube(finest))?;
            reference.objects(&truth)
        })
        .transpose()?;
    let reconstruction_arrangement = match config.layout_reference {
        LayoutReference::Fit => Some(reference.arrangement(&model.to_physical(&v_star)?)?),
        LayoutReference::Reconstruction => None,
    };
    let reconstruction = reproduction(model, &v_star, dataset, &spread(&training, config.views))?;
    let held = (!held_out.is_empty())
        .then(|| reproduction(model, &v_star, dataset, &spread(&held_out, config.views)))
        .transpose()?;
    // In the scene's coordinates, with the density rule the run renders by.
    let training_volume_psnr = model.volume_psnr(&v_star, scene_dataset, &training)?;
    let held_out_volume_psnr = (!held_out.is_empty())
        .then(|| model.volume_psnr(&v_star, scene_dataset, &held_out))
        .transpose()?;

    let all: Vec<usize> = (0..dataset.len()).collect();
    let chosen_frames = spread(&all, config.views);
    let chosen = dataset.subset(&chosen_frames)?;
    let size = model.render_size();
    let coarse = chosen.level(size, size, device)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let mut seen = SeenScenes::with_capacity(config.scenes);
    for i in 0..config.scenes {
        // As `SinGrav::sample_varying_from` draws them: scene i here is scene i of
        // `volgen sample --vary-from`.
        let raw = model.generate_random_from(&mut rng, config.vary_from)?;
        seen.push_arrangement(reference.arrangement(&model.to_physical(&raw)?)?);
        let maps = model.render_maps(&raw, &coarse.cameras)?;
        seen.views.push(maps.rgb);
        seen.opacity.push(maps.opacity);
        progress(i + 1, config.scenes);
    }
    // The upsampler, when trained, doubles the renderings: compare at the size they came out.
    let image_size = seen.views[0].dim(3)?;
    let real = chosen.level(image_size, image_size, device)?.images;
    let samples = SceneScores::of(&seen, &real, &coarse.opacity, inception)?;
    let family = source
        .map(|source| {
            let views = family::FamilyViews {
                frames: scene_dataset.subset(&chosen_frames)?,
                image_size,
                opacity_size: size,
                grid: model.config().pyramid.volume_sizes[scales - 1],
                background: model.config().rendering.background,
            };
            Family::score(
                source,
                config.family,
                &views,
                &reference,
                &real,
                &coarse.opacity,
                inception,
            )
        })
        .transpose()?;

    Ok(Evaluation {
        scenes: config.scenes,
        seed: config.seed,
        views: chosen.frame_names().to_vec(),
        image_size,
        depth_size: size,
        holdout,
        reconstruction_views: reconstruction.views,
        reconstruction_psnr: reconstruction.psnr,
        reconstruction_ssim: reconstruction.ssim,
        reconstruction_depth_rmse: reconstruction.depth_rmse,
        held_out_views: held.as_ref().map(|h| h.views.clone()).unwrap_or_default(),
        held_out_psnr: held.as_ref().map(|h| h.psnr),
        held_out_ssim: held.as_ref().map(|h| h.ssim),
        held_out_depth_rmse: held.as_ref().and_then(|h| h.depth_rmse),
        volume_psnr: training_volume_psnr,
        volume_views: training.len(),
        held_out_volume_psnr,
        vary_from: config.vary_from,
        samples,
        reconstruction_layout_distance: reconstruction_arrangement.as_ref().map(|a| a.distance),
        reconstruction_layout_distance_by_position: reconstruction_arrangement
            .as_ref()
            .map(|a| a.position_distance),
        reconstruction_misplaced_matter: reconstruction_arrangement.as_ref().map(|a| a.misplaced),
        layout_reference: match config.layout_reference {
            LayoutReference::Fit => "fit".into(),
            LayoutReference::Reconstruction => "vstar".into(),
        },
        object_kinds: reference.kind_colours(),
        reference_objects: reference.own_objects(),
        true_objects,
        family,
    })
}

/// The scene's matter that arrangements are measured against, in the scene's coordinates: a
/// fit of `dataset`'s training views, or V*.
fn scene_matter(
    model: &SinGrav,
    v_star: &Tensor,
    dataset: &Dataset,
    reference: LayoutReference,
) -> Result<SceneMatter> {
    let volume = match reference {
        LayoutReference::Fit => {
            // At the finest 3D scale, as the generated volumes are, whatever size the run's
            // own fit for its 3D critic had.
            let at_finest = model.config().clone().with(|c| c.pyramid.fit_size = None);
            crate::train::fit_training_target(&at_finest, dataset, None, &mut |_| {})?.volume
        }
        LayoutReference::Reconstruction => model.to_physical(v_star)?,
    };
    SceneMatter::of(&volume)
}

/// V* against the dataset's `frames`: colour at the final size, depth at the 3D pyramid's.
fn reproduction(
    model: &SinGrav,
    v_star: &Tensor,
    dataset: &Dataset,
    frames: &[usize],
) -> Result<Reproduction> {
    let chosen = dataset.subset(frames)?;
    let size = model.render_size();
    let coarse = chosen.level(size, size, model.device())?;
    let maps = model.render_maps(v_star, &coarse.cameras)?;
    let image_size = maps.rgb.dim(3)?;
    let real = chosen.level(image_size, image_size, model.device())?.images;
    Ok(Reproduction {
        views: chosen.frame_names().to_vec(),
        psnr: mean_psnr(&maps.rgb, &real)?,
        ssim: mean_ssim(&maps.rgb, &real)?,
        depth_rmse: (dataset.depth_kind() != DepthKind::None)
            .then(|| depth_rmse(&maps.depth, &coarse.depths))
            .transpose()?,
    })
}

/// `count` of `indices` evenly spaced (all of them when there are fewer).
fn spread(indices: &[usize], count: usize) -> Vec<usize> {
    let count = count.min(indices.len());
    (0..count)
        .map(|i| indices[i * indices.len() / count])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::spread;

    #[test]
    fn spread_takes_evenly_spaced_indices_and_all_when_there_are_fewer() {
        assert_eq!(spread(&[0, 1, 2, 3, 4, 5, 6, 7], 4), vec![0, 2, 4, 6]);
        assert_eq!(spread(&[3, 5, 9], 2), vec![3, 5]);
        assert_eq!(spread(&[3, 5], 4), vec![3, 5]);
    }
}
