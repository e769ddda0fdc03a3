//! Editing a scene as the paper does: on the finest raw volume V_{N-1} (before the activation,
//! so the generators can harmonise the result), a box in world coordinates becomes a mask of the
//! voxels whose centres it holds; removal fills the mask with an "empty" voxel, duplicate copies
//! the masked content by an offset, and move does both.

use std::fmt;

use candle_core::Tensor;
use glam::Vec3;
use radiance_volume::{Aabb, Activation, RadianceVolume};

use crate::error::{invalid, Result};

/// The physical density (1/world-length) that removal leaves behind: a ray crossing the whole
/// volume box along its diagonal (2 sqrt(3) long) loses less than 0.04 % of its light there,
/// less than one step of an 8-bit colour. (No raw value gives exactly 0: softplus never does.)
pub const EMPTY_SIGMA: f32 = 1e-4;

/// One of the paper's edits, with boxes in world coordinates inside the volume box `[-1, 1]^3`
/// (Z-up) and offsets in world units (rounded to whole voxels of the edited volume).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Edit {
    /// Fill the box with empty space (the paper's removal).
    Remove {
        /// The box to empty.
        region: Aabb,
    },
    /// Copy the box's content to the place `offset` away, over what is there (the paper's
    /// duplicate).
    Duplicate {
        /// The box to copy.
        region: Aabb,
        /// Where the copy goes, relative to the box.
        offset: Vec3,
    },
    /// Empty the box, then put its content `offset` away (the paper's move: a duplicate and a
    /// removal of the source; where source and destination overlap the moved content wins).
    Move {
        /// The box to move.
        region: Aabb,
        /// How far it moves.
        offset: Vec3,
    },
}

/// Writes a vector as `x,y,z`, the CLI's syntax.
fn comma_separated(v: Vec3) -> String {
    format!("{},{},{}", v.x, v.y, v.z)
}

impl fmt::Display for Edit {
    /// The edit in `volgen edit`'s syntax, e.g. `move -0.5,-0.5,-1,0,0,0 by 0.5,0,0`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let corners = |r: &Aabb| format!("{},{}", comma_separated(r.min), comma_separated(r.max));
        match self {
            Self::Remove { region } => write!(f, "remove {}", corners(region)),
            Self::Duplicate { region, offset } => write!(
                f,
                "duplicate {} to {}",
                corners(region),
                comma_separated(*offset)
            ),
            Self::Move { region, offset } => {
                write!(
                    f,
                    "move {} by {}",
                    corners(region),
                    comma_separated(*offset)
                )
            }
        }
    }
}

impl Edit {
    /// The edited box and, for duplicate and move, the offset.
    fn parts(&self) -> (Aabb, Option<Vec3>) {
        match *self {
            Self::Remove { region } => (region, None),
            Self::Duplicate { region, offset } | Self::Move { region, offset } => {
                (region, Some(offset))
            }
        }
    }

    /// Errors, naming the edit, unless its box (and, for duplicate and move, the box moved by
    /// the offset) lies inside the volume box `[-1, 1]^3`. [`Edit::apply`] checks this too;
    /// calling it first lets a caller refuse bad edits before generating anything.
    ///
    /// ```
    /// use glam::Vec3;
    /// use radiance_volume::Aabb;
    /// use singrav::applications::Edit;
    /// let region = Aabb::try_new(Vec3::splat(0.0), Vec3::splat(0.5))?;
    /// assert!(Edit::Duplicate { region, offset: Vec3::new(0.4, 0.0, 0.0) }.validate().is_ok());
    /// let err = Edit::Move { region, offset: Vec3::new(0.6, 0.0, 0.0) }.validate().unwrap_err();
    /// assert!(err.to_string().contains("move 0,0,0,0.5,0.5,0.5 by 0.6,0,0"));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn validate(&self) -> Result<()> {
        self.validate_in(Aabb::CUBE)
    }

    /// [`Edit::validate`] for a volume over `model_box` instead of `[-1, 1]^3` (a scene
    /// generated at another [extent](crate::SinGrav::set_extent): its
    /// [`model_box`](crate::SinGrav::model_box)).
    pub fn validate_in(&self, model_box: Aabb) -> Result<()> {
        let (region, offset) = self.parts();
        check_placement(region, offset, model_box)
            .map_err(|why| invalid(format!("edit `{self}`"), why))
    }

    /// Applies the edit to a raw volume `(1, 4, s, s, s)` over `[-1, 1]^3` (a scene's finest 3D
    /// scale, from [`crate::SinGrav::generate`]), filling removed space with `empty` (raw
    /// density, r, g, b; see [`empty_voxel`]). Voxels outside the edited boxes keep their exact
    /// values.
    ///
    /// Errors, naming the edit, when [`Edit::validate`] does, when the box holds no voxel
    /// centre, or when the offset rounds to no whole voxel.
    ///
    /// ```
    /// use candle_core::{Device, Tensor};
    /// use glam::Vec3;
    /// use radiance_volume::Aabb;
    /// use singrav::applications::Edit;
    /// let raw = Tensor::ones((1, 4, 8, 8, 8), candle_core::DType::F32, &Device::Cpu)?;
    /// let region = Aabb::try_new(Vec3::splat(-1.0), Vec3::splat(0.0))?;
    /// let edited = Edit::Remove { region }.apply(&raw, &[-9.0, 0.0, 0.0, 0.0])?;
    /// let values: Vec<f32> = edited.flatten_all()?.to_vec1()?;
    /// assert_eq!((values[0], values[511]), (-9.0, 1.0)); // voxel (0,0,0) emptied, (7,7,7) kept
    /// let outside = Aabb::try_new(Vec3::splat(0.5), Vec3::splat(1.5))?;
    /// assert!(Edit::Remove { region: outside }.apply(&raw, &[-9.0, 0.0, 0.0, 0.0]).is_err());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn apply(&self, raw: &Tensor, empty: &[f32; 4]) -> Result<Tensor> {
        self.apply_in(raw, Aabb::CUBE, empty)
    }

    /// [`Edit::apply`] to a raw volume over `model_box` (see [`Edit::validate_in`]).
    pub fn apply_in(&self, raw: &Tensor, model_box: Aabb, empty: &[f32; 4]) -> Result<Tensor> {
        let fail = |why: String| invalid(format!("edit `{self}`"), why);
        let volume = raw_volume(raw, model_box).map_err(fail)?;
        self.validate_in(model_box)?;
        let (region, offset) = self.parts();
        let mask = box_mask(&volume, region).map_err(fail)?;
        let Some(offset) = offset else {
            return Ok(volume.fill_masked(&mask, empty)?.tensor().unsqueeze(0)?);
        };
        let shift = voxel_shift(&volume, offset);
        if shift == [0; 3] {
            return Err(fail(format!(
                "the offset moves the box by less than half a voxel ({} wide)",
                volume.grid().voxel_size().x
            )));
        }
        let fill_source = matches!(self, Self::Move { .. }).then_some(empty.as_slice());
        let edited = volume.translate_masked(&mask, shift, fill_source)?;
        Ok(edited.tensor().unsqueeze(0)?)
    }
}

/// A raw volume `(1, 4, D, H, W)` over `model_box` as a radiance volume, or why not (for a
/// message naming the edit or placement).
pub(super) fn raw_volume(
    raw: &Tensor,
    model_box: Aabb,
) -> std::result::Result<RadianceVolume, String> {
    let dims = raw.dims();
    if dims.len() != 5 || dims[0] != 1 || dims[1] != 4 {
        return Err(format!(
            "expected a raw volume (1, 4, D, H, W), got shape {dims:?}"
        ));
    }
    raw.squeeze(0)
        .map_err(|e| e.to_string())
        .and_then(|t| RadianceVolume::new(t, model_box).map_err(|e| e.to_string()))
}

/// The mask of the voxels whose centres `region` holds, or why it cannot be used (it holds
/// none).
pub(super) fn box_mask(
    volume: &RadianceVolume,
    region: Aabb,
) -> std::result::Result<Tensor, String> {
    let mask = volume.box_mask(region).map_err(|e| e.to_string())?;
    let count = mask
        .sum_all()
        .and_then(|m| m.to_scalar::<f32>())
        .map_err(|e| e.to_string())?;
    if count == 0.0 {
        return Err(format!(
            "the box holds no voxel centre of the {:?} grid (voxels are {} wide); make it larger",
            volume.dims().xyz(),
            volume.grid().voxel_size().x
        ));
    }
    Ok(mask)
}

/// An offset in world units as whole voxels `(dz, dy, dx)` of `volume`'s grid, the order
/// [`RadianceVolume::translate_masked`] takes (D runs along z, W along x).
pub(super) fn voxel_shift(volume: &RadianceVolume, offset: Vec3) -> [i64; 3] {
    let cells = (offset / volume.grid().voxel_size()).round();
    [cells.z as i64, cells.y as i64, cells.x as i64]
}

/// Errors unless `region` and, with an offset, `region` moved by it lie inside the volume box
/// `model_box`.
pub(super) fn check_placement(
    region: Aabb,
    offset: Option<Vec3>,
    model_box: Aabb,
) -> std::result::Result<(), String> {
    check_inside("box", region, model_box)?;
    if let Some(offset) = offset {
        let destination = Aabb {
            min: region.min + offset,
            max: region.max + offset,
        };
        check_inside("destination", destination, model_box)?;
    }
    Ok(())
}

/// Errors unless `region` lies inside the volume box `model_box`.
fn check_inside(what: &str, region: Aabb, model_box: Aabb) -> std::result::Result<(), String> {
    if model_box.contains(region.min) && model_box.contains(region.max) {
        Ok(())
    } else if model_box == Aabb::CUBE {
        Err(format!(
            "the {what} {} .. {} must lie inside the volume box [-1, 1]^3",
            region.min, region.max
        ))
    } else {
        Err(format!(
            "the {what} {} .. {} must lie inside the volume box {} .. {}",
            region.min, region.max, model_box.min, model_box.max
        ))
    }
}

/// The raw voxel (density, r, g, b) that edits fill removed space with. As the paper samples a
/// point of "air" in the scene and uses its colour and density, this takes the scene's own
/// emptiest voxel (lowest raw density) of `raw` `(1, 4, s, s, s)`; where even that is denser
/// than [`EMPTY_SIGMA`] after `activation` (a foggy or barely trained scene), the density is
/// lowered to the raw value of [`EMPTY_SIGMA`], so removed space is empty in any case. Staying
/// near the scene's own values (rather than, say, a huge negative density) keeps the edited
/// volume within what the generators saw, which matters when they harmonise it.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use radiance_volume::Activation;
/// let raw = Tensor::new(&[0f32, 2.0, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8], &Device::Cpu)?
///     .reshape((1, 4, 1, 1, 2))?;
/// let act = Activation::default().with_density_scale(25.0).with_density_shift(-4.0);
/// let empty = singrav::applications::empty_voxel(&raw, &act)?;
/// assert_eq!(empty[1..], [0.3, 0.5, 0.7]); // the colour of the emptier voxel
/// assert_eq!(empty[0], act.raw_density(singrav::applications::EMPTY_SIGMA)?);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn empty_voxel(raw: &Tensor, activation: &Activation) -> Result<[f32; 4]> {
    let dims = raw.dims();
    if dims.len() != 5 || dims[0] != 1 || dims[1] != 4 {
        return Err(invalid(
            "raw",
            format!("expected a raw volume (1, 4, D, H, W), got shape {dims:?}"),
        ));
    }
    let channels: Vec<Vec<f32>> = raw.flatten_from(2)?.squeeze(0)?.to_vec2()?;
    if channels.iter().flatten().any(|v| !v.is_finite()) {
        return Err(invalid("raw", "the volume holds NaN or infinite values"));
    }
    let density = &channels[0];
    let emptiest = (0..density.len())
        .min_by(|&a, &b| density[a].total_cmp(&density[b]))
        .ok_or_else(|| invalid("raw", "the volume has no voxel"))?;
    let ceiling = activation.raw_density(EMPTY_SIGMA)?;
    Ok([
        density[emptiest].min(ceiling),
        channels[1][emptiest],
        channels[2][emptiest],
        channels[3][emptiest],
    ])
}
