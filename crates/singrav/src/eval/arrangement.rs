//! The generated volumes' arrangement against the scene's volume: how far their matter is
//! from the scene's ([`layout_distance`], and [`layout_distance_by_position`]), how much of it
//! stands where the scene has no matter of its kind nearby ([`MatterSupport::misplaced`]), both
//! seen from above (docs/metrics.md, "layout_distance" and "misplaced_matter"), and the
//! separate things they hold ([`Objects`], "objects").

use radiance_volume::RadianceVolume;
use scene_metrics::{
    layout_distance, layout_distance_by_position, LayoutPoints, LayoutWeighting, MatterKinds,
    MatterSupport, ObjectRule, Objects, LAYOUT_DIRECTIONS, MISPLACED_KINDS, MISPLACED_REACH,
};

use crate::error::Result;

/// The seed of the layout distance's directions and of the kinds' k-means: the same for every
/// evaluation, so that numbers compare across runs.
const ARRANGEMENT_SEED: u64 = 0;

/// The smallest object counted, as a share of the scene's median object: smaller pieces of
/// solid matter are crumbs, not things (a sample's stray speck is no stone).
const CRUMB_SHARE: f64 = 0.2;

/// The scene's matter that arrangements are measured against.
pub(super) struct SceneMatter {
    points: LayoutPoints,
    places: MatterSupport,
    kinds: MatterKinds,
    /// The scene's own objects.
    objects: Objects,
    /// The smallest counted object's volume (a share of the box).
    min_object: f64,
}

/// One volume's arrangement against the scene's.
pub(super) struct Arrangement {
    /// Its [`layout_distance`] from the scene's matter.
    pub distance: f64,
    /// The same by position alone ([`layout_distance_by_position`]).
    pub position_distance: f64,
    /// The share of its matter standing out of place.
    pub misplaced: f64,
    /// Its objects, counted and sized as the scene's are.
    pub objects: ObjectCount,
}

/// A volume's objects as the evaluation reports them.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ObjectCount {
    /// Objects no smaller than a fifth of the scene's median object.
    pub count: usize,
    /// The same per kind of the scene's matter, in the order of the evaluation's
    /// [`scene_metrics::MatterSupport::kinds`].
    pub by_kind: Vec<usize>,
    /// The largest object's share of all the volume's object matter (1: it all ran together).
    pub largest_share: f64,
}

impl SceneMatter {
    /// The matter of the scene's volume (a fit of the views, or V*), its kinds and their places.
    pub fn of(scene: &RadianceVolume) -> Result<Self> {
        let points = layout_points(scene)?;
        let kinds = MatterKinds::of(&points, MISPLACED_KINDS, ARRANGEMENT_SEED)?;
        let places = MatterSupport::of(&points, kinds.clone(), MISPLACED_REACH)?;
        let objects = objects_of(scene)?;
        let min_object = objects.median_volume(0.0).unwrap_or(0.0) * CRUMB_SHARE;
        Ok(Self {
            points,
            places,
            kinds,
            objects,
            min_object,
        })
    }

    /// The colours of the kinds of the scene's matter (the order of [`ObjectCount::by_kind`]).
    pub fn kind_colours(&self) -> Vec<[f64; 3]> {
        self.kinds.colours().to_vec()
    }

    /// The scene's own objects.
    pub fn own_objects(&self) -> ObjectCount {
        self.count(&self.objects)
    }

    /// The objects of `volume` (the scene's truth, say) counted as the scene's are.
    pub fn objects(&self, volume: &RadianceVolume) -> Result<ObjectCount> {
        Ok(self.count(&objects_of(volume)?))
    }

    fn count(&self, objects: &Objects) -> ObjectCount {
        ObjectCount {
            count: objects.count(self.min_object),
            by_kind: objects.count_by_kind(&self.kinds, self.min_object),
            largest_share: objects.largest_share(),
        }
    }

    /// `volume`'s arrangement against the scene's (a volume with no matter is infinitely far,
    /// [`layout_distance`], and has none out of place).
    pub fn arrangement(&self, volume: &RadianceVolume) -> Result<Arrangement> {
        let points = layout_points(volume)?;
        let (reference, seed) = (&self.points, ARRANGEMENT_SEED);
        Ok(Arrangement {
            distance: layout_distance(reference, &points, LAYOUT_DIRECTIONS, seed)?,
            position_distance: layout_distance_by_position(
                reference,
                &points,
                LAYOUT_DIRECTIONS,
                seed,
            )?,
            misplaced: self.places.misplaced(&points),
            objects: self.objects(volume)?,
        })
    }
}

/// A physical volume's objects by the default rule.
fn objects_of(volume: &RadianceVolume) -> Result<Objects> {
    let voxel = volume.aabb().size().x / volume.dims().xyz()[0] as f32;
    Ok(Objects::of(volume.tensor(), voxel, &ObjectRule::default())?)
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
