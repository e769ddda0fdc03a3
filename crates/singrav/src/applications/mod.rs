//! The paper's applications on a trained pyramid: editing a scene's finest raw volume
//! ([`Edit`]: removal, duplicate, move), composing objects of several scenes into one
//! ([`Placement`], on a scene or on a scene's [`ground`] alone), harmonising either by re-running
//! the finer generators on it ([`SinGrav::harmonize`]), and animation by a smoothed random walk
//! on the finer scales' noise ([`SinGrav::animation`]).

mod animation;
mod compose;
mod edit;

use candle_core::Tensor;

pub use animation::{Animation, WalkConfig};
pub use compose::{ground, Placement, GROUND_WINDOW};
pub use edit::{empty_voxel, Edit, EMPTY_SIGMA};

use crate::error::{invalid, Result};
use crate::model::SinGrav;

impl SinGrav {
    /// The paper's harmonisation of an edited raw volume `(1, 4, s, s, s)` of the finest 3D scale
    /// (for example one edited with [`Edit::apply`]): the edit is downscaled to the size of scale
    /// `from_scale` and stands in for the upsampled coarser volume that G_{from_scale} refines;
    /// then G_{from_scale} .. G_{N-1} add their detail with fresh noise from `rng`, which blends
    /// the edit into the scene. The paper uses `from_scale = 3`; it must lie between 2 and the
    /// finest 3D scale (G_1 makes a volume from noise and has nothing to refine). Returns the
    /// harmonised raw volume `(1, 4, s, s, s)`.
    pub fn harmonize(
        &self,
        edited: &Tensor,
        from_scale: usize,
        rng: &mut impl rand::Rng,
    ) -> Result<Tensor> {
        let last = self.volume_scales();
        if !(2..=last).contains(&from_scale) {
            return Err(invalid(
                "from_scale",
                format!(
                    "the first re-run generator must be one of G_2 .. G_{last} (this model has \
                     {last} 3D scales), got {from_scale}"
                ),
            ));
        }
        let finest = self.scale_dims(last);
        let expected = [1, 4, finest.d, finest.h, finest.w];
        if edited.dims() != expected {
            return Err(invalid(
                "edited",
                format!(
                    "expected a raw volume of the finest 3D scale, shape {expected:?}, got {:?}",
                    edited.dims()
                ),
            ));
        }
        let noise = self.draw_noise(last, rng)?;
        let mut volume = self.upsample_to_scale(edited, from_scale)?;
        for n in from_scale..=last {
            // At n = from_scale the volume already has scale n's size, so refine's resampling
            // is the identity and G_n sees the downscaled edit itself.
            volume = self.refine(n, &noise[n - 1], &volume)?;
        }
        Ok(volume.detach())
    }
}
