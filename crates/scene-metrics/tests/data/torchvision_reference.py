"""Reference values for volgen's SIFID and VGG-19 features, from torchvision's own networks.

torchvision builds InceptionV3 and VGG-19 with random weights and no download
(`inception_v3(weights=None)`, `vgg19(weights=None)`). This script saves parts of them as
safetensors, computes on the same images

- SinGAN's SIFID (`SIFID/sifid_score.py`): InceptionV3's first block on `2x - 1` inputs at their
  own size, every position of the 64-channel map one sample, `np.cov`, and the Frechet distance
  with `scipy.linalg.sqrtm` of `sigma1 @ sigma2`, exactly as that file does;
- VGG-19 features as swd-loss's `Vgg19Config::heitz()` defines them (ImageNet normalisation,
  reflect padding, 2x2 average pooling), up to relu2_1,

and writes them beside this file for `crates/scene-metrics/tests/torchvision_reference.rs` and
`crates/swd-loss/tests/torchvision_reference.rs`. Forward passes run in float64 (torch `double`)
so the references carry no float32 error.

    python -m venv /tmp/tv && /tmp/tv/bin/pip install torch torchvision scipy safetensors
    /tmp/tv/bin/python crates/scene-metrics/tests/data/torchvision_reference.py
"""

import json
import pathlib

import numpy as np
import scipy
import torch
import torchvision
from safetensors.torch import save_file
from scipy import linalg

HERE = pathlib.Path(__file__).resolve().parent
SWD_DATA = HERE.parents[2] / "swd-loss" / "tests" / "data"
torch.manual_seed(18)
rng = np.random.default_rng(18)


def images(count, size):
    """Smooth random 8-bit RGB images (count, 3, size, size): SinGAN reads PNGs and divides by 255."""
    coarse = rng.uniform(0, 255, (count, 3, size // 6, size // 6))
    up = torch.nn.functional.interpolate(torch.from_numpy(coarse), size=(size, size), mode="bilinear")
    noise = rng.normal(0, 12, (count, 3, size, size))
    return np.clip(np.round(up.numpy() + noise), 0, 255).astype(np.uint8)


def unit(pixels):
    """8-bit pixels as sifid_score.py feeds them: float32 divided by 255."""
    return pixels.astype(np.float32) / 255.0


# ---- SIFID: InceptionV3's first block -------------------------------------------------------
inception = torchvision.models.inception_v3(weights=None, aux_logits=False, init_weights=True).eval()
block = torch.nn.Sequential(
    inception.Conv2d_1a_3x3,
    inception.Conv2d_2a_3x3,
    inception.Conv2d_2b_3x3,
    torch.nn.MaxPool2d(kernel_size=3, stride=2),
)
# Fresh BatchNorms hold mean 0 and variance 1; random statistics and affine parameters make the
# folding of every BatchNorm tensor count.
with torch.no_grad():
    for name in ("Conv2d_1a_3x3", "Conv2d_2a_3x3", "Conv2d_2b_3x3"):
        bn = getattr(inception, name).bn
        n = bn.num_features
        bn.weight.copy_(torch.from_numpy(rng.uniform(0.5, 1.5, n)))
        # A positive shift keeps every channel alive somewhere (a channel that ReLU zeroes at
        # every position makes the covariance singular, and sqrtm inaccurate).
        bn.bias.copy_(torch.from_numpy(rng.uniform(0.1, 0.4, n)))
        bn.running_mean.copy_(torch.from_numpy(rng.uniform(-0.1, 0.1, n)))
        bn.running_var.copy_(torch.from_numpy(rng.uniform(0.5, 2.0, n)))
prefixes = ("Conv2d_1a_3x3.", "Conv2d_2a_3x3.", "Conv2d_2b_3x3.")
tensors = {
    k: v.float().contiguous()
    for k, v in inception.state_dict().items()
    if k.startswith(prefixes) and not k.endswith("num_batches_tracked")
}
real_u8 = images(2, 64)
fake_u8 = images(2, 64)
tensors["test.real_u8"] = torch.from_numpy(real_u8)
tensors["test.fake_u8"] = torch.from_numpy(fake_u8)
real, fake = unit(real_u8), unit(fake_u8)


def activations(image):
    """sifid_score.get_activations for one image: (positions, 64)."""
    with torch.no_grad():
        block64 = block.double()
        x = torch.from_numpy(image[None]).double() * 2 - 1  # pytorch-fid's normalize_input
        pred = block64(x)
    return pred.numpy().transpose(0, 2, 3, 1).reshape(pred.shape[2] * pred.shape[3], -1), pred


def calculate_frechet_distance(mu1, sigma1, mu2, sigma2, eps=1e-6):
    """sifid_score.calculate_frechet_distance, verbatim but for the messages."""
    mu1, mu2 = np.atleast_1d(mu1), np.atleast_1d(mu2)
    sigma1, sigma2 = np.atleast_2d(sigma1), np.atleast_2d(sigma2)
    diff = mu1 - mu2
    covmean, _ = linalg.sqrtm(sigma1.dot(sigma2), disp=False)
    if not np.isfinite(covmean).all():
        offset = np.eye(sigma1.shape[0]) * eps
        covmean = linalg.sqrtm((sigma1 + offset).dot(sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0, atol=1e-3):
            raise ValueError("Imaginary component {}".format(np.max(np.abs(covmean.imag))))
        covmean = covmean.real
    tr_covmean = np.trace(covmean)
    return diff.dot(diff) + np.trace(sigma1) + np.trace(sigma2) - 2 * tr_covmean


def stats(image):
    act, pred = activations(image)
    return np.mean(act, axis=0), np.cov(act, rowvar=False), pred


sifid = []
for v in range(real.shape[0]):
    mu1, s1, pred = stats(real[v])
    mu2, s2, _ = stats(fake[v])
    sifid.append(float(calculate_frechet_distance(mu1, s1, mu2, s2)))
    tensors[f"test.features_real_{v}"] = pred.float()[0]
save_file(tensors, HERE / "sifid_reference.safetensors")
versions = {"torch": torch.__version__, "torchvision": torchvision.__version__,
            "numpy": np.__version__, "scipy": scipy.__version__}
(HERE / "sifid_reference.json").write_text(json.dumps({
    "sifid_per_view": sifid,
    "sifid_mv": float(np.mean(sifid)),
    "versions": versions,
}, indent=2) + "\n")
print("SIFID per view", sifid)

# ---- VGG-19 features as in Heitz et al. --------------------------------------------------------
vgg = torchvision.models.vgg19(weights=None).features.eval()
with torch.no_grad():
    for i in (0, 2, 5):
        # torchvision initialises biases to 0; random ones make them count.
        vgg[i].bias.copy_(torch.from_numpy(rng.uniform(-0.1, 0.1, vgg[i].bias.shape[0])))
        # Stored as float16 to keep the file small; the reference uses the same rounded values.
        vgg[i].weight.copy_(vgg[i].weight.half().float())
        vgg[i].bias.copy_(vgg[i].bias.half().float())
weights = {f"features.{i}.{p}": getattr(vgg[i], p).half().contiguous()
           for i in (0, 2, 5) for p in ("weight", "bias")}
image_u8 = images(1, 12)
image = unit(image_u8)
mean = torch.tensor([0.485, 0.456, 0.406], dtype=torch.float64).view(1, 3, 1, 1)
std = torch.tensor([0.229, 0.224, 0.225], dtype=torch.float64).view(1, 3, 1, 1)


def conv(i, x):
    layer = vgg[i].double()
    return torch.nn.functional.conv2d(
        torch.nn.functional.pad(x, (1, 1, 1, 1), mode="reflect"), layer.weight, layer.bias)


with torch.no_grad():
    x = (torch.from_numpy(image).double() - mean) / std
    relu1_1 = torch.relu(conv(0, x))
    relu1_2 = torch.relu(conv(2, relu1_1))
    pooled = torch.nn.functional.avg_pool2d(relu1_2, 2)
    relu2_1 = torch.relu(conv(5, pooled))
save_file({
    **weights,
    "test.image_u8": torch.from_numpy(image_u8),
    "test.relu1_1": relu1_1.float(),
    "test.relu1_2": relu1_2.float(),
    "test.relu2_1": relu2_1.float(),
}, SWD_DATA / "vgg19_torchvision.safetensors")
(SWD_DATA / "vgg19_torchvision.json").write_text(json.dumps({"versions": versions}, indent=2) + "\n")
print("VGG-19 features written")
