//! The mean colour of a trained pyramid's matter, and of the clear voxels around it, at the end
//! of every 3D scale: for the reconstruction V* and for random samples. Used for
//! docs/journal/2026-11-training-quality.md ("The samples' purple tint"), where it showed `tiny`'s V* to hold purple
//! stone voxels in a green halo and every finer generator to move the samples' stones towards
//! them.
//!
//! ```text
//! cargo run --release -p research --example matter_colours -- RUN [--samples K] [--seed S]
//!     [--above Z] [--zero-last-reconstruction-noise] [--noise-like-reconstruction]
//! ```
//!
//! - "matter": voxels whose opacity across the voxel, `1 - exp(-sigma * voxel)`, exceeds 0.5;
//!   "halo": voxels below 0.05 with matter among their 26 neighbours. Only voxels whose centre
//!   lies above height `Z` (the model's box is [-1, 1]^3, z up; default: every voxel) count,
//!   so that `--above -0.42` on the stones scene keeps the stones and leaves out the ground.
//! - `--zero-last-reconstruction-noise`: V* with the optimised noise z*_n of the finest 3D scale
//!   set to zero.
//! - `--noise-like-reconstruction`: the samples' noise at the scales n >= 2 drawn with the
//!   per-channel RMS of z*_n instead of the scale's noise amplitude.

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use singrav::active_set::{active_mask, ActiveSetRule};
use singrav::SinGrav;

/// Opacity across a voxel above which it counts as matter.
const MATTER: f32 = 0.5;
/// Opacity across a voxel below which it counts as clear.
const CLEAR: f32 = 0.05;

/// What the command line asks for.
struct Options {
    run: String,
    samples: usize,
    seed: u64,
    above: f32,
    zero_last_reconstruction_noise: bool,
    noise_like_reconstruction: bool,
}

fn parse() -> Result<Options, String> {
    let mut args = std::env::args().skip(1);
    let mut options = Options {
        run: String::new(),
        samples: 4,
        seed: 7,
        above: -1.0,
        zero_last_reconstruction_noise: false,
        noise_like_reconstruction: false,
    };
    while let Some(arg) = args.next() {
        let mut value = |flag: &str| args.next().ok_or(format!("{flag} needs a value"));
        match arg.as_str() {
            "--samples" => options.samples = parse_value("--samples", &value("--samples")?)?,
            "--seed" => options.seed = parse_value("--seed", &value("--seed")?)?,
            "--above" => options.above = parse_value("--above", &value("--above")?)?,
            "--zero-last-reconstruction-noise" => options.zero_last_reconstruction_noise = true,
            "--noise-like-reconstruction" => options.noise_like_reconstruction = true,
            flag if flag.starts_with("--") => return Err(format!("unknown flag {flag}")),
            run => options.run = run.into(),
        }
    }
    if options.run.is_empty() {
        return Err(
            "usage: matter_colours RUN [--samples K] [--seed S] [--above Z] \
                    [--zero-last-reconstruction-noise] [--noise-like-reconstruction]"
                .into(),
        );
    }
    Ok(options)
}

fn parse_value<T: std::str::FromStr>(flag: &str, text: &str) -> Result<T, String> {
    text.parse()
        .map_err(|_| format!("{flag}: `{text}` is not a valid value"))
}

/// Count and summed colour of one class of voxels.
#[derive(Default)]
struct ColourSum {
    count: usize,
    rgb: [f64; 3],
}

impl ColourSum {
    fn add(&mut self, rgb: [f32; 3]) {
        self.count += 1;
        for (sum, value) in self.rgb.iter_mut().zip(rgb) {
            *sum += f64::from(value);
        }
    }

    fn cell(&self) -> String {
        if self.count == 0 {
            return "-".into();
        }
        let n = self.count as f64;
        format!(
            "({:.3}, {:.3}, {:.3}) of {}",
            self.rgb[0] / n,
            self.rgb[1] / n,
            self.rgb[2] / n,
            self.count
        )
    }
}

/// The density above which a voxel of side `voxel` is more than `opacity` opaque across:
/// `1 - exp(-sigma * voxel) > opacity`.
fn density_for_opacity(opacity: f32, voxel: f32) -> f32 {
    -(1.0 - opacity).ln() / voxel
}

/// The matter's and the halo's colour sums of a raw volume `(1, 4, s, s, s)`.
fn classify(model: &SinGrav, raw: &Tensor, above: f32) -> singrav::Result<[ColourSum; 2]> {
    let activation = model.config().activation();
    let physical = activation.apply(&raw.squeeze(0)?)?;
    let size = physical.dim(1)?;
    let voxel = 2.0 / size as f32;
    let matter_density = density_for_opacity(MATTER, voxel);
    // Within one voxel (the 26 neighbours) of matter: the active set's own dilation.
    let beside_matter = ActiveSetRule {
        threshold: matter_density,
        margin: 1,
        shell: false,
    };
    let beside_matter: Vec<f32> = active_mask(raw, &activation, &beside_matter)?
        .flatten_all()?
        .to_vec1()?;
    let values: Vec<f32> = physical.flatten_all()?.to_vec1()?;
    let cells = size * size * size;
    let (mut matter, mut halo) = (ColourSum::default(), ColourSum::default());
    // Voxels are stored z-major: the first `skipped` lie at or below height `above`.
    let skipped = (0..size)
        .take_while(|&z| -1.0 + (z as f32 + 0.5) * voxel <= above)
        .count()
        * size
        * size;
    for i in skipped..cells {
        let sigma = values[i];
        let rgb = [
            values[cells + i],
            values[2 * cells + i],
            values[3 * cells + i],
        ];
        if sigma > matter_density {
            matter.add(rgb);
        } else if sigma < density_for_opacity(CLEAR, voxel) && beside_matter[i] > 0.0 {
            halo.add(rgb);
        }
    }
    Ok([matter, halo])
}

/// Runs the pyramid scale by scale on `noise`, printing a row per 3D scale.
fn rows(model: &SinGrav, label: &str, noise: &[Tensor], above: f32) -> singrav::Result<()> {
    let mut volume = model.coarsest(&noise[0])?;
    for n in 1..=noise.len() {
        if n > 1 {
            volume = model.refine(n, &noise[n - 1], &volume)?;
        }
        let [matter, halo] = classify(model, &volume, above)?;
        println!("| {label} | {n} | {} | {} |", matter.cell(), halo.cell());
    }
    Ok(())
}

/// Per-channel RMS `(1, C, 1, 1, 1)` of a noise volume.
fn channel_rms(noise: &Tensor) -> candle_core::Result<Tensor> {
    noise
        .sqr()?
        .mean_keepdim(4)?
        .mean_keepdim(3)?
        .mean_keepdim(2)?
        .sqrt()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let options = parse()?;
    let device = Device::Cpu;
    let (model, _) = SinGrav::load(options.run.as_ref(), &device)?;
    let scales = model.volume_scales();
    let mut reconstruction = model.reconstruction_noise(scales)?;
    println!("| volume | 3D scale | matter colour of voxels | halo colour of voxels |");
    println!("|---|---|---|---|");
    if options.zero_last_reconstruction_noise && scales > 1 {
        reconstruction[scales - 1] = reconstruction[scales - 1].zeros_like()?;
    }
    rows(&model, "V*", &reconstruction, options.above)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
    for k in 0..options.samples {
        let mut noise = model.draw_noise(scales, &mut rng)?;
        if options.noise_like_reconstruction {
            for n in 2..=scales {
                let rms = channel_rms(&reconstruction[n - 1])?;
                let unit = singrav::noise::gaussian_volume(
                    &mut rng,
                    noise[n - 1].dim(1)?,
                    noise[n - 1].dim(2)?,
                    1.0,
                    &device,
                )?;
                noise[n - 1] = unit.broadcast_mul(&rms)?;
            }
        }
        rows(&model, &format!("sample {k}"), &noise, options.above)?;
    }
    Ok(())
}
