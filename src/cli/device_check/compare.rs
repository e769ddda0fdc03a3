//! How close a device's tensors are to the CPU's, and the shared inputs both sides get.

use anyhow::{Context, Result};
use candle_core::{backprop::GradStore, DType, Device, Tensor, Var};
use candle_nn::VarMap;
use rand::{Rng, SeedableRng};
use serde_json::{json, Map, Value};

/// The worst disagreement of a device's results with the CPU's, each measured as volrender's
/// portable tests do: the largest difference of one value relative to the reference's largest
/// magnitude, and the relative L2 error of the whole tensor.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Agreement {
    /// The largest difference of one value, relative to the reference's largest magnitude
    /// (infinite when the device gave a non-finite value).
    pub max_error: f64,
    /// The L2 norm of the difference relative to the reference's.
    pub l2_error: f64,
}

impl Agreement {
    /// `device` (any device) against `reference` (the CPU's), which must hold as many values.
    pub fn of(device: &Tensor, reference: &Tensor) -> Result<Self> {
        Self::of_values(&values(device)?, &values(reference)?)
    }

    /// The same for values already on the host.
    pub fn of_values(d: &[f64], r: &[f64]) -> Result<Self> {
        anyhow::ensure!(
            d.len() == r.len(),
            "the device gave {} values where the CPU gave {}",
            d.len(),
            r.len()
        );
        if d.iter().any(|x| !x.is_finite()) {
            return Ok(Self {
                max_error: f64::INFINITY,
                l2_error: f64::INFINITY,
            });
        }
        let peak = r.iter().fold(0f64, |m, x| m.max(x.abs()));
        let norm = r.iter().map(|x| x * x).sum::<f64>().sqrt();
        let max_diff = d.iter().zip(r).fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        let l2_diff = d
            .iter()
            .zip(r)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        // An all-zero reference is held to absolute differences.
        Ok(Self {
            max_error: if peak > 0.0 {
                max_diff / peak
            } else {
                max_diff
            },
            l2_error: if norm > 0.0 { l2_diff / norm } else { l2_diff },
        })
    }

    /// The worse of two agreements, field by field.
    pub fn worst(self, other: Self) -> Self {
        Self {
            max_error: self.max_error.max(other.max_error),
            l2_error: self.l2_error.max(other.l2_error),
        }
    }

    /// Whether both errors are within `tolerance`.
    pub fn passes(self, tolerance: f64) -> bool {
        self.max_error <= tolerance && self.l2_error <= tolerance
    }

    /// The line's fields for a comparison held to `tolerance`: `ok`, the errors, the tolerance.
    pub fn report(self, tolerance: f64) -> Map<String, Value> {
        let mut fields = Map::new();
        fields.insert("ok".into(), json!(self.passes(tolerance)));
        fields.insert("max_error".into(), json!(self.max_error));
        fields.insert("l2_error".into(), json!(self.l2_error));
        fields.insert("tolerance".into(), json!(tolerance));
        if !self.max_error.is_finite() {
            // JSON has no infinity: the errors print as null, this says why.
            fields.insert("non_finite".into(), json!(true));
        }
        fields
    }
}

/// A tensor's values as f64 on the host.
fn values(t: &Tensor) -> Result<Vec<f64>> {
    Ok(t.to_device(&Device::Cpu)?
        .to_dtype(DType::F64)?
        .flatten_all()?
        .to_vec1()?)
}

/// A tensor of `dims` with values uniform in `[-1, 1)` from the seed (candle's own CPU generator
/// cannot be seeded), on the CPU.
pub fn seeded(dims: &[usize], seed: u64) -> Result<Tensor> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = dims.iter().product();
    let data: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    Ok(Tensor::from_vec(data, dims, &Device::Cpu)?)
}

/// `sum(t * w)` over `tensors` with fixed pseudo-random weights `w` in `[-0.5, 0.5)`, so that
/// every element's gradient is checked (a plain sum would leave cancelling errors unseen).
pub fn probe_loss(tensors: &[&Tensor]) -> Result<Tensor> {
    let mut total: Option<Tensor> = None;
    for (k, t) in tensors.iter().enumerate() {
        let salt = 0.1 + 0.2 * k as f64;
        let w: Vec<f32> = (0..t.elem_count())
            .map(|i| ((i as f64 * 0.618 + salt).fract() - 0.5) as f32)
            .collect();
        let w = Tensor::from_vec(w, t.shape(), t.device())?.to_dtype(t.dtype())?;
        let term = (*t * w)?.sum_all()?;
        total = Some(match total {
            None => term,
            Some(acc) => (acc + term)?,
        });
    }
    total.context("no tensors to weigh")
}

/// Gives the convolutions of `map` weights drawn from `seed` (uniform in `±1 / sqrt(fan_in)`,
/// PyTorch's bound; biases in `±0.05`), leaving BatchNorm's as they start (1 and 0), so a
/// check's numbers repeat from run to run (candle's initialisers cannot be seeded).
pub fn seed_weights(map: &VarMap, seed: u64) -> Result<()> {
    let vars = map.data().lock().expect("the weights' lock");
    let mut names: Vec<&String> = vars.keys().collect();
    names.sort();
    for (k, name) in names.into_iter().enumerate() {
        let var = &vars[name];
        let dims = var.dims().to_vec();
        let bound = if dims.len() >= 2 {
            1.0 / (dims[1..].iter().product::<usize>() as f64).sqrt()
        } else if name.ends_with("conv.bias") || name.starts_with("tail") {
            0.05
        } else {
            continue;
        };
        let unit = seeded(&dims, seed.wrapping_add(k as u64))?;
        var.set(&unit.affine(bound, 0.0)?.to_dtype(var.dtype())?)?;
    }
    Ok(())
}

/// A copy of the CPU's weights on `device`, under the same names, so a network built from it
/// with a `VarBuilder` on `device` has the CPU network's weights.
pub fn weights_on(cpu: &VarMap, device: &Device) -> Result<VarMap> {
    let copy = VarMap::new();
    {
        let source = cpu.data().lock().expect("the CPU weights' lock");
        let mut target = copy.data().lock().expect("the device weights' lock");
        for (name, var) in source.iter() {
            target.insert(
                name.clone(),
                Var::from_tensor(&var.as_tensor().to_device(device)?)?,
            );
        }
    }
    Ok(copy)
}

/// The agreement of the device's gradients with the CPU's, all weights' gradients taken as
/// one vector: a weight the loss barely reaches (a convolution's bias before BatchNorm, whose
/// gradient is zero but for rounding) is held to the network's gradient scale, not to its own
/// rounding noise. A weight with a CPU gradient and none on the device is an error, and so is
/// no gradient at all.
pub fn gradients_agree(
    cpu: &VarMap,
    cpu_grads: &GradStore,
    device: &VarMap,
    device_grads: &GradStore,
) -> Result<Agreement> {
    let (source, target) = (
        cpu.data().lock().expect("the CPU weights' lock"),
        device.data().lock().expect("the device weights' lock"),
    );
    let mut names: Vec<&String> = source.keys().collect();
    names.sort();
    let (mut ours, mut reference) = (Vec::new(), Vec::new());
    for name in names {
        // Weights the loss does not reach at all have no gradient.
        let Some(cpu_grad) = cpu_grads.get(source[name].as_tensor()) else {
            continue;
        };
        let twin = target
            .get(name)
            .with_context(|| format!("weight `{name}` is missing on the device"))?;
        let grad = device_grads
            .get(twin.as_tensor())
            .with_context(|| format!("the device gave no gradient for `{name}`"))?;
        ours.extend(values(grad)?);
        reference.extend(values(cpu_grad)?);
    }
    anyhow::ensure!(!reference.is_empty(), "the CPU gave no weight a gradient");
    Agreement::of_values(&ours, &reference)
}
