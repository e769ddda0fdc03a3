//! Depth as datasets carry it: the three kinds, the "no surface" markers of real renderers and
//! sensors, and the conversion to the expected depth training compares.

use std::fmt;
use std::str::FromStr;

use volrender::Camera;

/// How a dataset's depth maps measure depth (`depth_kind` in `transforms.json`).
///
/// Training compares *expected* depth, so [`DepthKind::Z`] and [`DepthKind::Distance`] are
/// converted on loading: ray distance (z divided by the cosine between the ray and the camera's
/// viewing axis) times the pixel's opacity, 0 where the opacity is 0.
///
/// ```
/// use rgbd_dataset::DepthKind;
/// let kind: DepthKind = "z".parse()?;
/// assert_eq!(kind, DepthKind::Z);
/// assert_eq!(kind.to_string(), "z");
/// assert!("planar".parse::<DepthKind>().is_err());
/// # Ok::<(), String>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthKind {
    /// The renderer's expected depth `sum_i w_i t_i` along the ray, not divided by opacity (0
    /// where nothing is hit): what volgen writes.
    Expected,
    /// Planar depth: distance along the camera's viewing axis to the surface, as Blender's Z
    /// pass and most RGB-D sensors give it.
    Z,
    /// Ray length from the camera to the surface.
    Distance,
    /// No depth maps (photos posed by structure from motion): frames need no
    /// `depth_file_path`, and training and fitting go without the depth loss.
    None,
}

/// The three kinds explained, for error messages that ask the user to choose.
pub(super) const KINDS_EXPLAINED: &str = "\"expected\" (volgen's own: sum of weights times \
    ray distance, 0 where nothing is hit), \"z\" (planar: distance along the camera's viewing \
    axis, as Blender's Z pass and most RGB-D sensors), \"distance\" (ray length to the surface) or \"none\" \
    (no depth maps: training goes without the depth loss)";

impl DepthKind {
    /// The name as `transforms.json` and `--depth-kind` spell it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Expected => "expected",
            Self::Z => "z",
            Self::Distance => "distance",
            Self::None => "none",
        }
    }
}

impl fmt::Display for DepthKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DepthKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "expected" => Ok(Self::Expected),
            "z" => Ok(Self::Z),
            "distance" => Ok(Self::Distance),
            "none" => Ok(Self::None),
            other => Err(format!(
                "unknown depth kind \"{other}\": expected {KINDS_EXPLAINED}"
            )),
        }
    }
}

/// A pixel is foreground when its opacity is above this: more than half covered, and more than
/// 0.5 by a whole 8-bit step, since an 8-bit PNG stores a renderer's exact 0.5 (one of two
/// samples hit) as 128/255 = 0.502. Measured: a 16 x 16 Cycles view at 2 samples per pixel had
/// 8 pixels of opacity exactly 0.5 and no depth, 15% of its foreground when counted.
pub(super) const FOREGROUND_OPACITY: f32 = 0.5 + 1.0 / 255.0;
/// Above this depth a value marks "no surface" (Blender's Z pass writes 1e10 for background).
const FAR_MARKER: f32 = 1e9;
/// The largest half float: a half EXR's clamped "infinitely far".
const HALF_MAX: f32 = 65504.0;
/// A view whose foreground lacks depth on more than this fraction is refused.
pub(super) const MAX_HOLE_FRACTION: f32 = 0.05;

/// Whether a z or distance value says "no surface": infinite, NaN, >= 1e9, 65504 or 0.
fn no_surface(d: f32) -> bool {
    !d.is_finite() || d >= FAR_MARKER || d == HALF_MAX || d == 0.0
}

/// One frame's depth converted to expected depth.
pub(super) struct Converted {
    /// Expected depth per pixel (0 where left out).
    pub(super) depth: Vec<f32>,
    /// Per pixel 1 when its depth is known, 0 when it is left out of the depth loss; `None`
    /// when every pixel's depth is known.
    pub(super) mask: Option<Vec<f32>>,
    /// Pixels with opacity > 0 whose depth says "no surface" (left out).
    pub(super) left_out: usize,
    /// Of those, the ones in the foreground ([`FOREGROUND_OPACITY`]), and how many pixels are
    /// in the foreground.
    pub(super) foreground_holes: usize,
    pub(super) foreground: usize,
}

/// Converts `raw` depth of `kind` to expected depth using the pixels' `opacity` and, for
/// [`DepthKind::Z`], the camera's ray directions. Errors (as a sentence) on a value no kind
/// allows: non-finite expected depth, or negative depth.
pub(super) fn to_expected(
    kind: DepthKind,
    raw: &[f32],
    opacity: &[f32],
    camera: &Camera,
) -> Result<Converted, String> {
    if let Some((i, bad)) = raw.iter().enumerate().find(|(_, d)| **d < 0.0) {
        return Err(format!("depth must not be negative, pixel {i} holds {bad}"));
    }
    if kind == DepthKind::None {
        // Every pixel left out of the depth loss; nothing to refuse.
        let foreground = opacity.iter().filter(|&&a| a > FOREGROUND_OPACITY).count();
        return Ok(Converted {
            depth: vec![0.0; opacity.len()],
            mask: Some(vec![0.0; opacity.len()]),
            left_out: opacity.iter().filter(|&&a| a > 0.0).count(),
            foreground_holes: 0,
            foreground,
        });
    }
    if kind == DepthKind::Expected {
        if let Some(bad) = raw.iter().find(|d| !d.is_finite()) {
            return Err(format!(
                "expected depth must be finite, found {bad} (is this a \"z\" or \"distance\" map \
                 with its background marked as infinite?)"
            ));
        }
        let foreground = opacity.iter().filter(|&&a| a > FOREGROUND_OPACITY).count();
        return Ok(Converted {
            depth: raw.to_vec(),
            mask: None,
            left_out: 0,
            foreground_holes: 0,
            foreground,
        });
    }
    let width = camera.width;
    let axis = -camera.c2w.z_axis.truncate().normalize();
    let mut depth = vec![0f32; raw.len()];
    let mut mask = vec![1f32; raw.len()];
    let (mut left_out, mut foreground_holes, mut foreground) = (0, 0, 0);
    for (i, (&d, &a)) in raw.iter().zip(opacity).enumerate() {
        foreground += usize::from(a > FOREGROUND_OPACITY);
        if a == 0.0 {
            continue;
        }
        if no_surface(d) {
            mask[i] = 0.0;
            left_out += 1;
            foreground_holes += usize::from(a > FOREGROUND_OPACITY);
            continue;
        }
        let distance = match kind {
            DepthKind::Z => {
                let (row, col) = ((i / width) as f32 + 0.5, (i % width) as f32 + 0.5);
                d / camera.ray(row, col).1.dot(axis)
            }
            _ => d,
        };
        depth[i] = a * distance;
    }
    Ok(Converted {
        depth,
        mask: (left_out > 0).then_some(mask),
        left_out,
        foreground_holes,
        foreground,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_surface_markers() {
        for d in [f32::INFINITY, f32::NAN, 1e10, 1e9, 65504.0, 0.0] {
            assert!(no_surface(d), "{d}");
        }
        for d in [1e-3, 3.5, 65000.0, 9e8] {
            assert!(!no_surface(d), "{d}");
        }
    }
}
