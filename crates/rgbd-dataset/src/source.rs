//! Which built-in scene a dataset shows: [`write_built_in`](crate::write_built_in) records it in
//! `transforms.json`, so that the scene's other layouts (its family: what a perfect generator of
//! that kind of scene makes) can later be rendered from the dataset's own cameras.

use std::path::Path;

use serde_json::{json, Value};

use crate::error::{Error, Result};
use crate::scenes::SceneKind;

/// The built-in scene a dataset was rendered from, as `transforms.json` records it:
///
/// ```json
/// "volgen_scene": { "name": "stones", "seed": 0, "grid": 128 }
/// ```
///
/// ```
/// use rgbd_dataset::scenes::SceneKind;
/// use rgbd_dataset::SceneSource;
/// let source = SceneSource { kind: SceneKind::StandingStones, seed: 4, grid: 64 };
/// let seeds: Vec<u64> = source.family_seeds(3).collect();
/// assert_eq!(seeds, [5, 6, 7]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SceneSource {
    /// The scene.
    pub kind: SceneKind,
    /// The seed of its layout ([`SceneKind::build`]).
    pub seed: u64,
    /// The edge of the grid it was baked on before rendering.
    pub grid: usize,
}

/// The `transforms.json` field that holds a [`SceneSource`].
pub(crate) const SOURCE_FIELD: &str = "volgen_scene";

impl SceneSource {
    /// The seeds of `count` other layouts of the scene: the `count` seeds after its own.
    pub fn family_seeds(&self, count: usize) -> impl Iterator<Item = u64> {
        let seed = self.seed;
        (1..=count as u64).map(move |i| seed.wrapping_add(i))
    }

    /// The record written into `transforms.json`.
    pub(crate) fn to_json(self) -> Value {
        json!({ "name": self.kind.name(), "seed": self.seed, "grid": self.grid })
    }

    /// Reads the record of `transforms.json` at `path` (`value` is its `volgen_scene` field).
    pub(crate) fn from_json(value: &Value, path: &Path) -> Result<Self> {
        let error = |why: String| Error::Dataset {
            path: path.to_path_buf(),
            frame: None,
            why: format!("`{SOURCE_FIELD}`: {why}"),
        };
        let field = |name: &str| {
            value
                .get(name)
                .ok_or_else(|| error(format!("missing field `{name}`")))
        };
        let kind = field("name")?
            .as_str()
            .ok_or_else(|| error("`name` must be a string".into()))?
            .parse::<SceneKind>()
            .map_err(|e| error(e.to_string()))?;
        let seed = field("seed")?
            .as_u64()
            .ok_or_else(|| error("`seed` must be a non-negative integer".into()))?;
        let grid = field("grid")?
            .as_u64()
            .filter(|&g| g >= 2)
            .ok_or_else(|| error("`grid` must be an integer of at least 2".into()))?;
        Ok(Self {
            kind,
            seed,
            grid: grid as usize,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_record_reads_back_and_bad_fields_are_named() {
        let source = SceneSource {
            kind: SceneKind::Islands,
            seed: 11,
            grid: 96,
        };
        let path = Path::new("data/transforms.json");
        assert_eq!(
            SceneSource::from_json(&source.to_json(), path).unwrap(),
            source
        );
        for (bad, named) in [
            (json!({"seed": 1, "grid": 8}), "missing field `name`"),
            (
                json!({"name": "forest", "seed": 1, "grid": 8}),
                "unknown scene `forest`",
            ),
            (
                json!({"name": "stones", "seed": -1, "grid": 8}),
                "`seed` must be",
            ),
            (
                json!({"name": "stones", "seed": 1, "grid": 1}),
                "`grid` must be",
            ),
        ] {
            let err = SceneSource::from_json(&bad, path).unwrap_err().to_string();
            assert!(err.contains(named), "{err}");
            assert!(
                err.contains("data/transforms.json") && err.contains(SOURCE_FIELD),
                "{err}"
            );
        }
    }

    #[test]
    fn family_seeds_never_repeat_the_scenes_own() {
        let last = SceneSource {
            kind: SceneKind::StandingStones,
            seed: u64::MAX,
            grid: 8,
        };
        let seeds: Vec<u64> = last.family_seeds(2).collect();
        assert_eq!(seeds, [0, 1]);
    }
}
