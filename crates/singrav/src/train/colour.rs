//! The colour-distribution loss of generated scenes: a sample rendered from a camera
//! should show the colours the real view from that camera shows, in the same proportions.
//!
//! The critics judge colour only through their small receptive fields and learn it slowly;
//! samples of the stones scene kept blue and purple stones on grey-stone views. This term
//! compares the two views' pixel colours as point sets in RGB, by the sliced Wasserstein
//! distance (squared W2 along random directions), which is indifferent to where the colours
//! are, so it constrains colours, not the layout a sample may vary. With a grid
//! (`losses.colour_grid`) the views are compared cell by cell, so colours may move within a
//! cell but not across the view: a scene's colour patches keep their places.
//!
//! In RGB a pixel's brightness spreads far more than its tint (white sky, dark stones), so a
//! random direction mostly sorts the pixels by brightness and a tint of a few stones costs
//! little. The chroma-distribution loss takes the same distance in the plane orthogonal to grey,
//! where the pixels are matched by their tints alone: a purple stone against the real view's
//! grey ones, whatever its brightness.

use candle_core::Tensor;
use swd_loss::{sliced_wasserstein, Metric, Projections};

use crate::error::Result;

/// Random directions in RGB per view and step.
const DIRECTIONS: usize = 16;

/// The mean over views of the squared sliced W2 distance between the pixel colours of
/// `generated` and `real` (both `(V, 3, h, w)`), along directions drawn from `rng`, per cell of
/// a `grid` x `grid` division of each view.
pub(super) fn colour_distribution_loss(
    generated: &Tensor,
    real: &Tensor,
    grid: usize,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Result<Tensor> {
    pixel_distribution_distance(generated, real, grid, || {
        Ok(Projections::random(3, DIRECTIONS, rng, generated.device())?)
    })
}

/// The mean over views of the squared sliced W2 distance between the pixel chroma of
/// `generated` and `real` (both `(V, 3, h, w)` RGB), along directions in the chroma plane drawn
/// from `rng`, per cell of a `grid` x `grid` division of each view.
pub(super) fn chroma_distribution_loss(
    generated: &Tensor,
    real: &Tensor,
    grid: usize,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Result<Tensor> {
    pixel_distribution_distance(&chroma(generated)?, &chroma(real)?, grid, || {
        Ok(Projections::random(2, DIRECTIONS, rng, generated.device())?)
    })
}

/// The chroma `(V, 2, h, w)` of RGB images `(V, 3, h, w)`: their coordinates along the
/// orthonormal basis `(1, -1, 0) / sqrt 2`, `(1, 1, -2) / sqrt 6` of the plane orthogonal to grey
/// `(1, 1, 1)`, so adding a grey to every channel changes nothing and lengths are RGB lengths.
fn chroma(images: &Tensor) -> Result<Tensor> {
    let channel = |c: usize| images.narrow(1, c, 1);
    let (r, g, b) = (channel(0)?, channel(1)?, channel(2)?);
    let red_green = ((&r - &g)? * std::f64::consts::FRAC_1_SQRT_2)?;
    let yellow_blue = (((&r + &g)? - (&b * 2.0)?)? * (1.0 / 6f64.sqrt()))?;
    Ok(Tensor::cat(&[red_green, yellow_blue], 1)?)
}

/// The mean over views, and over the cells of a `grid` x `grid` division of each view, of the
/// squared sliced W2 distance between the pixels of `generated` and `real` (both
/// `(V, C, h, w)`) as point sets in C dimensions, along the directions `directions` gives for
/// each view in turn (every cell of a view shares them). Cell `(i, j)` holds the rows
/// `[i h / grid, (i + 1) h / grid)` and the columns likewise; `grid` is at most `h` and `w`.
fn pixel_distribution_distance(
    generated: &Tensor,
    real: &Tensor,
    grid: usize,
    mut directions: impl FnMut() -> Result<Projections>,
) -> Result<Tensor> {
    let (views, _, height, width) = generated.dims4()?;
    let span = |cell: usize, size: usize| (cell * size / grid, (cell + 1) * size / grid);
    let pixels = |images: &Tensor, v: usize, i: usize, j: usize| -> Result<Tensor> {
        let ((top, bottom), (left, right)) = (span(i, height), span(j, width));
        let cell = images
            .get(v)?
            .narrow(1, top, bottom - top)?
            .narrow(2, left, right - left)?;
        // (C, rows, columns) -> (rows columns, C): one point per pixel.
        Ok(cell.flatten_from(1)?.t()?.contiguous()?)
    };
    let mut per_cell = Vec::with_capacity(views * grid * grid);
    for v in 0..views {
        let along = directions()?;
        for i in 0..grid {
            for j in 0..grid {
                per_cell.push(sliced_wasserstein(
                    &pixels(generated, v, i, j)?,
                    &pixels(real, v, i, j)?,
                    &along,
                    Metric::SquaredW2,
                )?);
            }
        }
    }
    Ok(Tensor::stack(&per_cell, 0)?.mean(0)?)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};
    use rand::SeedableRng;

    use super::{chroma_distribution_loss, colour_distribution_loss};

    /// The directions the losses draw next from `rng` in `dims` dimensions, as the `(dims, K)`
    /// matrix's rows in f64: row c holds component c of every direction.
    fn directions(dims: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<Vec<f64>> {
        swd_loss::Projections::random(dims, super::DIRECTIONS, rng, &Device::Cpu)
            .unwrap()
            .as_tensor()
            .to_dtype(candle_core::DType::F64)
            .unwrap()
            .to_vec2()
            .unwrap()
    }

    #[test]
    fn a_constant_shift_costs_its_squared_length_projected_and_a_permutation_nothing() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let real = Tensor::rand(0f32, 1f32, (2, 3, 4, 5), &Device::Cpu).unwrap();
        // The same pixels in another order: the same colours, another layout.
        let flipped = real.flip(&[2, 3]).unwrap();
        let same = colour_distribution_loss(&flipped, &real, 1, &mut rng).unwrap();
        assert!(same.to_scalar::<f32>().unwrap().abs() < 1e-10);
        // A constant shift s moves every pixel's projection on u by s . u, so each direction
        // costs (s . u)^2: the loss is their mean over the directions drawn.
        let shift = 0.1f32;
        let tinted = (&real + f64::from(shift)).unwrap();
        let mut seeded = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let loss = colour_distribution_loss(&tinted, &real, 1, &mut seeded)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let mut again = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut expected = 0.0f64;
        for _ in 0..2 {
            let p = swd_loss::Projections::random(3, super::DIRECTIONS, &mut again, &Device::Cpu)
                .unwrap();
            // Column k of the (3, K) matrix is direction u_k; s . u_k = shift * sum_c u_k[c].
            let component_sums: Vec<f64> = p.as_tensor().sum(0).unwrap().to_vec1().unwrap();
            for sum in component_sums {
                let along = sum * f64::from(shift);
                expected += along * along;
            }
        }
        expected /= 2.0 * super::DIRECTIONS as f64;
        assert!(
            (f64::from(loss) - expected).abs() < 1e-5,
            "{loss} against {expected}"
        );
    }

    #[test]
    fn a_grid_charges_colours_that_changed_sides_and_keeps_what_stays_in_its_cell() {
        // One 2 x 4 view: its left half colour a, its right half colour b; the sample has them
        // the other way round.
        let (a, b) = ([0.2f32, 0.6, 0.1], [0.5f32, 0.4, 0.3]);
        let view = |left: [f32; 3], right: [f32; 3]| {
            let mut values = Vec::with_capacity(24);
            for c in 0..3 {
                for _row in 0..2 {
                    values.extend([left[c], left[c], right[c], right[c]]);
                }
            }
            Tensor::from_vec(values, (1, 3, 2, 4), &Device::Cpu).unwrap()
        };
        let (real, swapped) = (view(a, b), view(b, a));
        let loss = |generated: &Tensor, grid: usize| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
            colour_distribution_loss(generated, &real, grid, &mut rng)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        // The whole view holds the same colours either way.
        assert!(loss(&swapped, 1).abs() < 1e-10);
        // Each of the four 1 x 2 cells holds b where the real one holds a (or the reverse): each
        // direction u costs ((a - b) . u)^2 in every cell.
        let mut again = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let u = directions(3, &mut again);
        // Row c of the (3, K) matrix holds component c of every direction.
        let difference: Vec<f64> = (0..3).map(|c| f64::from(a[c] - b[c])).collect();
        let mut expected = 0.0f64;
        for ((u0, u1), u2) in u[0].iter().zip(&u[1]).zip(&u[2]) {
            let along = difference[0] * u0 + difference[1] * u1 + difference[2] * u2;
            expected += along * along;
        }
        expected /= super::DIRECTIONS as f64;
        assert!(expected > 1e-3);
        let gridded = f64::from(loss(&swapped, 2));
        assert!(
            (gridded - expected).abs() < 1e-5 * (1.0 + expected),
            "{gridded} against {expected}"
        );
        // Pixels moved within their cells cost nothing; moved across cells, they do.
        let noise = Tensor::rand(0f32, 1f32, (1, 3, 4, 4), &Device::Cpu).unwrap();
        let columns = |order: [u32; 4]| {
            let order = Tensor::new(&order, &Device::Cpu).unwrap();
            noise.index_select(&order, 3).unwrap()
        };
        let against_noise = |generated: &Tensor| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
            colour_distribution_loss(generated, &noise, 2, &mut rng)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        assert!(against_noise(&columns([1, 0, 3, 2])).abs() < 1e-10);
        assert!(against_noise(&columns([3, 2, 1, 0])) > 1e-4);
    }

    #[test]
    fn chroma_ignores_grey_and_a_tint_costs_its_chroma_length_projected() {
        let real = Tensor::rand(0f32, 1f32, (2, 3, 4, 5), &Device::Cpu).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // A grey added to every channel is brightness only.
        let brighter = (&real + 0.2).unwrap();
        let loss = chroma_distribution_loss(&brighter, &real, 1, &mut rng).unwrap();
        assert!(loss.to_scalar::<f32>().unwrap().abs() < 1e-10);
        // A tint t = (0.1, 0, 0.1): chroma coordinates (0.1 / sqrt 2, -0.1 / sqrt 6) (hand
        // projected on the basis), so each direction u costs (c . u)^2.
        let tint = Tensor::new(&[0.1f32, 0.0, 0.1], &Device::Cpu)
            .unwrap()
            .reshape((1, 3, 1, 1))
            .unwrap();
        let tinted = real.broadcast_add(&tint).unwrap();
        let mut seeded = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let loss = chroma_distribution_loss(&tinted, &real, 1, &mut seeded)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        let c = [0.1 / 2f64.sqrt(), -0.1 / 6f64.sqrt()];
        let mut again = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut expected = 0.0f64;
        for _ in 0..2 {
            let u = directions(2, &mut again);
            for (u0, u1) in u[0].iter().zip(&u[1]) {
                let along = c[0] * u0 + c[1] * u1;
                expected += along * along;
            }
        }
        expected /= 2.0 * super::DIRECTIONS as f64;
        assert!(expected > 1e-3);
        assert!(
            (f64::from(loss) - expected).abs() < 1e-5 * (1.0 + expected),
            "{loss} against {expected}"
        );
    }
}
