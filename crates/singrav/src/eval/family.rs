//! The reference row of a built-in scene: its other layouts ([`SceneSource::family_seeds`])
//! seen from the evaluation's views and scored with the same functions as the generated
//! scenes, which is what a perfect generator of that kind of scene scores.

use candle_core::Tensor;
use radiance_volume::GridDims;
use rgbd_dataset::{Dataset, SceneSource};
use scene_metrics::InceptionBlock1;
use serde::Serialize;

use super::arrangement::SceneMatter;
use super::scores::{SceneScores, SeenScenes};
use crate::error::Result;

/// How the family's layouts are seen: as the generated scenes are.
pub(super) struct FamilyViews {
    /// The evaluation's frames at the dataset's resolution, in the scene's coordinates.
    pub frames: Dataset,
    /// Edge of the compared colour images.
    pub image_size: usize,
    /// Edge of the compared opacity maps.
    pub opacity_size: usize,
    /// Edge of the grid the layouts are baked on for the layout distance: the model's finest
    /// 3D scale, so that their matter is as coarse as the generated volumes'.
    pub grid: usize,
    /// What transparent pixels are composited onto.
    pub background: [f32; 3],
}

/// Other layouts of the dataset's built-in scene, scored as the generated scenes are.
#[derive(Debug, Clone, Serialize)]
pub struct Family {
    /// The built-in scene's name.
    pub scene: String,
    /// The layouts' seeds (the dataset's own layout is not among them).
    pub seeds: Vec<u64>,
    /// Their sample metrics.
    #[serde(flatten)]
    pub scores: SceneScores,
}

impl Family {
    /// Bakes `count` other layouts of `source` on its grid, renders them from `views.frames`'s
    /// cameras as the dataset was rendered ([`Dataset::rendered`]), resizes them as the real
    /// views are, and scores them against `real` and `real_alpha`, their arrangement against
    /// `reference`.
    pub(super) fn score(
        source: SceneSource,
        count: usize,
        views: &FamilyViews,
        reference: &SceneMatter,
        real: &Tensor,
        real_alpha: &Tensor,
        inception: Option<&InceptionBlock1>,
    ) -> Result<Self> {
        let device = real.device();
        let seeds: Vec<u64> = source.family_seeds(count).collect();
        let mut seen = SeenScenes::with_capacity(count);
        for &seed in &seeds {
            let scene = source.kind.build(seed);
            let full = scene.to_volume(GridDims::cube(source.grid))?;
            let rendered = views.frames.rendered(&full, views.background)?;
            let size = views.image_size;
            seen.views.push(rendered.level(size, size, device)?.images);
            let size = views.opacity_size;
            seen.opacity
                .push(rendered.level(size, size, device)?.opacity);
            let coarse = scene.to_volume(GridDims::cube(views.grid))?;
            seen.push_arrangement(reference.arrangement(&coarse)?);
        }
        Ok(Self {
            scene: source.kind.name().to_owned(),
            seeds,
            scores: SceneScores::of(&seen, real, real_alpha, inception)?,
        })
    }
}
