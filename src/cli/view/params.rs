//! The scene a request asks for: its query parameters checked against what the source can
//! draw, before any work, each refusal one line that names the parameter and what it expects
//! (the server answers it with 400).

use csg_embed::Outside;
use singrav::extent::Extent;

/// The largest extent factor the viewer draws: `volgen sample` takes up to
/// [`Extent::MAX_FACTOR`], but a browser holds the whole volume as one 3D texture.
pub const MAX_VIEW_FACTOR: f64 = 4.0;

/// The most voxels a drawn scene's finest grid may have (a 256^3 grid; its texture is 256 MiB
/// of 32-bit floats).
pub const MAX_VOXELS: usize = 1 << 24;

/// The last frame of the noise walk a request may ask for: reaching frame t costs t steps of
/// every moving scale's noise.
pub const MAX_WALK: usize = 120;

/// One scene the viewer shows: drawn by the model, or one of the volume files.
#[derive(Debug, Clone, PartialEq)]
pub enum SceneKey {
    /// A scene of a trained model: `volgen sample --seed S --count 1 --vary-from V --extent E`
    /// draws it, and at walk frame `walk > 0` `volgen animate --seed S --vary-from V` writes it
    /// as frame `walk`.
    Drawn {
        seed: u64,
        vary: usize,
        walk: usize,
        extent: Extent,
        /// [`Outside::default`] at the learned size, where it changes nothing (so equal scenes
        /// have equal keys).
        outside: Outside,
    },
    /// The volume file with this index in the source's listing.
    File { index: usize },
}

impl SceneKey {
    /// The name of the scene's downloads (without extension), saying what a user needs to draw
    /// it again: `scene_seed7`, `scene_seed7_vary2_walk3_extent2x1x1_clamp`; a file's stem for
    /// files.
    pub fn stem(&self, file_stems: &[String]) -> String {
        match self {
            SceneKey::File { index } => file_stems[*index].clone(),
            SceneKey::Drawn {
                seed,
                vary,
                walk,
                extent,
                outside,
            } => {
                let mut stem = format!("scene_seed{seed}");
                if *vary > 1 {
                    stem += &format!("_vary{vary}");
                }
                if *walk > 0 {
                    stem += &format!("_walk{walk}");
                }
                if !extent.is_one() {
                    let [x, y, z] = extent.factors();
                    stem += &format!("_extent{x}x{y}x{z}_{outside}");
                }
                stem
            }
        }
    }
}

/// What the source can draw, as the request checks need it (shared with the server's threads,
/// while the model itself stays on the generator's).
#[derive(Debug, Clone, PartialEq)]
pub enum Limits {
    /// A trained model with `scales` 3D scales whose finest grid is `finest`^3 voxels; the
    /// noise walk needs at least two 3D scales (its first moving scale is 2).
    Model { scales: usize, finest: usize },
    /// `count` volume files.
    Files { count: usize },
}

/// Reads a request's query parameters (`seed`, `vary`, `walk`, `extent`, `outside` for a
/// model; `file` for files) into the scene they ask for. Missing parameters take the
/// defaults (`seed` 0, `vary` 1, `walk` 0, `extent` 1,1,1, `outside` mirror, `file` 0).
pub fn scene_key(query: &[(String, String)], limits: &Limits) -> Result<SceneKey, String> {
    let known: &[&str] = match limits {
        Limits::Model { .. } => &["seed", "vary", "walk", "extent", "outside"],
        Limits::Files { .. } => &["file"],
    };
    for (i, (name, _)) in query.iter().enumerate() {
        if !known.contains(&name.as_str()) {
            return Err(format!(
                "unknown parameter `{name}`: expected {}",
                known.join(", ")
            ));
        }
        if query[..i].iter().any(|(earlier, _)| earlier == name) {
            return Err(format!("parameter `{name}` is given twice"));
        }
    }
    let value = |name: &str| {
        query
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    };
    match *limits {
        Limits::Files { count } => {
            let index = whole(value("file"), "file", 0)?;
            if index >= count {
                return Err(format!(
                    "file: expected a scene from 0 to {}, got {index}",
                    count - 1
                ));
            }
            Ok(SceneKey::File { index })
        }
        Limits::Model { scales, finest } => {
            let seed = match value("seed") {
                None => 0,
                Some(text) => text.parse::<u64>().map_err(|_| {
                    format!(
                        "seed: expected a whole number from 0 to {}, got {text:?}",
                        u64::MAX
                    )
                })?,
            };
            let vary = whole(value("vary"), "vary", 1)?;
            if !(1..=scales).contains(&vary) {
                return Err(format!(
                    "vary: expected a 3D scale from 1 to {scales} (1: everything varies), got {vary}"
                ));
            }
            let walk = whole(value("walk"), "walk", 0)?;
            if walk > MAX_WALK {
                return Err(format!(
                    "walk: expected a frame of the noise walk from 0 to {MAX_WALK}, got {walk}"
                ));
            }
            if walk > 0 && scales < 2 {
                return Err(
                    "walk: the noise walk moves the scales from 2 on, and this model has one 3D \
                     scale"
                        .into(),
                );
            }
            let extent = extent(value("extent"), finest)?;
            if vary > 1 && !extent.is_one() {
                return Err(format!(
                    "vary: scenes at extent {extent} vary from scale 1 (V*'s layout has the \
                     learned size), got {vary}"
                ));
            }
            let outside = match value("outside") {
                None => Outside::default(),
                Some(text) => text
                    .parse::<Outside>()
                    .map_err(|e| format!("outside: {e}"))?,
            };
            let outside = if extent.is_one() {
                Outside::default()
            } else {
                outside
            };
            Ok(SceneKey::Drawn {
                seed,
                vary,
                walk,
                extent,
                outside,
            })
        }
    }
}

/// A whole number parameter `name` (absent: `default`).
fn whole(text: Option<&str>, name: &str, default: usize) -> Result<usize, String> {
    match text {
        None => Ok(default),
        Some(text) => text
            .parse::<usize>()
            .map_err(|_| format!("{name}: expected a whole number, got {text:?}")),
    }
}

/// The `extent` parameter: `volgen sample --extent`'s `X,Y,Z`, within the viewer's bounds for
/// a model whose finest grid is `finest`^3.
fn extent(text: Option<&str>, finest: usize) -> Result<Extent, String> {
    let Some(text) = text else {
        return Ok(Extent::ONE);
    };
    let extent: Extent = text.parse().map_err(|e| format!("extent: {e}"))?;
    if extent.factors().iter().any(|f| *f > MAX_VIEW_FACTOR) {
        return Err(format!(
            "extent: the viewer draws scenes up to {MAX_VIEW_FACTOR} times the learned box along \
             each axis (volgen sample takes up to {}), got {extent}",
            Extent::MAX_FACTOR
        ));
    }
    let dims = extent.dims(finest);
    if dims.voxel_count() > MAX_VOXELS {
        return Err(format!(
            "extent: {extent} makes a {} x {} x {} grid ({} voxels); the viewer draws at most {}",
            dims.w,
            dims.h,
            dims.d,
            dims.voxel_count(),
            MAX_VOXELS
        ));
    }
    Ok(extent)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MODEL: Limits = Limits::Model {
        scales: 3,
        finest: 28,
    };

    fn query(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    fn refusal(pairs: &[(&str, &str)], limits: &Limits) -> String {
        let err = scene_key(&query(pairs), limits).unwrap_err();
        assert!(!err.contains('\n'), "one line: {err}");
        err
    }

    #[test]
    fn defaults_are_scene_zero_of_the_learned_size() {
        assert_eq!(
            scene_key(&[], &MODEL).unwrap(),
            SceneKey::Drawn {
                seed: 0,
                vary: 1,
                walk: 0,
                extent: Extent::ONE,
                outside: Outside::default()
            }
        );
        assert_eq!(
            scene_key(&[], &Limits::Files { count: 2 }).unwrap(),
            SceneKey::File { index: 0 }
        );
    }

    #[test]
    fn bad_values_name_the_parameter_and_the_expectation() {
        assert!(refusal(&[("seed", "abc")], &MODEL).starts_with("seed: expected a whole number"));
        assert!(refusal(&[("seed", "-1")], &MODEL).starts_with("seed:"));
        let vary = refusal(&[("vary", "4")], &MODEL);
        assert!(
            vary.contains("from 1 to 3") && vary.contains("got 4"),
            "{vary}"
        );
        assert!(refusal(&[("vary", "0")], &MODEL).starts_with("vary:"));
        let zero = refusal(&[("extent", "0,1,1")], &MODEL);
        assert!(
            zero.starts_with("extent:") && zero.contains("0.25"),
            "{zero}"
        );
        assert!(refusal(&[("extent", "8,1,1")], &MODEL).contains("up to 4"));
        assert!(refusal(&[("extent", "2,1")], &MODEL).starts_with("extent:"));
        assert!(refusal(&[("walk", "121")], &MODEL).starts_with("walk:"));
        assert!(
            refusal(&[("outside", "wrap"), ("extent", "2,1,1")], &MODEL).starts_with("outside:")
        );
        assert!(refusal(&[("vary", "2"), ("extent", "2,1,1")], &MODEL).starts_with("vary:"));
        assert!(refusal(&[("colour", "red")], &MODEL).starts_with("unknown parameter `colour`"));
        assert!(refusal(&[("seed", "1"), ("seed", "2")], &MODEL).contains("twice"));
        assert!(refusal(&[("seed", "1")], &Limits::Files { count: 2 }).contains("`seed`"));
        assert!(refusal(&[("file", "2")], &Limits::Files { count: 2 }).contains("0 to 1"));
        let one_scale = Limits::Model {
            scales: 1,
            finest: 16,
        };
        assert!(refusal(&[("walk", "1")], &one_scale).starts_with("walk:"));
    }

    #[test]
    fn the_voxel_bound_holds_for_large_models() {
        let paper = Limits::Model {
            scales: 5,
            finest: 126,
        };
        // 4 x 4 x 1 of 126^3 is 32 million voxels.
        assert!(refusal(&[("extent", "4,4,1")], &paper).contains("at most"));
        assert!(scene_key(&query(&[("extent", "2,1,1")]), &paper).is_ok());
    }

    #[test]
    fn outside_only_matters_beyond_the_learned_size() {
        let key = |pairs| scene_key(&query(pairs), &MODEL).unwrap();
        assert_eq!(key(&[("outside", "clamp")]), key(&[]));
        assert_ne!(
            key(&[("outside", "clamp"), ("extent", "2,1,1")]),
            key(&[("extent", "2,1,1")])
        );
    }

    #[test]
    fn stems_say_how_to_draw_the_scene_again() {
        let key = |pairs| scene_key(&query(pairs), &MODEL).unwrap();
        assert_eq!(key(&[("seed", "7")]).stem(&[]), "scene_seed7");
        assert_eq!(
            key(&[("seed", "7"), ("vary", "2"), ("walk", "3")]).stem(&[]),
            "scene_seed7_vary2_walk3"
        );
        assert_eq!(
            key(&[("extent", "2,1,0.5"), ("outside", "clamp")]).stem(&[]),
            "scene_seed0_extent2x1x0.5_clamp"
        );
        assert_eq!(
            SceneKey::File { index: 1 }.stem(&["a".into(), "b".into()]),
            "b"
        );
    }
}
