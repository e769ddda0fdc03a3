//! `--extent X,Y,Z` and `--csg-outside RULE` on the commands that generate scenes (`sample`,
//! `animate`, `edit`): scenes that many times the learned box along x, y and z.

use anyhow::{Context, Result};
use csg_embed::Outside;
use singrav::extent::Extent;
use singrav::SinGrav;

/// The size of the generated scenes.
#[derive(Debug, Clone, clap::Args)]
pub struct ExtentArgs {
    /// Generate scenes X,Y,Z times the learned box along x, y and z (e.g. 2,1,1: twice as wide;
    /// factors from 0.25 to 16), the box growing about its centre. Volumes, VDB, EXR slices and
    /// meshes cover the larger box; views are taken from farther away, at the learned pixel
    /// size. The reconstruction V* and --vary-from above 1 keep the learned size.
    #[arg(long, value_name = "X,Y,Z", default_value = "1,1,1")]
    extent: Extent,
    /// With --extent, what the coarsest generator's position anchors (the CSG grid) hold beyond
    /// the learned box: `mirror` (the learned box repeated, mirrored at its borders), `clamp`
    /// (the border's anchors) or `extend` (coordinates it never saw). docs/applications.md
    /// compares them.
    #[arg(long, value_name = "RULE", default_value_t = Outside::default())]
    csg_outside: Outside,
}

impl ExtentArgs {
    /// Sets the model's extent; refuses a generation that needs V*'s learned size.
    pub fn apply(&self, model: &mut SinGrav) -> Result<()> {
        model
            .set_extent(self.extent, self.csg_outside)
            .context("--extent")
    }

    /// Whether scenes keep the learned size.
    pub fn is_learned_size(&self) -> bool {
        self.extent.is_one()
    }
}
