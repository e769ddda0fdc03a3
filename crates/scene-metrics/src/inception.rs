//! InceptionV3's first block: the 64-channel features that SIFID (SinGAN's `sifid_score.py`)
//! and pytorch-fid's `dims=64` compare, loaded from torchvision's weights in a safetensors file.

use std::path::Path;

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, VarBuilder};

use crate::error::{invalid, io_error, Error, Result};

/// torchvision's `BasicConv2d` normalises with `BatchNorm2d(eps=0.001)`.
const BN_EPS: f64 = 1e-3;
/// Every convolution of the block is 3 x 3.
const KERNEL: usize = 3;
/// The block ends with `MaxPool2d(kernel_size=3, stride=2)`.
const POOL_KERNEL: usize = 3;
const POOL_STRIDE: usize = 2;
/// The smallest image side the block accepts (it gives a 1-pixel feature map).
const MIN_SIDE: usize = 11;
/// The BatchNorm tensors of a `BasicConv2d`, after `{name}.bn.`.
const BN_TENSORS: [&str; 4] = ["weight", "bias", "running_mean", "running_var"];
/// The name every weights file holds; what stands before it is a common prefix.
const FIRST_TENSOR: &str = "Conv2d_1a_3x3.conv.weight";

/// One `BasicConv2d` of torchvision's `inception_v3`: conv (no bias) + BatchNorm + ReLU.
struct ConvSpec {
    name: &'static str,
    in_channels: usize,
    out_channels: usize,
    stride: usize,
    padding: usize,
}

impl ConvSpec {
    fn weight_shape(&self) -> Vec<usize> {
        vec![self.out_channels, self.in_channels, KERNEL, KERNEL]
    }

    /// The side of the output for an input side `n`, if the kernel fits.
    fn output_side(&self, n: usize) -> Option<usize> {
        Some((n + 2 * self.padding).checked_sub(KERNEL)? / self.stride + 1)
    }
}

/// `Conv2d_1a_3x3`, `Conv2d_2a_3x3`, `Conv2d_2b_3x3`, in forward order.
const CONVS: [ConvSpec; 3] = [
    ConvSpec {
        name: "Conv2d_1a_3x3",
        in_channels: 3,
        out_channels: 32,
        stride: 2,
        padding: 0,
    },
    ConvSpec {
        name: "Conv2d_2a_3x3",
        in_channels: 32,
        out_channels: 32,
        stride: 1,
        padding: 0,
    },
    ConvSpec {
        name: "Conv2d_2b_3x3",
        in_channels: 32,
        out_channels: 64,
        stride: 1,
        padding: 1,
    },
];

/// InceptionV3's first block as pytorch-fid and SinGAN's SIFID use it (their "block 0",
/// `dims=64`): inputs RGB in [0, 1] are mapped to [-1, 1] (`2x - 1`), then `Conv2d_1a_3x3`
/// (3 -> 32, stride 2), `Conv2d_2a_3x3` (32 -> 32), `Conv2d_2b_3x3` (32 -> 64, padding 1), each a
/// convolution without bias, `BatchNorm2d(eps=0.001)` with the running statistics, and ReLU;
/// then `MaxPool2d(3, stride 2)`. Images are fed at their own size, as SIFID does (FID instead
/// resizes to 299 x 299 first).
///
/// Each BatchNorm is folded into its convolution when loading (weights scaled by
/// `gamma / sqrt(var + eps)`, a bias `beta - mean * gamma / sqrt(var + eps)`, computed in
/// float64), so a forward pass is three biased convolutions in f32. The max-pool is candle's
/// `max_pool2d_with_stride`, whose forward takes PyTorch's floor-mode windows; its backward is
/// wrong in candle 0.11, but no gradient flows through this metric.
///
/// ```
/// use std::collections::HashMap;
/// use candle_core::{DType, Device, Tensor};
/// use scene_metrics::InceptionBlock1;
/// // Zeros stand in for converted torchvision weights (docs/metrics.md shows the conversion).
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("inception.safetensors");
/// let zeros = InceptionBlock1::tensor_shapes()
///     .into_iter()
///     .map(|(name, shape)| Ok((name, Tensor::zeros(shape, DType::F32, &Device::Cpu)?)))
///     .collect::<candle_core::Result<HashMap<_, _>>>()?;
/// candle_core::safetensors::save(&zeros, &path)?;
///
/// let block = InceptionBlock1::from_safetensors(&path, &Device::Cpu)?;
/// let images = Tensor::rand(0f32, 1., (2, 3, 64, 64), &Device::Cpu)?;
/// assert_eq!(block.features(&images)?.dims(), &[2, 64, 14, 14]);
/// assert_eq!(InceptionBlock1::output_size(64, 64), Some((14, 14)));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct InceptionBlock1 {
    /// The three convolutions with their BatchNorms folded in, in forward order.
    convs: Vec<Conv2d>,
}

impl InceptionBlock1 {
    /// Channels of the features.
    pub const CHANNELS: usize = 64;

    /// The tensors a weights file must hold, with their shapes, named as in torchvision's
    /// `inception_v3().state_dict()` (and pytorch-fid's `FIDInceptionV3`):
    /// `Conv2d_1a_3x3.conv.weight` `(32, 3, 3, 3)`, `Conv2d_1a_3x3.bn.weight`, `.bn.bias`,
    /// `.bn.running_mean`, `.bn.running_var` `(32)`, and the same for `Conv2d_2a_3x3` and
    /// `Conv2d_2b_3x3`.
    #[must_use]
    pub fn tensor_shapes() -> Vec<(String, Vec<usize>)> {
        CONVS
            .iter()
            .flat_map(|c| {
                std::iter::once((format!("{}.conv.weight", c.name), c.weight_shape())).chain(
                    BN_TENSORS
                        .iter()
                        .map(|t| (format!("{}.bn.{t}", c.name), vec![c.out_channels])),
                )
            })
            .collect()
    }

    /// Loads the block from a safetensors file with torchvision's tensor names (see
    /// [`InceptionBlock1::tensor_shapes`]), onto `device`. Other tensors in the file (the rest of
    /// InceptionV3, `num_batches_tracked`) are ignored, and a common prefix is accepted: if the
    /// file names `inception.Conv2d_1a_3x3.conv.weight`, every name is read with `inception.`
    /// before it. Errors name the file, and for a missing, misshapen, non-finite or negative
    /// variance tensor its name and expected shape.
    pub fn from_safetensors(path: impl AsRef<Path>, device: &Device) -> Result<Self> {
        let path = path.as_ref();
        let weights_error = |why: String| Error::Weights {
            path: path.to_path_buf(),
            why,
        };
        let bytes = std::fs::read(path).map_err(io_error(path))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes)
            .map_err(|e| weights_error(format!("not a safetensors file: {e}")))?;
        let prefix = name_prefix(header.tensors().keys());
        let vb = VarBuilder::from_buffered_safetensors(bytes, DType::F64, device)
            .map_err(|e| weights_error(e.to_string()))?;
        let load = |name: &str, shape: &[usize]| -> Result<Tensor> {
            let name = format!("{prefix}{name}");
            if !vb.contains_tensor(&name) {
                return Err(weights_error(format!(
                    "tensor `{name}` is missing (expected shape {shape:?}, named as in \
                     torchvision's inception_v3 state_dict)"
                )));
            }
            let tensor = vb
                .get_unchecked(&name)
                .map_err(|e| weights_error(format!("tensor `{name}`: {e}")))?;
            if tensor.dims() != shape {
                return Err(weights_error(format!(
                    "tensor `{name}` has shape {:?}, expected {shape:?}",
                    tensor.dims()
                )));
            }
            let values: Vec<f64> = tensor.flatten_all()?.to_vec1()?;
            if values.iter().any(|v| !v.is_finite()) {
                return Err(weights_error(format!(
                    "tensor `{name}` holds NaN or infinite values"
                )));
            }
            if name.ends_with("running_var") && values.iter().any(|v| *v < 0.0) {
                return Err(weights_error(format!(
                    "tensor `{name}` holds a negative variance"
                )));
            }
            Ok(tensor)
        };
        let convs = CONVS
            .iter()
            .map(|spec| folded_conv(spec, &load))
            .collect::<Result<_>>()?;
        Ok(Self { convs })
    }

    /// The `(height, width)` of the feature map for an image of `height` x `width`, or `None`
    /// if the image is smaller than 11 x 11 pixels.
    ///
    /// ```
    /// use scene_metrics::InceptionBlock1;
    /// // 320: stride-2 conv 159, conv 157, padded conv 157, max-pool 78.
    /// assert_eq!(InceptionBlock1::output_size(320, 320), Some((78, 78)));
    /// assert_eq!(InceptionBlock1::output_size(10, 64), None);
    /// ```
    #[must_use]
    pub fn output_size(height: usize, width: usize) -> Option<(usize, usize)> {
        let side = |n: usize| -> Option<usize> {
            let n = CONVS.iter().try_fold(n, |n, spec| spec.output_side(n))?;
            Some(n.checked_sub(POOL_KERNEL)? / POOL_STRIDE + 1)
        };
        Some((side(height)?, side(width)?))
    }

    /// The features `(B, 64, h, w)` of `images` `(B, 3, H, W)`, RGB in [0, 1] on the block's
    /// device, H and W at least 11 (see [`InceptionBlock1::output_size`]).
    pub fn features(&self, images: &Tensor) -> Result<Tensor> {
        let shape_error = || {
            invalid(
                "images",
                format!(
                    "InceptionV3's first block needs (B, 3, H, W) with H, W >= {MIN_SIDE}, got {:?}",
                    images.dims()
                ),
            )
        };
        let (_, channels, height, width) = images.dims4().map_err(|_| shape_error())?;
        if channels != 3 || Self::output_size(height, width).is_none() {
            return Err(shape_error());
        }
        // Inception was trained on inputs in [-1, 1].
        let mut x = images.to_dtype(DType::F32)?.affine(2.0, -1.0)?;
        for conv in &self.convs {
            x = conv.forward(&x)?.relu()?;
        }
        Ok(x.max_pool2d_with_stride(POOL_KERNEL, POOL_STRIDE)?)
    }
}

/// What stands before [`FIRST_TENSOR`] in a file's tensor names: empty for torchvision's own
/// names, `inception.` (say) for a state dict saved from a wrapping module.
fn name_prefix<'a>(names: impl Iterator<Item = &'a String>) -> String {
    let mut prefixes: Vec<&str> = names
        .filter_map(|n| n.strip_suffix(FIRST_TENSOR))
        .filter(|p| p.is_empty() || p.ends_with('.'))
        .collect();
    // The shortest, so the unprefixed names win if a file has both.
    prefixes.sort_by_key(|p| p.len());
    prefixes
        .first()
        .map_or_else(String::new, |p| (*p).to_string())
}

/// Loads `spec`'s convolution and BatchNorm through `load` and folds the BatchNorm (running
/// statistics, as in evaluation) into a biased f32 convolution.
fn folded_conv(spec: &ConvSpec, load: &dyn Fn(&str, &[usize]) -> Result<Tensor>) -> Result<Conv2d> {
    let channels = [spec.out_channels];
    let weight = load(&format!("{}.conv.weight", spec.name), &spec.weight_shape())?;
    let [gamma, beta, mean, var] =
        BN_TENSORS.map(|t| load(&format!("{}.bn.{t}", spec.name), &channels));
    let (gamma, beta, mean, var) = (gamma?, beta?, mean?, var?);
    let scale = gamma.div(&(var + BN_EPS)?.sqrt()?)?;
    let weight = weight
        .broadcast_mul(&scale.reshape((spec.out_channels, 1, 1, 1))?)?
        .to_dtype(DType::F32)?;
    let bias = beta.sub(&mean.mul(&scale)?)?.to_dtype(DType::F32)?;
    let config = Conv2dConfig {
        padding: spec.padding,
        stride: spec.stride,
        ..Conv2dConfig::default()
    };
    Ok(Conv2d::new(weight, Some(bias), config))
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::HashMap;
    use std::path::PathBuf;

    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Weights with torchvision's names and shapes, drawn so every layer passes some signal
    /// through its ReLU: He-scaled convolutions, BatchNorm scales near 1, variances in [0.5, 1.5].
    pub(crate) fn random_weights(seed: u64) -> HashMap<String, Tensor> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        InceptionBlock1::tensor_shapes()
            .into_iter()
            .map(|(name, shape)| {
                let count: usize = shape.iter().product();
                let (low, high) = if name.ends_with("conv.weight") {
                    let bound = (6.0 / (shape[1] * KERNEL * KERNEL) as f32).sqrt();
                    (-bound, bound)
                } else if name.ends_with("bn.weight") || name.ends_with("running_var") {
                    (0.5, 1.5)
                } else {
                    (-0.2, 0.2)
                };
                let values: Vec<f32> = (0..count).map(|_| rng.random_range(low..high)).collect();
                let tensor = Tensor::from_vec(values, shape, &Device::Cpu).unwrap();
                (name, tensor)
            })
            .collect()
    }

    /// Writes `weights` to `name` in `dir`.
    fn write(dir: &Path, name: &str, weights: &HashMap<String, Tensor>) -> PathBuf {
        let path = dir.join(name);
        candle_core::safetensors::save(weights, &path).unwrap();
        path
    }

    /// A block with [`random_weights`], loaded through a file as a user's would be.
    pub(crate) fn random_block(seed: u64) -> InceptionBlock1 {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "block.safetensors", &random_weights(seed));
        InceptionBlock1::from_safetensors(&path, &Device::Cpu).unwrap()
    }

    fn values(weights: &HashMap<String, Tensor>, name: &str) -> Vec<f64> {
        weights[name]
            .to_dtype(DType::F64)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    }

    /// A plain float64 `BasicConv2d` (conv, BatchNorm with running statistics, ReLU) on a
    /// `(c, h, w)` image, written from PyTorch's definitions without folding.
    fn basic_conv_f64(
        x: &[f64],
        (c, h, w): (usize, usize, usize),
        spec: &ConvSpec,
        weights: &HashMap<String, Tensor>,
    ) -> (Vec<f64>, (usize, usize, usize)) {
        let p = |t: &str| values(weights, &format!("{}.{t}", spec.name));
        let (kernel, gamma, beta, mean, var) = (
            p("conv.weight"),
            p("bn.weight"),
            p("bn.bias"),
            p("bn.running_mean"),
            p("bn.running_var"),
        );
        let (oh, ow) = (spec.output_side(h).unwrap(), spec.output_side(w).unwrap());
        let o = spec.out_channels;
        let mut out = vec![0.0; o * oh * ow];
        for oc in 0..o {
            for y in 0..oh {
                for xx in 0..ow {
                    let mut sum = 0.0;
                    for ic in 0..c {
                        for ky in 0..KERNEL {
                            for kx in 0..KERNEL {
                                let iy = (y * spec.stride + ky) as isize - spec.padding as isize;
                                let ix = (xx * spec.stride + kx) as isize - spec.padding as isize;
                                if iy < 0 || ix < 0 || iy >= h as isize || ix >= w as isize {
                                    continue;
                                }
                                let pixel = x[(ic * h + iy as usize) * w + ix as usize];
                                sum += pixel * kernel[((oc * c + ic) * KERNEL + ky) * KERNEL + kx];
                            }
                        }
                    }
                    let normalised =
                        (sum - mean[oc]) / (var[oc] + BN_EPS).sqrt() * gamma[oc] + beta[oc];
                    out[(oc * oh + y) * ow + xx] = normalised.max(0.0);
                }
            }
        }
        (out, (o, oh, ow))
    }

    /// The whole block in float64 on one `(3, h, w)` image in [0, 1].
    fn block_f64(
        image: &[f64],
        (h, w): (usize, usize),
        weights: &HashMap<String, Tensor>,
    ) -> (Vec<f64>, (usize, usize, usize)) {
        let mut x: Vec<f64> = image.iter().map(|v| 2.0 * v - 1.0).collect();
        let mut dims = (3, h, w);
        for spec in &CONVS {
            (x, dims) = basic_conv_f64(&x, dims, spec, weights);
        }
        let (c, h, w) = dims;
        let (oh, ow) = (
            (h - POOL_KERNEL) / POOL_STRIDE + 1,
            (w - POOL_KERNEL) / POOL_STRIDE + 1,
        );
        let mut out = vec![f64::NEG_INFINITY; c * oh * ow];
        for ch in 0..c {
            for y in 0..oh {
                for xx in 0..ow {
                    for ky in 0..POOL_KERNEL {
                        for kx in 0..POOL_KERNEL {
                            let v = x[(ch * h + y * POOL_STRIDE + ky) * w + xx * POOL_STRIDE + kx];
                            let cell = &mut out[(ch * oh + y) * ow + xx];
                            *cell = cell.max(v);
                        }
                    }
                }
            }
        }
        (out, (c, oh, ow))
    }

    #[test]
    fn output_shape_follows_the_convolution_arithmetic() {
        let block = random_block(1);
        // 64: stride-2 conv floor((64 - 3) / 2) + 1 = 31, conv 29, padded conv 29, pool 14.
        let images = Tensor::rand(0f32, 1., (2, 3, 64, 64), &Device::Cpu).unwrap();
        assert_eq!(block.features(&images).unwrap().dims(), &[2, 64, 14, 14]);
        // 37 x 50: 18 x 24, 16 x 22, 16 x 22, 7 x 10.
        let images = Tensor::rand(0f32, 1., (1, 3, 37, 50), &Device::Cpu).unwrap();
        assert_eq!(block.features(&images).unwrap().dims(), &[1, 64, 7, 10]);
        assert_eq!(InceptionBlock1::output_size(37, 50), Some((7, 10)));
        assert_eq!(
            InceptionBlock1::output_size(MIN_SIDE, MIN_SIDE),
            Some((1, 1))
        );
        assert_eq!(InceptionBlock1::output_size(MIN_SIDE - 1, MIN_SIDE), None);
        let small = Tensor::zeros((1, 3, MIN_SIDE - 1, 32), DType::F32, &Device::Cpu).unwrap();
        let err = block.features(&small).unwrap_err().to_string();
        assert!(err.contains("11"), "{err}");
        let gray = Tensor::zeros((1, 1, 32, 32), DType::F32, &Device::Cpu).unwrap();
        assert!(block.features(&gray).is_err());
    }

    #[test]
    fn features_match_a_float64_reference_without_folding() {
        let weights = random_weights(2);
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "w.safetensors", &weights);
        let block = InceptionBlock1::from_safetensors(&path, &Device::Cpu).unwrap();
        let (h, w) = (17, 19);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let image: Vec<f64> = (0..3 * h * w).map(|_| rng.random_range(0.0..1.0)).collect();
        let (expected, dims) = block_f64(&image, (h, w), &weights);
        assert_eq!(dims, (64, 2, 3));
        let input = Tensor::from_vec(image, (1, 3, h, w), &Device::Cpu).unwrap();
        let got: Vec<f32> = block
            .features(&input)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let scale = expected.iter().fold(0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.1, "the random weights pass no signal");
        for (g, e) in got.iter().zip(&expected) {
            assert!(
                (f64::from(*g) - e).abs() < 1e-5 * scale,
                "{g} vs {e} (scale {scale})"
            );
        }
    }

    #[test]
    fn a_common_prefix_is_accepted_and_other_tensors_ignored() {
        let weights = random_weights(4);
        let mut prefixed: HashMap<String, Tensor> = weights
            .iter()
            .map(|(k, v)| (format!("inception.{k}"), v.clone()))
            .collect();
        prefixed.insert(
            "fc.weight".into(),
            Tensor::zeros((2, 2), DType::F32, &Device::Cpu).unwrap(),
        );
        let dir = tempfile::tempdir().unwrap();
        let plain = InceptionBlock1::from_safetensors(
            write(dir.path(), "plain.safetensors", &weights),
            &Device::Cpu,
        )
        .unwrap();
        let wrapped = InceptionBlock1::from_safetensors(
            write(dir.path(), "wrapped.safetensors", &prefixed),
            &Device::Cpu,
        )
        .unwrap();
        let images = Tensor::rand(0f32, 1., (1, 3, 24, 24), &Device::Cpu).unwrap();
        let features = |b: &InceptionBlock1| -> Vec<f32> {
            b.features(&images)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        assert_eq!(features(&plain), features(&wrapped));
    }

    /// The error of loading `weights` from a file, which it must name.
    fn load_error(weights: &HashMap<String, Tensor>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "broken.safetensors", weights);
        let err = match InceptionBlock1::from_safetensors(&path, &Device::Cpu) {
            Ok(_) => panic!("broken weights loaded"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains(path.to_str().unwrap()), "{err}");
        err
    }

    #[test]
    fn missing_and_misshapen_tensors_are_named_with_the_file_and_expected_shape() {
        let mut weights = random_weights(5);
        weights.remove("Conv2d_2a_3x3.bn.running_var");
        let err = load_error(&weights);
        assert!(
            err.contains("`Conv2d_2a_3x3.bn.running_var` is missing") && err.contains("[32]"),
            "{err}"
        );

        let mut weights = random_weights(5);
        weights.insert(
            "Conv2d_2b_3x3.conv.weight".into(),
            Tensor::zeros((64, 32, 1, 1), DType::F32, &Device::Cpu).unwrap(),
        );
        let err = load_error(&weights);
        assert!(
            err.contains("`Conv2d_2b_3x3.conv.weight` has shape [64, 32, 1, 1]")
                && err.contains("expected [64, 32, 3, 3]"),
            "{err}"
        );

        let mut weights = random_weights(5);
        let negative = (weights["Conv2d_1a_3x3.bn.running_var"].clone() - 2.0).unwrap();
        weights.insert("Conv2d_1a_3x3.bn.running_var".into(), negative);
        let err = load_error(&weights);
        assert!(err.contains("negative variance"), "{err}");
    }

    #[test]
    fn unreadable_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nowhere.safetensors");
        let err = InceptionBlock1::from_safetensors(&missing, &Device::Cpu)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("nowhere.safetensors"), "{err}");
        let junk = dir.path().join("junk.safetensors");
        std::fs::write(&junk, b"not a tensor file").unwrap();
        let err = InceptionBlock1::from_safetensors(&junk, &Device::Cpu)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("junk.safetensors") && err.contains("not a safetensors file"),
            "{err}"
        );
    }
}
