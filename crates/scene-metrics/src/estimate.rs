//! How precisely a handful of generated scenes pins a metric down.
//!
//! The sample metrics are averages over randomly generated scenes, so they carry sampling
//! noise: with `volgen eval`'s first default of 8 scenes, the same trained `tiny` run gave
//! floaters from 0.0196 to 0.0268 under six noise seeds (docs/metrics.md). An [`Estimate`]
//! holds a metric's value over all scenes with its standard error over scenes, so a
//! difference between two runs can be read against it.

use crate::error::{invalid, Result};

/// A metric's value over a set of generated scenes and its standard error: the standard
/// deviation of the value over repeated draws of that many scenes, estimated from the scenes
/// themselves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The metric over all scenes.
    pub value: f64,
    /// One standard error over scenes.
    pub stderr: f64,
}

impl Estimate {
    /// The mean of per-scene values (a metric that averages over scenes, such as
    /// [`floaters_per_scene`](super::floaters_per_scene)) and its standard error, the values'
    /// sample standard deviation (n - 1 in the denominator) over `sqrt(n)`. Needs at least
    /// two finite values.
    ///
    /// ```
    /// let e = scene_metrics::Estimate::mean_of(&[1.0, 2.0, 3.0, 6.0])?;
    /// assert_eq!(e.value, 3.0);
    /// // Sample variance (4 + 1 + 0 + 9) / 3 = 14 / 3; over 4 scenes.
    /// assert!((e.stderr - (14.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-15);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn mean_of(values: &[f64]) -> Result<Self> {
        check_values(values, 2)?;
        let n = values.len() as f64;
        let value = super::mean(values);
        let variance = values.iter().map(|v| (v - value).powi(2)).sum::<f64>() / (n - 1.0);
        Ok(Self {
            value,
            stderr: (variance / n).sqrt(),
        })
    }

    /// Any statistic of a set of scenes (such as [`diversity_mv`](super::diversity_mv), a
    /// spread over scenes rather than a mean) with its jackknife standard error:
    /// `sqrt((n - 1) / n * sum_i (s_i - s_mean)^2)`, where `s_i` is the statistic without scene
    /// `i`. For a mean over scenes this is exactly [`Estimate::mean_of`]'s standard error.
    /// Needs `statistic` to accept `n - 1` scenes, and `n >= 3`.
    ///
    /// ```
    /// use scene_metrics::Estimate;
    /// let scenes = [1.0, 2.0, 3.0, 6.0];
    /// let mean = |s: &[f64]| Ok(s.iter().sum::<f64>() / s.len() as f64);
    /// let jackknife = Estimate::jackknife(&scenes, mean)?;
    /// let direct = Estimate::mean_of(&scenes)?;
    /// assert!((jackknife.stderr - direct.stderr).abs() < 1e-12);
    /// assert_eq!(jackknife.value, 3.0);
    /// # Ok::<(), scene_metrics::Error>(())
    /// ```
    pub fn jackknife<T: Clone>(
        scenes: &[T],
        statistic: impl Fn(&[T]) -> Result<f64>,
    ) -> Result<Self> {
        if scenes.len() < 3 {
            return Err(invalid(
                "scenes",
                format!(
                    "a jackknife standard error needs at least 3 scenes, got {}",
                    scenes.len()
                ),
            ));
        }
        let value = statistic(scenes)?;
        let left_out = (0..scenes.len())
            .map(|i| {
                let rest: Vec<T> = scenes
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, scene)| scene.clone())
                    .collect();
                statistic(&rest)
            })
            .collect::<Result<Vec<f64>>>()?;
        check_values(&left_out, 3)?;
        let n = left_out.len() as f64;
        let centre = super::mean(&left_out);
        let squares = left_out.iter().map(|s| (s - centre).powi(2)).sum::<f64>();
        Ok(Self {
            value,
            stderr: ((n - 1.0) / n * squares).sqrt(),
        })
    }
}

/// At least `min` values, all finite.
fn check_values(values: &[f64], min: usize) -> Result<()> {
    if values.len() < min {
        return Err(invalid(
            "values",
            format!(
                "a standard error needs at least {min} values, got {}",
                values.len()
            ),
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(invalid(
            "values",
            format!("value {i} is {}, expected a finite number", values[i]),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_jackknife_of_a_mean_is_the_classical_standard_error() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [3, 5, 32] {
            let values: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..4.0)).collect();
            let mean = |s: &[f64]| Ok(s.iter().sum::<f64>() / s.len() as f64);
            let jackknife = Estimate::jackknife(&values, mean).unwrap();
            let direct = Estimate::mean_of(&values).unwrap();
            assert!((jackknife.value - direct.value).abs() < 1e-12);
            assert!(
                (jackknife.stderr / direct.stderr - 1.0).abs() < 1e-10,
                "{n}: {jackknife:?} vs {direct:?}"
            );
        }
    }

    #[test]
    fn the_standard_error_matches_the_spread_of_repeated_draws() {
        // The spread of the mean of 8 draws from a uniform distribution on [0, 1]
        // (variance 1/12) is sqrt(1 / 96); the estimates average close to it.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let trials = 4000;
        let mut stderr_sum = 0.0;
        for _ in 0..trials {
            let draws: Vec<f64> = (0..8).map(|_| rng.random::<f64>()).collect();
            stderr_sum += Estimate::mean_of(&draws).unwrap().stderr;
        }
        let want = (1.0f64 / 96.0).sqrt();
        // E[s] < sigma (c4(8) = 0.965), so the mean estimate sits a little below.
        let got = stderr_sum / trials as f64;
        assert!((got / (0.965 * want) - 1.0).abs() < 0.02, "{got} vs {want}");
    }

    #[test]
    fn identical_scenes_have_no_error_and_bad_input_is_refused() {
        assert_eq!(Estimate::mean_of(&[0.5, 0.5, 0.5]).unwrap().stderr, 0.0);
        let err = Estimate::mean_of(&[0.5]).unwrap_err().to_string();
        assert!(err.contains("at least 2"), "{err}");
        let err = Estimate::mean_of(&[0.5, f64::NAN]).unwrap_err().to_string();
        assert!(err.contains("value 1 is NaN"), "{err}");
        let two = [1.0, 2.0];
        let err = Estimate::jackknife(&two, |s: &[f64]| Ok(s[0]))
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least 3 scenes"), "{err}");
    }
}
