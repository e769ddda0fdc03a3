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
    pub max_error: f64,
    pub l2_error: f64,
}

impl Agreement {
    /// `device` (any device) against `reference` (the CPU's), which must hold as many values.
    pub fn of(device: &Tensor, reference: &Tensor) -> Result<Self> {
        let (d, r) = (values(device)?, values(reference)?);
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
        let max_diff = d
            .iter()
            .zip(&r)
            .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        let l2_diff = d
            .iter()
            .zip(&r)
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

    /// The line's fields for a comparison held to `tolerance`: `ok`, the errors, the tolerance.
    pub fn report(self, tolerance: f64) -> Map<String, Value> {
        let mut fields = Map::new();
        fields.insert(
            "ok".into(),
            json!(self.max_error <= tolerance && self.l2_error <= tolerance),
        );
        fields.insert("max_error".into(), json!(self.max_error));
        fields.insert("l2_error".into(), json!(self.l2_error));
        fields.insert("tolerance".into(), json!(tolerance));
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

/// The worst agreement of the device's gradients with the CPU's, weight by weight (a weight
/// with a CPU gradient and none on the device is an error).
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
    let mut worst = Agreement::default();
    for (name, var) in source.iter() {
        let Some(reference) = cpu_grads.get(var.as_tensor()) else {
            continue;
        };
        let twin = target
            .get(name)
            .with_context(|| format!("weight `{name}` is missing on the device"))?;
        let grad = device_grads
            .get(twin.as_tensor())
            .with_context(|| format!("the device gave no gradient for `{name}`"))?;
        worst = worst.worst(Agreement::of(grad, reference)?);
    }
    Ok(worst)
}
