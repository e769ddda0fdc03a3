//! The agreement checks of single pieces: each runs the form the device runs in training on
//! the device and the CPU kernel on the CPU, from the same inputs and weights, and compares
//! values and gradients.
//!
//! Tolerances are relative to the CPU result's largest value and its L2 norm (see
//! [`Agreement`]): 1e-4 for the renderer and the convolutions, whose sums are reordered on a
//! device; 1e-3 for the generator, the active set's form and the critic, whose BatchNorm
//! statistics and penalty norms divide by sums of many such terms. On the CPU volrender's and patch-gan's own tests hold
//! the renderer and the convolutions to 1e-5.

use std::sync::Arc;

use anyhow::Result;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{
    functional, ActiveSites, ConvConfig, Generator3d, Generator3dConfig, GradientPenalty,
    PatchDiscriminator2d, PatchDiscriminator2dConfig,
};
use rand::SeedableRng;
use serde_json::{json, Map, Value};
use volrender::portable::render_portable;
use volrender::scenes::{make_scene, peer_rays, Scene};
use volrender::{DensityInterpolation, RenderConfig, Sampler};

use super::compare::{gradients_agree, probe_loss, seed_weights, seeded, weights_on, Agreement};
use super::CheckContext;

const KERNEL_TOLERANCE: f64 = 1e-4;
const NETWORK_TOLERANCE: f64 = 1e-3;
/// The networks' gradients, all weights as one vector: the CPU's own two forms of the active
/// set (sparse and dense, the same math to 1e-9 in f64) differ in f32 by up to 2.8e-2 of the
/// largest gradient for some draws of the weights (BatchNorm over half-empty volumes amplifies
/// rounding), 1.3e-5 to 2.6e-5 for others; a wrong form is off by order 1.
const NETWORK_GRADIENT_TOLERANCE: f64 = 5e-2;

/// The `paper` preset's generator, for scales above the first.
fn paper_generator() -> Result<Generator3dConfig> {
    let layers = singrav::TrainConfig::preset("paper")?.pyramid.layers;
    Ok(Generator3dConfig::for_scale(2, layers))
}

/// The renderer: `volrender::portable` on the device against the fused CPU kernel, on the
/// dense and sparse benchmark scenes (32^3), both uniform samplers and post-activated density;
/// colour, depth, opacity and the gradient of a probe loss with respect to the volume.
pub fn render(cx: &CheckContext) -> Result<Map<String, Value>> {
    let rays = peer_rays(4096)?;
    let full = |sampler| {
        RenderConfig::default()
            .with_sampler(sampler)
            .with_depth(true)
            .with_opacity(true)
            .with_background([1.0, 0.5, 0.25])
    };
    let configs = [
        full(Sampler::Uniform { samples: 64 }),
        full(Sampler::UniformLeft { samples: 64 }),
        full(Sampler::Uniform { samples: 64 }).with_density(DensityInterpolation::PostActivated {
            scale: 4.0,
            shift: -1.5,
        }),
    ];
    let mut worst = Agreement::default();
    for scene in [Scene::Dense, Scene::Sparse] {
        let volume = make_scene(scene, 32, 3)?.tensor().to_dtype(DType::F32)?;
        for cfg in &configs {
            let cpu = Var::from_tensor(&volume)?;
            let on_device = Var::from_tensor(&volume.to_device(&cx.device)?)?;
            let reference = volrender::render(cpu.as_tensor(), &rays, cfg)?;
            let ours = render_portable(on_device.as_tensor(), &rays, cfg)?;
            let outputs = |o: &volrender::RenderOutput| -> Vec<Tensor> {
                [Some(&o.rgb), o.depth.as_ref(), o.opacity.as_ref()]
                    .into_iter()
                    .flatten()
                    .cloned()
                    .collect()
            };
            for (a, b) in outputs(&ours).iter().zip(outputs(&reference).iter()) {
                worst = worst.worst(Agreement::of(a, b)?);
            }
            let grad_of = |o: &volrender::RenderOutput, var: &Var| -> Result<Tensor> {
                let out = outputs(o);
                let grads = probe_loss(&out.iter().collect::<Vec<_>>())?.backward()?;
                grads
                    .get(var.as_tensor())
                    .cloned()
                    .ok_or_else(|| anyhow::anyhow!("the renderer gave the volume no gradient"))
            };
            worst = worst.worst(Agreement::of(
                &grad_of(&ours, &on_device)?,
                &grad_of(&reference, &cpu)?,
            )?);
        }
    }
    let mut fields = worst.report(KERNEL_TOLERANCE);
    fields.insert(
        "compared".into(),
        json!("volrender::portable vs the CPU kernel: 4096 rays, 64 samples, 2 scenes, 3 settings, values and volume gradient"),
    );
    Ok(fields)
}

/// Conv3d: candle's conv2d over depth slices (what every device but the CPU runs) against the
/// CPU kernel, stride 1 and 2, forward and both gradients.
pub fn conv3d(cx: &CheckContext) -> Result<Map<String, Value>> {
    let x = seeded(&[2, 8, 14, 13, 12], 1)?;
    let k = seeded(&[16, 8, 3, 3, 3], 2)?;
    let mut worst = Agreement::default();
    for cfg in [
        ConvConfig::default().with_padding(1),
        ConvConfig::default().with_padding(1).with_stride(2),
    ] {
        let (xc, kc) = (Var::from_tensor(&x)?, Var::from_tensor(&k)?);
        let (xd, kd) = (
            Var::from_tensor(&x.to_device(&cx.device)?)?,
            Var::from_tensor(&k.to_device(&cx.device)?)?,
        );
        let reference = functional::conv3d(xc.as_tensor(), kc.as_tensor(), cfg)?;
        let ours = functional::conv3d_by_slices(xd.as_tensor(), kd.as_tensor(), cfg)?;
        worst = worst.worst(Agreement::of(&ours, &reference)?);
        let grads_c = probe_loss(&[&reference])?.backward()?;
        let grads_d = probe_loss(&[&ours])?.backward()?;
        for (c, d) in [(&xc, &xd), (&kc, &kd)] {
            let missing = || anyhow::anyhow!("conv3d gave no gradient");
            worst = worst.worst(Agreement::of(
                grads_d.get(d.as_tensor()).ok_or_else(missing)?,
                grads_c.get(c.as_tensor()).ok_or_else(missing)?,
            )?);
        }
    }
    let mut fields = worst.report(KERNEL_TOLERANCE);
    fields.insert(
        "compared".into(),
        json!("conv2d over depth slices vs the CPU kernel: 8 -> 16 channels, stride 1 and 2, output and both gradients"),
    );
    Ok(fields)
}

/// A network built twice from the same weights: on the CPU, and on the check's device.
struct Twins<N> {
    cpu: N,
    device: N,
    cpu_weights: VarMap,
    device_weights: VarMap,
}

impl<N> Twins<N> {
    fn new(cx: &CheckContext, build: impl Fn(VarBuilder) -> patch_gan::Result<N>) -> Result<Self> {
        let cpu_weights = VarMap::new();
        let cpu = build(VarBuilder::from_varmap(
            &cpu_weights,
            DType::F32,
            &Device::Cpu,
        ))?;
        seed_weights(&cpu_weights, 10)?;
        let device_weights = weights_on(&cpu_weights, &cx.device)?;
        let device = build(VarBuilder::from_varmap(
            &device_weights,
            DType::F32,
            &cx.device,
        ))?;
        Ok(Self {
            cpu,
            device,
            cpu_weights,
            device_weights,
        })
    }

    /// The line's fields for the device's output `ours` against the CPU's `reference`, and
    /// for the gradients of `loss` of each with respect to its side's weights (all weights'
    /// gradients as one vector): the values held to [`NETWORK_TOLERANCE`], the gradients to
    /// [`NETWORK_GRADIENT_TOLERANCE`], each one's errors apart.
    fn report(
        &self,
        ours: &Tensor,
        reference: &Tensor,
        loss: impl Fn(&Tensor) -> Result<Tensor>,
    ) -> Result<Map<String, Value>> {
        let gradients = gradients_agree(
            &self.cpu_weights,
            &loss(reference)?.backward()?,
            &self.device_weights,
            &loss(ours)?.backward()?,
        )?;
        let values = Agreement::of(ours, reference)?;
        let mut fields = Map::new();
        let values_ok = values.passes(NETWORK_TOLERANCE);
        let gradients_ok = gradients.passes(NETWORK_GRADIENT_TOLERANCE);
        fields.insert("ok".into(), json!(values_ok && gradients_ok));
        for (what, agreement, tolerance) in [
            ("values", values, NETWORK_TOLERANCE),
            ("gradients", gradients, NETWORK_GRADIENT_TOLERANCE),
        ] {
            fields.insert(format!("{what}_max_error"), json!(agreement.max_error));
            fields.insert(format!("{what}_l2_error"), json!(agreement.l2_error));
            fields.insert(format!("{what}_tolerance"), json!(tolerance));
        }
        Ok(fields)
    }
}

/// The `paper` preset's generator (7 layers, 32 channels, BatchNorm on batch statistics) at
/// 24^3: one training-mode forward and the gradient of every weight, as the device runs it against the
/// CPU's kernels.
pub fn generator(cx: &CheckContext) -> Result<Map<String, Value>> {
    let config = paper_generator()?;
    let dims = [1, 4, 24, 24, 24];
    let (z, prev) = (seeded(&dims, 3)?, seeded(&dims, 4)?);
    let g = Twins::new(cx, |vb| Generator3d::new(&config, vb))?;
    let reference = g.cpu.forward_residual(&z, &prev, true)?;
    let ours = g.device.forward_residual(
        &z.to_device(&cx.device)?,
        &prev.to_device(&cx.device)?,
        true,
    )?;
    let mut fields = g.report(&ours, &reference, |t| probe_loss(&[t]))?;
    fields.insert(
        "compared".into(),
        json!(device_form(
            cx,
            &format!(
                "Generator3d 24^3, {} layers, {} channels: output and every weight's gradient",
                config.layers, config.channels
            )
        )),
    );
    Ok(fields)
}

/// The finer scales' active set: the dense masked form (what every device but the CPU runs)
/// on the device against the CPU's sparse submanifold form, on a volume with every other
/// 2x2x2 block active.
pub fn active_set(cx: &CheckContext) -> Result<Map<String, Value>> {
    let config = paper_generator()?;
    let n = 20;
    let dims = [1, 4, n, n, n];
    let (z, prev) = (seeded(&dims, 5)?, seeded(&dims, 6)?);
    let active: Vec<bool> = (0..n * n * n)
        .map(|i| {
            let (x, y, zz) = (i % n, (i / n) % n, i / (n * n));
            (x / 2 + y / 2 + zz / 2) % 2 == 0
        })
        .collect();
    let sites = Arc::new(ActiveSites::new(1, [n, n, n], config.kernel, &active)?);
    let g = Twins::new(cx, |vb| Generator3d::new(&config, vb))?;
    let reference = g.cpu.forward_residual_active(&z, &prev, &sites, true)?;
    let ours = g.device.forward_residual_active_dense(
        &z.to_device(&cx.device)?,
        &prev.to_device(&cx.device)?,
        &sites,
        true,
    )?;
    let mut fields = g.report(&ours, &reference, |t| probe_loss(&[t]))?;
    fields.insert(
        "compared".into(),
        json!(format!(
            "the dense masked form vs the CPU's sparse form: 20^3, {} of {} voxels active, \
             output and every weight's gradient",
            sites.len(),
            n * n * n
        )),
    );
    Ok(fields)
}

/// A critic step: the WGAN loss of real and fake renderings plus the gradient penalty (weight
/// 0.1, per pixel) of the default 2D critic (5 layers, 32 channels) at 54^2, batch 2, and every weight's gradient; the
/// device runs candle's double backward where the CPU runs the penalty's first-order form.
pub fn critic(cx: &CheckContext) -> Result<Map<String, Value>> {
    let config = PatchDiscriminator2dConfig::default();
    let dims = [2, 4, 54, 54];
    let (real, fake) = (seeded(&dims, 7)?, seeded(&dims, 8)?);
    let d = Twins::new(cx, |vb| PatchDiscriminator2d::new(&config, vb))?;
    let step = |d: &PatchDiscriminator2d, real: &Tensor, fake: &Tensor| -> Result<Tensor> {
        // The same draw of the mixing factors on both sides.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let penalty = d.gradient_penalty(real, fake, GradientPenalty::default(), &mut rng)?;
        Ok((d.critic_loss(real, fake)? + penalty)?)
    };
    let reference = step(&d.cpu, &real, &fake)?;
    let ours = step(
        &d.device,
        &real.to_device(&cx.device)?,
        &fake.to_device(&cx.device)?,
    )?;
    let mut fields = d.report(&ours, &reference, |t| Ok(t.clone()))?;
    fields.insert("loss_cpu".into(), json!(reference.to_scalar::<f32>()?));
    fields.insert(
        "loss_device".into(),
        json!(ours.to_device(&Device::Cpu)?.to_scalar::<f32>()?),
    );
    fields.insert(
        "compared".into(),
        json!(device_form(
            cx,
            "critic loss + gradient penalty, 5 layers, 32 channels, 2 x 54^2: value and every \
             weight's gradient"
        )),
    );
    Ok(fields)
}

/// What a network check compared: on the CPU both sides run the same kernels, which the line
/// says, so a CPU run is not mistaken for a check of the device forms.
fn device_form(cx: &CheckContext, what: &str) -> String {
    if cx.device.is_cpu() {
        format!("{what} (on the CPU both sides run the CPU kernels)")
    } else {
        format!("{what}, the device's candle ops vs the CPU kernels")
    }
}
