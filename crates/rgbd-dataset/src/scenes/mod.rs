//! Built-in procedural scenes: analytic density and colour fields with simple baked shading, in
//! the spirit of the paper's natural scenes (many constituents that repeat with variation).
//!
//! A scene is a pure function of the world point and its seed, so a volume of any resolution
//! can be baked from it with [`Scene::to_volume`]. Every scene is a signed distance field with
//! albedo, turned into density by a soft shell (60 per world length inside, 0 beyond 0.03 outside
//! the surface) and lit by one fixed sun plus sky light; content stays within about
//! `z in [-0.7, 0.5]` and 0.85 of the z axis (solid ground fills the box below it), so the
//! paper's hemisphere cameras see all of it.
//!
//! [`SceneKind`] is the one list of them, by name: what `volgen scene`, `volgen demo` and
//! `volgen eval --family` accept and the docs' tests check. A new scene is a module here (its
//! [`Scene`] with a `new(seed)`) and its row in that list.

use std::fmt;
use std::str::FromStr;

use glam::Vec3;
use radiance_volume::{Aabb, GridDims, RadianceVolume};

use crate::error::{invalid, Error};

mod islands;
mod mushrooms;
mod sdf;
mod shade;
mod stones;

pub use islands::Islands;
pub use mushrooms::Mushrooms;
pub use stones::StandingStones;

/// A scene: density (>= 0) and colour at every world point of the box `[-1, 1]^3`.
pub trait Scene: Sync {
    /// Returns the density and the shaded colour at `p`.
    fn eval(&self, p: Vec3) -> (f32, [f32; 3]);

    /// Bakes the scene into a physical volume over `[-1, 1]^3` by evaluating it at cell centres.
    fn to_volume(&self, dims: GridDims) -> radiance_volume::Result<RadianceVolume> {
        RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
            let (sigma, rgb) = self.eval(p);
            out[0] = sigma;
            out[1..4].copy_from_slice(&rgb);
        })
    }
}

/// Defines [`SceneKind`] from its rows: per scene its variant, name, one line about it and its
/// type (built by `new(seed)`).
macro_rules! scene_kinds {
    ($($(#[$doc:meta])* $kind:ident: $name:literal, $about:literal, $scene:ident;)*) => {
        /// The built-in scenes by name, for command lines and configuration files.
        ///
        /// ```
        /// use rgbd_dataset::scenes::SceneKind;
        /// let kind: SceneKind = "mushrooms".parse()?;
        /// assert_eq!(kind, SceneKind::Mushrooms);
        /// let scene = kind.build(3);
        /// assert_eq!(scene.eval(glam::Vec3::new(0.0, 0.0, 0.95)).0, 0.0);
        /// let err = "forest".parse::<SceneKind>().unwrap_err().to_string();
        /// assert!(err.contains("stones, mushrooms, islands"), "{err}");
        /// # Ok::<(), rgbd_dataset::Error>(())
        /// ```
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum SceneKind {
            $($(#[$doc])* $kind,)*
        }

        impl SceneKind {
            /// Every built-in scene, in the order of their names in messages.
            pub const ALL: [Self; [$($name),*].len()] = [$(Self::$kind),*];

            /// The scene's short name (what [`FromStr`] accepts).
            #[must_use]
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$kind => $name,)*
                }
            }

            /// What the scene is, in a few words.
            #[must_use]
            pub fn about(self) -> &'static str {
                match self {
                    $(Self::$kind => $about,)*
                }
            }

            /// Lays out the scene from `seed`.
            #[must_use]
            pub fn build(self, seed: u64) -> Box<dyn Scene> {
                match self {
                    $(Self::$kind => Box::new($scene::new(seed)),)*
                }
            }
        }
    };
}

scene_kinds! {
    /// [`StandingStones`], named `stones`.
    StandingStones: "stones", "a ring of standing stones on a grassy mound", StandingStones;
    /// [`Mushrooms`], named `mushrooms`.
    Mushrooms: "mushrooms", "a field of mushrooms on mossy ground", Mushrooms;
    /// [`Islands`], named `islands`.
    Islands: "islands", "rocky, grassy islands in water", Islands;
}

impl fmt::Display for SceneKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SceneKind {
    type Err = Error;

    fn from_str(name: &str) -> Result<Self, Error> {
        Self::ALL
            .into_iter()
            .find(|kind| kind.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|kind| kind.name()).collect();
                invalid(
                    "scene",
                    format!(
                        "unknown scene `{name}`; the built-in scenes are {}",
                        names.join(", ")
                    ),
                )
            })
    }
}
