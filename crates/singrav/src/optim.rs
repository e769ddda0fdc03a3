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

    use super::Adam;

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
}
