//! The CSG grid over a box larger than the learned one: a scene generated wider or deeper than
//! the scene a model learned from. Inside `[-1, 1]` on every axis the grid is
//! [`csg_grid_3d`](crate::csg_grid_3d)'s; what the anchors hold beyond it is a choice
//! ([`Outside`]), since a generator never saw coordinates there.

use std::fmt;
use std::str::FromStr;

use candle_core::{Device, Tensor};

use crate::error::{invalid, Result};
use crate::grid::csg_coordinate;

/// What the CSG anchors hold outside the learned box `[-1, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Outside {
    /// The coordinates go on: `x = 1.5` is 1.5, values no generator saw in training.
    Extend,
    /// The coordinates stop at the border: everything beyond it is anchored as the border
    /// itself is.
    Clamp,
    /// The learned box repeats, mirrored at each border (`x = 1.5` is anchored as 0.5), so the
    /// anchors are continuous across the borders and every value was seen in training.
    #[default]
    Mirror,
}

impl Outside {
    /// The names [`FromStr`] takes and [`fmt::Display`] writes, in declaration order.
    pub const NAMES: [&'static str; 3] = ["extend", "clamp", "mirror"];

    /// Where a coordinate `c` of the larger box is anchored.
    ///
    /// ```
    /// use csg_embed::Outside;
    /// assert_eq!(Outside::Extend.anchor(1.5), 1.5);
    /// assert_eq!(Outside::Clamp.anchor(1.5), 1.0);
    /// assert_eq!(Outside::Mirror.anchor(1.5), 0.5);
    /// assert_eq!(Outside::Mirror.anchor(-3.5), 0.5);
    /// assert_eq!(Outside::Mirror.anchor(0.25), 0.25);
    /// ```
    #[must_use]
    pub fn anchor(self, c: f64) -> f64 {
        match self {
            Self::Extend => c,
            Self::Clamp => c.clamp(-1.0, 1.0),
            // A triangle wave of period 4 through (-1, -1) and (1, 1).
            Self::Mirror => {
                let t = (c + 1.0).rem_euclid(4.0);
                if t > 2.0 {
                    3.0 - t
                } else {
                    t - 1.0
                }
            }
        }
    }
}

impl fmt::Display for Outside {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let i = match self {
            Self::Extend => 0,
            Self::Clamp => 1,
            Self::Mirror => 2,
        };
        f.write_str(Self::NAMES[i])
    }
}

impl FromStr for Outside {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "extend" => Ok(Self::Extend),
            "clamp" => Ok(Self::Clamp),
            "mirror" => Ok(Self::Mirror),
            _ => Err(format!(
                "expected one of {}, got \"{s}\"",
                Self::NAMES.join(", ")
            )),
        }
    }
}

/// The CSG grid `(3, D, H, W)` of a grid whose cells cover `[-hx, hx] x [-hy, hy] x [-hz, hz]`
/// (`half = [hx, hy, hz]`, the learned box is 1): each voxel centre's coordinate, anchored by
/// `outside` where it lies beyond `[-1, 1]`. With `half` all 1 it is
/// [`csg_grid_3d`](crate::csg_grid_3d) bit for bit, whatever `outside`.
///
/// ```
/// use csg_embed::{csg_grid_3d_over, Outside};
/// let dev = candle_core::Device::Cpu;
/// // Twice as wide: 8 cells over [-2, 2] along x, centres -1.75 .. 1.75.
/// let g = csg_grid_3d_over((1, 1, 8), [2.0, 1.0, 1.0], Outside::Mirror, &dev)?;
/// let x: Vec<f32> = g.get(0)?.flatten_all()?.to_vec1()?;
/// assert_eq!(x, [-0.25, -0.75, -0.75, -0.25, 0.25, 0.75, 0.75, 0.25]);
/// # Ok::<(), csg_embed::Error>(())
/// ```
pub fn csg_grid_3d_over(
    (d, h, w): (usize, usize, usize),
    half: [f64; 3],
    outside: Outside,
    device: &Device,
) -> Result<Tensor> {
    if half.iter().any(|&e| !(e.is_finite() && e > 0.0)) {
        return Err(invalid(
            "half extent",
            format!("expected finite half sides > 0, got {half:?}"),
        ));
    }
    let axis = |n: usize, what: &'static str, half: f64| -> Result<Tensor> {
        if n == 0 {
            return Err(invalid(what, "a grid axis needs at least one cell"));
        }
        let values: Vec<f32> = (0..n)
            .map(|i| {
                let c = csg_coordinate(i, n);
                // Inside the learned box the product would round again; keep its exact value.
                if half == 1.0 {
                    c as f32
                } else {
                    outside.anchor(half * c) as f32
                }
            })
            .collect();
        Ok(Tensor::from_vec(values, n, device)?)
    };
    let shape = (d, h, w);
    let x = axis(w, "width", half[0])?.reshape((1, 1, w))?;
    let y = axis(h, "height", half[1])?.reshape((1, h, 1))?;
    let z = axis(d, "depth", half[2])?.reshape((d, 1, 1))?;
    Ok(Tensor::stack(
        &[
            x.broadcast_as(shape)?,
            y.broadcast_as(shape)?,
            z.broadcast_as(shape)?,
        ],
        0,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csg_grid_3d;

    #[test]
    fn the_learned_box_is_the_plain_grid() {
        let plain = csg_grid_3d(3, 4, 5, &Device::Cpu).unwrap();
        for outside in [Outside::Extend, Outside::Clamp, Outside::Mirror] {
            let over = csg_grid_3d_over((3, 4, 5), [1.0; 3], outside, &Device::Cpu).unwrap();
            let (a, b): (Vec<f32>, Vec<f32>) = (
                plain.flatten_all().unwrap().to_vec1().unwrap(),
                over.flatten_all().unwrap().to_vec1().unwrap(),
            );
            assert_eq!(a, b, "{outside}");
        }
    }

    /// The larger box's voxel centres by hand: 12 cells over [-3, 3] (half side 3) are at
    /// -2.75, -2.25, ..., 2.75.
    #[test]
    fn anchors_beyond_the_box_follow_the_rule() {
        let n = 12;
        let grid = |outside| {
            let g = csg_grid_3d_over((1, 1, n), [3.0, 1.0, 1.0], outside, &Device::Cpu).unwrap();
            g.get(0)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
        };
        let centres: Vec<f64> = (0..n).map(|i| -2.75 + 0.5 * i as f64).collect();
        let extend = grid(Outside::Extend);
        let clamp = grid(Outside::Clamp);
        let mirror = grid(Outside::Mirror);
        for (i, &c) in centres.iter().enumerate() {
            assert_eq!(f64::from(extend[i]), c);
            assert_eq!(f64::from(clamp[i]), c.clamp(-1.0, 1.0));
            // Mirrored at +-1, then at +-3: -2.75 -> 0.75, -1.25 -> -0.75, 2.25 -> -0.25.
            let folded = if c > 1.0 {
                2.0 - c
            } else if c < -1.0 {
                -2.0 - c
            } else {
                c
            };
            assert_eq!(f64::from(mirror[i]), folded, "centre {c}");
        }
        // Every mirrored anchor is one the learned box has.
        assert!(mirror.iter().all(|v| v.abs() <= 1.0));
    }

    #[test]
    fn mirror_is_continuous_and_periodic() {
        for i in -400..400 {
            let c = f64::from(i) * 0.01;
            let (a, b) = (Outside::Mirror.anchor(c), Outside::Mirror.anchor(c + 0.01));
            assert!((a - b).abs() <= 0.01 + 1e-12, "jump at {c}");
            assert!((Outside::Mirror.anchor(c + 4.0) - a).abs() < 1e-12);
        }
    }

    #[test]
    fn names_round_trip_and_bad_ones_are_refused() {
        for name in Outside::NAMES {
            assert_eq!(name.parse::<Outside>().unwrap().to_string(), name);
        }
        let err = "tile".parse::<Outside>().unwrap_err();
        assert!(err.contains("extend, clamp, mirror") && err.contains("tile"));
        assert!(
            csg_grid_3d_over((1, 1, 1), [0.0, 1.0, 1.0], Outside::Clamp, &Device::Cpu).is_err()
        );
        assert!(csg_grid_3d_over((1, 0, 1), [1.0; 3], Outside::Clamp, &Device::Cpu).is_err());
    }
}
