//! The generated volumes' arrangement against the scene's volume: how far their matter is
//! from the scene's ([`layout_distance`]) and how much of it stands where the scene has no
//! matter of its kind nearby ([`MatterSupport::misplaced`]). Both see the volumes as seen from
//! above (docs/metrics.md, "layout_distance" and "misplaced_matter").

use radiance_volume::RadianceVolume;
use scene_metrics::{
    layout_distance, LayoutPoints, LayoutWeighting, MatterKinds, MatterSupport, LAYOUT_DIRECTIONS,
    MISPLACED_KINDS, MISPLACED_REACH,
};

use crate::error::Result;

/// The seed of the layout distance's directions and of the kinds' k-means: the same for every
/// evaluation, so that numbers compare across runs.
const ARRANGEMENT_SEED: u64 = 0;

/// The scene's matter that arrangements are measured against.
pub(super) struct SceneMatter {
    points: LayoutPoints,
    places: MatterSupport,
}

/// One volume's arrangement against the scene's.
pub(super) struct Arrangement {
    /// Its [`layout_distance`] from the scene's matter.
    pub distance: f64,
    /// The share of its matter standing out of place.
    pub misplaced: f64,
}

impl SceneMatter {
    /// The matter of the scene's volume (a fit of the views, or V*), its kinds and their places.
    pub fn of(scene: &RadianceVolume) -> Result<Self> {
        let points = layout_points(scene)?;
        let kinds = MatterKinds::of(&points, MISPLACED_KINDS, ARRANGEMENT_SEED)?;
        let places = MatterSupport::of(&points, kinds, MISPLACED_REACH)?;
        Ok(Self { points, places })
    }

    /// `volume`'s arrangement against the scene's (a volume with no matter is infinitely far,
    /// [`layout_distance`], and has none out of place).
    pub fn arrangement(&self, volume: &RadianceVolume) -> Result<Arrangement> {
        let points = layout_points(volume)?;
        Ok(Arrangement {
            distance: layout_distance(&self.points, &points, LAYOUT_DIRECTIONS, ARRANGEMENT_SEED)?,
            misplaced: self.places.misplaced(&points),
        })
    }
}

/// A physical volume's matter as layout points, as seen from above
/// ([`LayoutWeighting::SeenFromAbove`]): a fit of views holds fog where no view sees (below
/// the ground), and a generated volume holds what it likes there; weighted by opacity alone,
/// that hidden matter outweighed the arrangement on top (docs/metrics.md, "layout_distance").
fn layout_points(volume: &RadianceVolume) -> Result<LayoutPoints> {
    let voxel = volume.aabb().size().x / volume.dims().xyz()[0] as f32;
    Ok(LayoutPoints::from_volume_weighted(
        volume.tensor(),
        voxel,
        LayoutWeighting::SeenFromAbove,
    )?)
}
