//! Conv3d against a direct float64 sum, and its gradients against finite differences.

// Loading weights by memory map is `unsafe` (the file must not change meanwhile).
#![allow(unsafe_code)]

use candle_core::{DType, Device, Module, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use patch_gan::{conv3d, functional, Conv3d, ConvConfig};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Random values in [-1, 1) from a fixed seed.
fn random(len: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
}

struct Case {
    n: usize,
    c_in: usize,
    c_out: usize,
    dhw: [usize; 3],
    k: usize,
    cfg: ConvConfig,
}

impl Case {
    fn out(&self) -> [usize; 3] {
        self.dhw
            .map(|s| (s + 2 * self.cfg.padding - self.k) / self.cfg.stride + 1)
    }

    fn x_len(&self) -> usize {
        self.n * self.c_in * self.dhw.iter().product::<usize>()
    }

    fn w_len(&self) -> usize {
        self.c_out * self.c_in * self.k.pow(3)
    }

    fn tensors(&self, x: &[f64], w: &[f64]) -> (Tensor, Tensor) {
        let [d, h, wd] = self.dhw;
        let k = self.k;
        (
            Tensor::from_slice(x, (self.n, self.c_in, d, h, wd), &Device::Cpu).unwrap(),
            Tensor::from_slice(w, (self.c_out, self.c_in, k, k, k), &Device::Cpu).unwrap(),
        )
    }

    /// The definition, one output at a time, in float64.
    fn reference(&self, x: &[f64], w: &[f64]) -> Vec<f64> {
        let [d, h, wd] = self.dhw;
        let [od, oh, ow] = self.out();
        let (k, p, s) = (self.k, self.cfg.padding as isize, self.cfg.stride);
        let mut out = Vec::with_capacity(self.n * self.c_out * od * oh * ow);
        for n in 0..self.n {
            for o in 0..self.c_out {
                for z in 0..od {
                    for y in 0..oh {
                        for xo in 0..ow {
                            let mut acc = 0.0;
                            for c in 0..self.c_in {
                                for a in 0..k {
                                    for b in 0..k {
                                        for e in 0..k {
                                            let iz = (s * z + a) as isize - p;
                                            let iy = (s * y + b) as isize - p;
                                            let ix = (s * xo + e) as isize - p;
                                            if iz < 0
                                                || iy < 0
                                                || ix < 0
                                                || iz >= d as isize
                                                || iy >= h as isize
                                                || ix >= wd as isize
                                            {
                                                continue;
                                            }
                                            let (iz, iy, ix) =
                                                (iz as usize, iy as usize, ix as usize);
                                            let xv = x[(((n * self.c_in + c) * d + iz) * h + iy)
                                                * wd
                                                + ix];
                                            let wv =
                                                w[(((o * self.c_in + c) * k + a) * k + b) * k + e];
                                            acc += xv * wv;
                                        }
                                    }
                                }
                            }
                            out.push(acc);
                        }
                    }
                }
            }
        }
        out
    }

    fn run(&self, x: &[f64], w: &[f64]) -> Vec<f64> {
        let (xt, wt) = self.tensors(x, w);
        let y = functional::conv3d(&xt, &wt, self.cfg).unwrap();
        let [od, oh, ow] = self.out();
        assert_eq!(y.dims(), &[self.n, self.c_out, od, oh, ow]);
        y.flatten_all().unwrap().to_vec1().unwrap()
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

fn cases() -> Vec<Case> {
    let pad = |p| ConvConfig::default().with_padding(p);
    vec![
        Case {
            n: 2,
            c_in: 3,
            c_out: 2,
            dhw: [4, 5, 3],
            k: 1,
            cfg: pad(0),
        },
        Case {
            n: 1,
            c_in: 2,
            c_out: 3,
            dhw: [4, 5, 6],
            k: 1,
            cfg: pad(1),
        },
        Case {
            n: 2,
            c_in: 3,
            c_out: 2,
            dhw: [5, 4, 6],
            k: 3,
            cfg: pad(0),
        },
        Case {
            n: 1,
            c_in: 2,
            c_out: 4,
            dhw: [4, 6, 5],
            k: 3,
            cfg: pad(1),
        },
        Case {
            n: 1,
            c_in: 2,
            c_out: 2,
            dhw: [3, 3, 4],
            k: 3,
            cfg: pad(2),
        },
        Case {
            n: 2,
            c_in: 2,
            c_out: 3,
            dhw: [5, 6, 7],
            k: 3,
            cfg: pad(1).with_stride(2),
        },
        Case {
            n: 1,
            c_in: 1,
            c_out: 2,
            dhw: [7, 5, 6],
            k: 5,
            cfg: pad(2).with_stride(3),
        },
    ]
}

#[test]
fn forward_matches_direct_sum_f64() {
    for (i, case) in cases().iter().enumerate() {
        let x = random(case.x_len(), 10 + i as u64);
        let w = random(case.w_len(), 20 + i as u64);
        let err = max_abs_diff(&case.run(&x, &w), &case.reference(&x, &w));
        assert!(err < 1e-12, "case {i}: max error {err}");
    }
}

#[test]
fn forward_f32_matches_direct_sum() {
    let case = &cases()[3];
    let x = random(case.x_len(), 1);
    let w = random(case.w_len(), 2);
    let (xt, wt) = case.tensors(&x, &w);
    let y = functional::conv3d(
        &xt.to_dtype(DType::F32).unwrap(),
        &wt.to_dtype(DType::F32).unwrap(),
        case.cfg,
    )
    .unwrap();
    let y: Vec<f64> = y
        .to_dtype(DType::F64)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let err = max_abs_diff(&y, &case.reference(&x, &w));
    assert!(err < 1e-5, "max error {err}");
}

/// `L = sum(r * conv3d(x, w))` for a fixed random `r`, and its gradients by candle's backward.
fn loss_and_grads(case: &Case, x: &[f64], w: &[f64], r: &Tensor) -> (f64, Vec<f64>, Vec<f64>) {
    let (xt, wt) = case.tensors(x, w);
    let (xv, wv) = (
        Var::from_tensor(&xt).unwrap(),
        Var::from_tensor(&wt).unwrap(),
    );
    let y = functional::conv3d(xv.as_tensor(), wv.as_tensor(), case.cfg).unwrap();
    let loss = (y * r).unwrap().sum_all().unwrap();
    let grads = loss.backward().unwrap();
    let flat = |v: &Var| -> Vec<f64> {
        grads
            .get(v)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    };
    (loss.to_scalar().unwrap(), flat(&xv), flat(&wv))
}

#[test]
fn gradients_match_central_differences() {
    let h = 1e-6;
    for (i, case) in cases().iter().enumerate() {
        eprintln!("case {i}");
        let x = random(case.x_len(), 30 + i as u64);
        let w = random(case.w_len(), 40 + i as u64);
        let [od, oh, ow] = case.out();
        let r = random(case.n * case.c_out * od * oh * ow, 50 + i as u64);
        let r = Tensor::from_vec(r, (case.n, case.c_out, od, oh, ow), &Device::Cpu).unwrap();
        let (_, gx, gw) = loss_and_grads(case, &x, &w, &r);
        let loss = |x: &[f64], w: &[f64]| -> f64 {
            let y = case.run(x, w);
            let r: Vec<f64> = r.flatten_all().unwrap().to_vec1().unwrap();
            y.iter().zip(&r).map(|(a, b)| a * b).sum()
        };
        for j in 0..x.len() {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[j] += h;
            xm[j] -= h;
            let fd = (loss(&xp, &w) - loss(&xm, &w)) / (2.0 * h);
            assert!(
                (fd - gx[j]).abs() < 1e-6,
                "case {i} d/dx[{j}]: fd {fd} vs {}",
                gx[j]
            );
        }
        for j in 0..w.len() {
            let (mut wp, mut wm) = (w.clone(), w.clone());
            wp[j] += h;
            wm[j] -= h;
            let fd = (loss(&x, &wp) - loss(&x, &wm)) / (2.0 * h);
            assert!(
                (fd - gw[j]).abs() < 1e-6,
                "case {i} d/dw[{j}]: fd {fd} vs {}",
                gw[j]
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Random geometries: forward equals the direct sum, and the gradients pass a directional
    /// check, `L(x + dx, w + dw) - L(x, w) = <grad_x, dx> + <grad_w, dw> + L(dx, dw)` (exact for
    /// the bilinear `L`).
    #[test]
    fn random_geometries(
        n in 1usize..3, c_in in 1usize..4, c_out in 1usize..4,
        d in 1usize..6, h in 1usize..6, w in 1usize..6,
        half_k in 0usize..2, padding in 0usize..3, stride in 1usize..3, seed in 0u64..1000,
    ) {
        let k = 2 * half_k + 1;
        prop_assume!([d, h, w].iter().all(|&s| s + 2 * padding >= k));
        let cfg = ConvConfig::default().with_padding(padding).with_stride(stride);
        let case = Case { n, c_in, c_out, dhw: [d, h, w], k, cfg };
        let x = random(case.x_len(), seed);
        let wt = random(case.w_len(), seed + 1);
        let y = case.run(&x, &wt);
        prop_assert!(max_abs_diff(&y, &case.reference(&x, &wt)) < 1e-12);

        let [od, oh, ow] = case.out();
        let r = random(y.len(), seed + 2);
        let rt = Tensor::from_vec(r.clone(), (n, c_out, od, oh, ow), &Device::Cpu).unwrap();
        let (l0, gx, gw) = loss_and_grads(&case, &x, &wt, &rt);
        let dx = random(x.len(), seed + 3);
        let dw = random(wt.len(), seed + 4);
        let loss = |x: &[f64], w: &[f64]| -> f64 {
            case.reference(x, w).iter().zip(&r).map(|(a, b)| a * b).sum()
        };
        let xs: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + b).collect();
        let ws: Vec<f64> = wt.iter().zip(&dw).map(|(a, b)| a + b).collect();
        let lhs = loss(&xs, &ws) - l0;
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| a * b).sum::<f64>();
        let rhs = dot(&gx, &dx) + dot(&gw, &dw) + loss(&dx, &dw);
        prop_assert!((lhs - rhs).abs() < 1e-9 * (1.0 + lhs.abs()), "{lhs} vs {rhs}");
    }
}

#[test]
fn layer_adds_bias_and_uses_pytorch_init_bounds() {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F64, &Device::Cpu);
    let (c_in, c_out, k) = (4, 6, 3);
    let conv = conv3d(c_in, c_out, k, ConvConfig::default().with_padding(1), vb).unwrap();
    let bound = 1.0 / ((c_in * k * k * k) as f64).sqrt();
    for t in [conv.weight(), conv.bias().unwrap()] {
        let v: Vec<f64> = t.flatten_all().unwrap().to_vec1().unwrap();
        assert!(v.iter().all(|x| x.abs() <= bound));
    }
    let w: Vec<f64> = conv.weight().flatten_all().unwrap().to_vec1().unwrap();
    let std = (w.iter().map(|x| x * x).sum::<f64>() / w.len() as f64).sqrt();
    // U(-b, b) has standard deviation b / sqrt(3); 648 draws put it within ~5%.
    assert!(
        (std / (bound / 3f64.sqrt()) - 1.0).abs() < 0.15,
        "std {std}"
    );

    let x = Tensor::from_vec(random(c_in * 27, 7), (1, c_in, 3, 3, 3), &Device::Cpu).unwrap();
    let with_bias = conv.forward(&x).unwrap();
    let without = functional::conv3d(&x, conv.weight(), conv.config()).unwrap();
    let diff = (with_bias - without).unwrap();
    let bias: Vec<f64> = conv.bias().unwrap().to_vec1().unwrap();
    for (o, b) in bias.iter().enumerate() {
        let d: Vec<f64> = diff
            .get(0)
            .unwrap()
            .get(o)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert!(d.iter().all(|v| (v - b).abs() < 1e-12));
    }
}

#[test]
fn loads_pytorch_names_from_safetensors() {
    let dev = Device::Cpu;
    let w = Tensor::from_vec(random(2 * 3 * 27, 3), (2, 3, 3, 3, 3), &dev).unwrap();
    let b = Tensor::new(&[0.5f64, -0.25], &dev).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("conv.safetensors");
    let tensors = std::collections::HashMap::from([
        ("layer.weight".to_string(), w.clone()),
        ("layer.bias".to_string(), b.clone()),
    ]);
    candle_core::safetensors::save(&tensors, &path).unwrap();
    // SAFETY: the file is ours and not modified while mapped.
    let vb = unsafe { VarBuilder::from_mmaped_safetensors(&[&path], DType::F64, &dev) }.unwrap();
    let conv = conv3d(3, 2, 3, ConvConfig::default(), vb.pp("layer")).unwrap();
    let same = |a: &Tensor, b: &Tensor| {
        (a - b)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap()
            .max(0)
            .unwrap()
            .to_scalar::<f64>()
            .unwrap()
            == 0.0
    };
    assert!(same(conv.weight(), &w) && same(conv.bias().unwrap(), &b));
    // A wrong shape is an error, not a silent reinterpretation.
    // SAFETY: the file was written above and nothing changes it while it is mapped.
    let vb = unsafe { VarBuilder::from_mmaped_safetensors(&[&path], DType::F64, &dev) }.unwrap();
    assert!(conv3d(2, 3, 3, ConvConfig::default(), vb.pp("layer")).is_err());
}

#[test]
fn bad_shapes_are_errors() {
    let dev = Device::Cpu;
    let x = Tensor::zeros((1, 2, 4, 4, 4), DType::F32, &dev).unwrap();
    let w = Tensor::zeros((3, 2, 3, 3, 3), DType::F32, &dev).unwrap();
    let cfg = ConvConfig::default();
    assert!(functional::conv3d(&x.flatten_from(3).unwrap(), &w, cfg).is_err());
    assert!(functional::conv3d(&x, &w.narrow(1, 0, 1).unwrap(), cfg).is_err());
    assert!(functional::conv3d(&x, &w.narrow(4, 0, 0).unwrap(), cfg).is_err());
    assert!(functional::conv3d(&x, &w, cfg.with_stride(0)).is_err());
    let tiny = Tensor::zeros((1, 2, 2, 4, 4), DType::F32, &dev).unwrap();
    assert!(functional::conv3d(&tiny, &w, cfg).is_err());
    assert!(functional::conv3d(&x, &w.to_dtype(DType::F64).unwrap(), cfg).is_err());
    assert!(Conv3d::new(
        w.clone(),
        Some(Tensor::zeros(2, DType::F32, &dev).unwrap()),
        cfg
    )
    .is_err());
}

/// `L = sum(r * f(x, w))` and its gradients for either conv3d path.
fn path_loss_and_grads(
    case: &Case,
    x: &[f64],
    w: &[f64],
    seed: u64,
    slices: bool,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (xt, wt) = case.tensors(x, w);
    let (xv, wv) = (
        Var::from_tensor(&xt).unwrap(),
        Var::from_tensor(&wt).unwrap(),
    );
    let conv = if slices {
        functional::conv3d_by_slices
    } else {
        functional::conv3d
    };
    let y = conv(xv.as_tensor(), wv.as_tensor(), case.cfg).unwrap();
    let r = Tensor::from_vec(random(y.elem_count(), seed), y.shape(), &Device::Cpu).unwrap();
    assert_eq!(
        y.dims(),
        &[
            case.n,
            case.c_out,
            case.out()[0],
            case.out()[1],
            case.out()[2]
        ]
    );
    let grads = (&y * r).unwrap().sum_all().unwrap().backward().unwrap();
    let flat = |t: &Tensor| -> Vec<f64> { t.flatten_all().unwrap().to_vec1().unwrap() };
    (
        flat(&y),
        flat(grads.get(&xv).unwrap()),
        flat(grads.get(&wv).unwrap()),
    )
}

/// The conv2d-over-slices path (what CUDA devices run) gives the CPU kernel's values and
/// gradients, with and without padding, strided too (sizes the stride leaves a remainder of
/// included: candle 0.11's own conv2d backward gets those wrong, which the path works around).
#[test]
fn slice_path_matches_the_cpu_kernel() {
    for (i, case) in cases().iter().enumerate() {
        let x = random(case.x_len(), 30 + i as u64);
        let w = random(case.w_len(), 40 + i as u64);
        let kernel = path_loss_and_grads(case, &x, &w, 50 + i as u64, false);
        assert!(max_abs_diff(&kernel.0, &case.reference(&x, &w)) < 1e-12);
        let slices = path_loss_and_grads(case, &x, &w, 50 + i as u64, true);
        for (what, a, b) in [
            ("output", &kernel.0, &slices.0),
            ("input gradient", &kernel.1, &slices.1),
            ("weight gradient", &kernel.2, &slices.2),
        ] {
            let err = max_abs_diff(a, b);
            assert!(err < 1e-12, "case {i}: {what} differs by {err}");
        }
    }
}

/// The weight gradient sums many chunks in parallel; its bits must not depend on the thread
/// count or on scheduling (training is reproducible from its seed).
#[test]
fn weight_gradient_bits_do_not_depend_on_threads() {
    let dev = &Device::Cpu;
    let x = Tensor::from_vec(
        random(2 * 8 * 24 * 24 * 24, 11)
            .into_iter()
            .map(|v| v as f32)
            .collect::<Vec<_>>(),
        (2, 8, 24, 24, 24),
        dev,
    )
    .unwrap();
    let w = Var::from_tensor(
        &Tensor::from_vec(
            random(8 * 8 * 27, 12)
                .into_iter()
                .map(|v| v as f32)
                .collect::<Vec<_>>(),
            (8, 8, 3, 3, 3),
            dev,
        )
        .unwrap(),
    )
    .unwrap();
    let cfg = ConvConfig {
        padding: 1,
        stride: 1,
    };
    let weight_grad_bits = || {
        let y = functional::conv3d(&x, w.as_tensor(), cfg).unwrap();
        let grads = y.sqr().unwrap().sum_all().unwrap().backward().unwrap();
        let g: Vec<f32> = grads
            .get(&w)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        g.iter().map(|v| v.to_bits()).collect::<Vec<u32>>()
    };
    let in_pool = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(weight_grad_bits)
    };
    let one = in_pool(1);
    for threads in [2, 3, 2, 3] {
        assert_eq!(in_pool(threads), one, "{threads} threads");
    }
}
