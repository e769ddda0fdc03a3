//! The sample metrics of a set of scenes seen from the evaluation's views: of the generated
//! scenes, and of the reference family of a built-in scene.

use candle_core::Tensor;
use scene_metrics::{
    colour_swd_per_scene, diversity_mv, floaters_per_scene, patch_swd_per_scene, sifid_mv,
    Estimate, InceptionBlock1, PATCH_SWD_MIN_SIDE,
};
use serde::Serialize;

use super::arrangement::{Arrangement, ObjectCount};
use crate::error::Result;

/// Scenes as the evaluation sees them, one entry per scene.
pub(super) struct SeenScenes {
    /// Colour renderings `(V, 3, h, w)` at the compared size.
    pub views: Vec<Tensor>,
    /// Opacity renderings `(V, 1, h', w')` at the real opacity maps' size.
    pub opacity: Vec<Tensor>,
    /// Layout distances from the scene's volume.
    pub layouts: Vec<f64>,
    /// The same by position alone.
    pub position_layouts: Vec<f64>,
    /// Shares of matter out of place against the scene's volume.
    pub misplaced: Vec<f64>,
    /// Their objects.
    pub objects: Vec<ObjectCount>,
}

impl SeenScenes {
    pub fn with_capacity(scenes: usize) -> Self {
        Self {
            views: Vec::with_capacity(scenes),
            opacity: Vec::with_capacity(scenes),
            layouts: Vec::with_capacity(scenes),
            position_layouts: Vec::with_capacity(scenes),
            misplaced: Vec::with_capacity(scenes),
            objects: Vec::with_capacity(scenes),
        }
    }

    /// Records the next scene's arrangement.
    pub fn push_arrangement(&mut self, arrangement: Arrangement) {
        self.layouts.push(arrangement.distance);
        self.position_layouts.push(arrangement.position_distance);
        self.misplaced.push(arrangement.misplaced);
        self.objects.push(arrangement.objects);
    }
}

/// The sample metrics of a set of scenes against the real views (docs/metrics.md), each with
/// its standard error over the scenes where it has one.
#[derive(Debug, Clone, Serialize)]
pub struct SceneScores {
    /// Lower is closer to the real views' patch statistics; None for views too small for its
    /// pyramid.
    pub patch_swd_mv: Option<f64>,
    /// One standard error of `patch_swd_mv` over the scenes (as for every `_stderr` below: the
    /// value's spread over repeated draws of as many scenes; None for a single scene).
    pub patch_swd_mv_stderr: Option<f64>,
    /// Lower is closer to the real views' colours.
    pub colour_swd: f64,
    /// Its standard error over scenes.
    pub colour_swd_stderr: Option<f64>,
    /// Mean opacity where the real views are empty; None when no real pixel is empty.
    pub floaters: Option<f64>,
    /// Its standard error over scenes.
    pub floaters_stderr: Option<f64>,
    /// Higher is more varied; 0 when every scene is the same; None for a single scene (it is a
    /// spread over scenes).
    pub diversity_mv: Option<f64>,
    /// The jackknife standard error over scenes; None with fewer than 3 scenes.
    pub diversity_mv_stderr: Option<f64>,
    /// Lower is closer to the real views' statistics; None without InceptionV3 weights.
    pub sifid_mv: Option<f64>,
    /// The volumes' mean [`layout_distance`](scene_metrics::layout_distance) from the
    /// evaluation's reference volume: lower keeps the scene's arrangement (where its matter
    /// is, of which colour) closer.
    pub layout_distance: f64,
    /// Its standard error over scenes.
    pub layout_distance_stderr: Option<f64>,
    /// The mean layout distance by position alone
    /// ([`layout_distance_by_position`](scene_metrics::layout_distance_by_position)): where
    /// `layout_distance` is high and this is not, the matter stands in the scene's places in
    /// other colours.
    pub layout_distance_by_position: f64,
    /// Its standard error over scenes.
    pub layout_distance_by_position_stderr: Option<f64>,
    /// The volumes' mean share of matter out of place against the evaluation's reference
    /// volume ([`MatterSupport::misplaced`](scene_metrics::MatterSupport::misplaced)): matter
    /// standing where the scene has none of its colour nearby; lower keeps the arrangement.
    pub misplaced_matter: f64,
    /// Its standard error over scenes.
    pub misplaced_matter_stderr: Option<f64>,
    /// The volumes' mean number of objects ([`Objects`](scene_metrics::Objects): separate
    /// pieces of solid matter above the ground, no smaller than a fifth of the scene's median
    /// object): fewer than the scene's where neighbours run together.
    pub objects: f64,
    /// Its standard error over scenes.
    pub objects_stderr: Option<f64>,
    /// The mean number per kind of the scene's matter (the evaluation's `object_kinds`).
    pub objects_by_kind: Vec<f64>,
    /// The volumes' mean share of their object matter in their largest object.
    pub largest_object_share: f64,
    /// Its standard error over scenes.
    pub largest_object_share_stderr: Option<f64>,
    /// The largest of the volumes' largest-object shares.
    pub largest_object_share_max: f64,
}

impl SceneScores {
    /// The metrics of `seen` against the real colour views `real` `(V, 3, h, w)` and alpha
    /// `real_alpha` `(V, 1, h', w')`; `inception` adds SIFID-MV.
    pub(super) fn of(
        seen: &SeenScenes,
        real: &Tensor,
        real_alpha: &Tensor,
        inception: Option<&InceptionBlock1>,
    ) -> Result<Self> {
        let image_size = real.dim(3)?;
        let patch_swd = (image_size >= PATCH_SWD_MIN_SIDE)
            .then(|| mean_and_error(&patch_swd_per_scene(&seen.views, real)?))
            .transpose()?;
        let colour = mean_and_error(&colour_swd_per_scene(&seen.views, real)?)?;
        let layout = mean_and_error(&seen.layouts)?;
        let position_layout = mean_and_error(&seen.position_layouts)?;
        let misplaced = mean_and_error(&seen.misplaced)?;
        let counts: Vec<f64> = seen.objects.iter().map(|o| o.count as f64).collect();
        let objects = mean_and_error(&counts)?;
        let shares: Vec<f64> = seen.objects.iter().map(|o| o.largest_share).collect();
        let largest = mean_and_error(&shares)?;
        let kinds = seen.objects.first().map_or(0, |o| o.by_kind.len());
        let objects_by_kind = (0..kinds)
            .map(|k| {
                let total: usize = seen.objects.iter().map(|o| o.by_kind[k]).sum();
                total as f64 / seen.objects.len() as f64
            })
            .collect();
        let floaters = floaters_per_scene(&seen.opacity, real_alpha)?
            .map(|per_scene| mean_and_error(&per_scene))
            .transpose()?;
        // The jackknife computes Diversity-MV over all scenes too; below 3 scenes it has no
        // error, below 2 no value.
        let (diversity, diversity_stderr) = match seen.views.len() {
            0 | 1 => (None, None),
            2 => (Some(diversity_mv(&seen.views, real)?), None),
            _ => {
                let estimate =
                    Estimate::jackknife(&seen.views, |scenes| diversity_mv(scenes, real))?;
                (Some(estimate.value), Some(estimate.stderr))
            }
        };
        Ok(Self {
            patch_swd_mv: patch_swd.map(|e| e.0),
            patch_swd_mv_stderr: patch_swd.and_then(|e| e.1),
            colour_swd: colour.0,
            colour_swd_stderr: colour.1,
            floaters: floaters.map(|e| e.0),
            floaters_stderr: floaters.and_then(|e| e.1),
            diversity_mv: diversity,
            diversity_mv_stderr: diversity_stderr,
            sifid_mv: inception
                .map(|block| sifid_mv(&seen.views, real, block))
                .transpose()?,
            layout_distance: layout.0,
            layout_distance_stderr: layout.1,
            layout_distance_by_position: position_layout.0,
            layout_distance_by_position_stderr: position_layout.1,
            misplaced_matter: misplaced.0,
            misplaced_matter_stderr: misplaced.1,
            objects: objects.0,
            objects_stderr: objects.1,
            objects_by_kind,
            largest_object_share: largest.0,
            largest_object_share_stderr: largest.1,
            largest_object_share_max: shares.iter().copied().fold(0.0, f64::max),
        })
    }
}

/// The mean of per-scene values with its standard error (None for a single scene).
fn mean_and_error(values: &[f64]) -> Result<(f64, Option<f64>)> {
    if values.len() == 1 {
        return Ok((values[0], None));
    }
    let estimate = Estimate::mean_of(values)?;
    Ok((estimate.value, Some(estimate.stderr)))
}
