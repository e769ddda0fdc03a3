//! Computing only where a volume needs it: the active sites of a batch of volumes, moving
//! features between volumes and sites, and (in `functional::conv3d_active`) submanifold
//! convolutions on the sites. The sparse path of [`crate::Generator3d`]
//! (`forward_residual_active`) is built from these.

mod gather;
mod sites;

pub use gather::{gather, scatter};
pub use sites::ActiveSites;
pub(crate) use sites::NO_SITE;
