//! Adam with inspectable state, so a checkpoint can hold the moments and a resumed run takes
//! exactly the steps an uninterrupted one would (candle-nn's `AdamW` keeps its state private).

use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

use crate::error::Result;

/// Adam (Kingma and Ba) over a fixed, named set of variables, without weight decay.
///
/// ```
/// use candle_core::{Device, Tensor, Var};
/// use singrav::optim::Adam;
/// let x = Var::new(&[1f32, -2.0], &Device::Cpu)?;
/// let mut adam = Adam::new(vec![("x".into(), x.clone())], 0.1, (0.9, 0.999))?;
/// for _ in 0..200 {
///     let loss = x.as_tensor().sqr()?.sum_all()?;
///     adam.step(&loss.backward()?)?;
/// }
/// assert!(x.as_tensor().abs()?.max(0)?.to_scalar::<f32>()? < 0.05);
/// # Ok::<(), singrav::Error>(())
/// ```
#[derive(Debug)]
pub struct Adam {
    params: Vec<(String, Var)>,
    first: Vec<Tensor>,
    second: Vec<Tensor>,
    steps: usize,
    learning_rate: f64,
    betas: (f64, f64),
}

/// Added to the second moment's root, as in PyTorch.
const EPS: f64 = 1e-8;

impl Adam {
    /// An optimiser over `params` (names are used for checkpoints) with zero moments.
    pub fn new(params: Vec<(String, Var)>, learning_rate: f64, betas: (f64, f64)) -> Result<Self> {
        let zeros = || -> Result<Vec<Tensor>> {
            Ok(params
                .iter()
                .map(|(_, v)| v.as_tensor().zeros_like())
                .collect::<candle_core::Result<_>>()?)
        };
        Ok(Self {
            first: zeros()?,
            second: zeros()?,
            params,
            steps: 0,
            learning_rate,
            betas,
        })
    }

    /// One update of every variable that has a gradient in `grads` (the others keep their
    /// values and moments).
    ///
    /// # Errors
    /// [`crate::Error::NonFiniteGradient`] naming the first variable whose gradient holds a NaN
    /// or an infinity; then nothing is updated and the step is not counted.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.check_finite(grads)?;
        self.steps += 1;
        let (b1, b2) = self.betas;
        let t = self.steps as i32;
        let step_size = self.learning_rate / (1.0 - b1.powi(t));
        let second_correction = 1.0 - b2.powi(t);
        for (i, (_, var)) in self.params.iter().enumerate() {
            let Some(grad) = grads.get(var.as_tensor()) else {
                continue;
            };
            // With CANDLE_GRAD_DO_NOT_DETACH (the gradient penalty's on a GPU) gradients keep
            // their backward graph; the moments must not, or every step's graph stays alive.
            let grad = grad.detach();
            let grad = &grad;
            let m = ((&self.first[i] * b1)? + (grad * (1.0 - b1))?)?;
            let v = ((&self.second[i] * b2)? + (grad.sqr()? * (1.0 - b2))?)?;
            let denom = ((&v / second_correction)?.sqrt()? + EPS)?;
            let update = ((&m / &denom)? * step_size)?;
            var.set(&var.as_tensor().sub(&update)?)?;
            self.first[i] = m;
            self.second[i] = v;
        }
        Ok(())
    }

    /// Errors unless every gradient in `grads` is finite (checked through its sum, which is NaN
    /// or infinite if any element is; it may also overflow for huge finite gradients, which
    /// would wreck the step all the same).
    fn check_finite(&self, grads: &GradStore) -> Result<()> {
        for (name, var) in &self.params {
            let Some(grad) = grads.get(var.as_tensor()) else {
                continue;
            };
            let value = grad.detach().sum_all()?.to_scalar::<f32>()?;
            if !value.is_finite() {
                return Err(crate::Error::NonFiniteGradient {
                    parameter: name.clone(),
                    value,
                });
            }
        }
        Ok(())
    }

    /// Sets the learning rate of the steps from now on (a schedule's decay); the moments are
    /// kept.
    pub fn set_learning_rate(&mut self, learning_rate: f64) {
        self.learning_rate = learning_rate;
    }

    /// The number of steps taken.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The state as named tensors (`{prefix}m.{name}`, `{prefix}v.{name}`) plus the step count.
    pub fn state(&self, prefix: &str) -> (HashMap<String, Tensor>, usize) {
        let mut tensors = HashMap::new();
        for (i, (name, _)) in self.params.iter().enumerate() {
            tensors.insert(format!("{prefix}m.{name}"), self.first[i].clone());
            tensors.insert(format!("{prefix}v.{name}"), self.second[i].clone());
        }
        (tensors, self.steps)
    }

    /// Restores the moments saved by [`Adam::state`]; a variable without saved moments (or with
    /// moments of another shape) is an error naming it.
    pub fn restore(
        &mut self,
        tensors: &HashMap<String, Tensor>,
        prefix: &str,
        steps: usize,
    ) -> std::result::Result<(), String> {
        for (i, (name, var)) in self.params.iter().enumerate() {
            for (key, slot) in [("m", &mut self.first[i]), ("v", &mut self.second[i])] {
                let full = format!("{prefix}{key}.{name}");
                *slot = saved_like(tensors, &full, var, "optimiser state")?;
            }
        }
        self.steps = steps;
        Ok(())
    }
}

/// An exponential moving average of a set of variables' values (Polyak averaging, as GANs
/// sample from an average of the generator's weights: StyleGAN's `G_ema`): after every optimiser
/// step, `average = decay * average + (1 - decay) * value`. The average starts at the values it
/// is made from; [`WeightAverage::apply`] writes it into the variables.
///
/// ```
/// use candle_core::{Device, Var};
/// use singrav::optim::WeightAverage;
/// let x = Var::new(&[0f32], &Device::Cpu)?;
/// let mut average = WeightAverage::new(vec![("x".into(), x.clone())], 0.5)?;
/// x.set(&candle_core::Tensor::new(&[4f32], &Device::Cpu)?)?;
/// average.update()?; // 0.5 * 0 + 0.5 * 4
/// average.apply()?;
/// assert_eq!(x.as_tensor().to_vec1::<f32>()?, [2.0]);
/// # Ok::<(), singrav::Error>(())
/// ```
#[derive(Debug)]
pub struct WeightAverage {
    params: Vec<(String, Var)>,
    average: Vec<Tensor>,
    decay: f64,
}

impl WeightAverage {
    /// An average of `params` (names are used for checkpoints) starting at their values, with
    /// the weight `decay` (in [0, 1)) on the past at every update.
    pub fn new(params: Vec<(String, Var)>, decay: f64) -> Result<Self> {
        crate::config::check_fraction("decay", "a weight average's decay", decay)?;
        let average = params
            .iter()
            .map(|(_, v)| v.as_tensor().copy())
            .collect::<candle_core::Result<_>>()?;
        Ok(Self {
            params,
            average,
            decay,
        })
    }

    /// Moves the average towards the variables' current values.
    pub fn update(&mut self) -> Result<()> {
        for ((_, var), average) in self.params.iter().zip(&mut self.average) {
            *average = ((&*average * self.decay)? + (var.as_tensor() * (1.0 - self.decay))?)?;
        }
        Ok(())
    }

    /// Sets every variable to its average.
    pub fn apply(&self) -> Result<()> {
        for ((_, var), average) in self.params.iter().zip(&self.average) {
            var.set(average)?;
        }
        Ok(())
    }

    /// The averages as named tensors (`{prefix}{name}`).
    pub fn state(&self, prefix: &str) -> HashMap<String, Tensor> {
        self.params
            .iter()
            .zip(&self.average)
            .map(|((name, _), average)| (format!("{prefix}{name}"), average.clone()))
            .collect()
    }

    /// Restores the averages saved by [`WeightAverage::state`]; a variable without a saved
    /// average (or with one of another shape) is an error naming it.
    pub fn restore(
        &mut self,
        tensors: &HashMap<String, Tensor>,
        prefix: &str,
    ) -> std::result::Result<(), String> {
        for ((name, var), slot) in self.params.iter().zip(&mut self.average) {
            *slot = saved_like(tensors, &format!("{prefix}{name}"), var, "weight average")?;
        }
        Ok(())
    }
}

/// The saved tensor `name` (a `what` of `var`, for messages), which must have `var`'s shape.
fn saved_like(
    tensors: &HashMap<String, Tensor>,
    name: &str,
    var: &Var,
    what: &str,
) -> std::result::Result<Tensor, String> {
    let saved = tensors
        .get(name)
        .ok_or_else(|| format!("{what} `{name}` is missing"))?;
    if saved.shape() != var.as_tensor().shape() {
        return Err(format!(
            "{what} `{name}` has shape {:?}, the variable {:?}",
            saved.shape(),
            var.as_tensor().shape()
        ));
    }
    Ok(saved.clone())
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::{Adam, WeightAverage};

    #[test]
    fn a_non_finite_gradient_names_the_variable_and_updates_nothing() {
        let a = Var::new(&[1f32, 2.0], &Device::Cpu).unwrap();
        let b = Var::new(&[3f32], &Device::Cpu).unwrap();
        let mut adam = Adam::new(
            vec![("a".into(), a.clone()), ("b".into(), b.clone())],
            0.1,
            (0.9, 0.999),
        )
        .unwrap();
        // d/da = 1 (finite), d/db = 0.5 / sqrt(b - 3) at b = 3: infinite.
        let loss = (a.as_tensor().sum_all().unwrap()
            + (b.as_tensor() - 3.0)
                .unwrap()
                .sqrt()
                .unwrap()
                .sum_all()
                .unwrap())
        .unwrap();
        let err = adam.step(&loss.backward().unwrap()).unwrap_err();
        assert!(
            matches!(&err, crate::Error::NonFiniteGradient { parameter, .. } if parameter == "b"),
            "{err}"
        );
        assert_eq!(adam.steps(), 0);
        assert_eq!(a.as_tensor().to_vec1::<f32>().unwrap(), [1.0, 2.0]);
        assert_eq!(b.as_tensor().to_vec1::<f32>().unwrap(), [3.0]);
    }

    #[test]
    fn the_weight_average_is_the_exponential_average_of_every_updated_value() {
        let x = Var::new(&[1f32, -1.0], &Device::Cpu).unwrap();
        let decay = 0.9;
        let mut average = WeightAverage::new(vec![("x".into(), x.clone())], decay).unwrap();
        let steps = [[2.0f32, 0.5], [-3.0, 4.0], [0.25, 8.0]];
        let mut expected = [1f64, -1.0];
        for values in steps {
            x.set(&candle_core::Tensor::new(&values, &Device::Cpu).unwrap())
                .unwrap();
            average.update().unwrap();
            for (e, v) in expected.iter_mut().zip(values) {
                *e = decay * *e + (1.0 - decay) * v as f64;
            }
        }
        // Until applied, the variable keeps its own value.
        assert_eq!(x.as_tensor().to_vec1::<f32>().unwrap(), [0.25, 8.0]);
        let saved = average.state("avg.");
        average.apply().unwrap();
        let got = x.as_tensor().to_vec1::<f32>().unwrap();
        for (g, e) in got.iter().zip(expected) {
            assert!((*g as f64 - e).abs() < 1e-6, "{g} against {e}");
        }
        // Restored from its state, a fresh average applies the same values.
        let y = Var::new(&[0f32, 0.0], &Device::Cpu).unwrap();
        let mut restored = WeightAverage::new(vec![("x".into(), y.clone())], decay).unwrap();
        restored.restore(&saved, "avg.").unwrap();
        restored.apply().unwrap();
        assert_eq!(y.as_tensor().to_vec1::<f32>().unwrap(), got);
        let missing = restored.restore(&saved, "other.").unwrap_err();
        assert!(missing.contains("other.x"), "{missing}");
        assert!(WeightAverage::new(vec![("x".into(), x)], 1.0).is_err());
    }
}
