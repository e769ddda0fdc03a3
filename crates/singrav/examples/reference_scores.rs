//! What a perfect generator would score on the sample metrics of `volgen eval`: scenes drawn from
//! the very distribution the stones dataset comes from (the built-in stones scene with other
//! layout seeds), rendered from the dataset's own cameras and compared with its views exactly as
//! `volgen eval` compares generated scenes (its default 4 views, 108^2 colour, 54^2 opacity).
//!
//! Generated scenes vary the real one, so they cannot score 0 on patch SWD, colour SWD or
//! floaters: stones that stand elsewhere cover sky pixels of the real view. These numbers are the
//! floor a generator of new stone circles can reach, and the diversity such scenes have.
//!
//! ```bash
//! cargo run --release -p singrav --example reference_scores -- /tmp/reference 8
//! ```

use std::path::PathBuf;

use candle_core::Device;
use singrav::dataset::{write_dataset, Dataset, DatasetSpec};
use singrav::metrics::{colour_swd, diversity_mv, floaters, patch_swd_mv};
use singrav::scenes::StandingStones;

/// `volgen eval`'s defaults: views compared, colour and opacity sizes for `tiny`.
const VIEWS: usize = 4;
const COLOUR_SIZE: usize = 108;
const OPACITY_SIZE: usize = 54;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().ok_or("usage: reference_scores DIR [SCENES]")?);
    let scenes: u64 = args.next().map_or(Ok(8), |s| s.parse())?;
    let device = Device::Cpu;
    // Seed 0's cameras for every layout: `volgen scene stones` uses the seed for both.
    let spec = DatasetSpec::default();
    let background = [1.0, 1.0, 1.0];
    let load = |layout: u64| -> Result<Dataset> {
        let out = dir.join(format!("stones-{layout}"));
        if !out.join("transforms.json").exists() {
            write_dataset(&StandingStones::new(layout), &out, &spec)?;
        }
        let data = Dataset::load(&out.join("transforms.json"), background)?;
        // As `volgen eval` spreads its views over the frames.
        let chosen: Vec<usize> = (0..VIEWS).map(|i| i * data.len() / VIEWS).collect();
        Ok(data.subset(&chosen)?)
    };
    let real = load(0)?;
    let real_colour = real.level(COLOUR_SIZE, COLOUR_SIZE, &device)?.images;
    let real_alpha = real.level(OPACITY_SIZE, OPACITY_SIZE, &device)?.opacity;
    let (mut colour, mut opacity) = (Vec::new(), Vec::new());
    for layout in 1..=scenes {
        let other = load(layout)?;
        colour.push(other.level(COLOUR_SIZE, COLOUR_SIZE, &device)?.images);
        opacity.push(other.level(OPACITY_SIZE, OPACITY_SIZE, &device)?.opacity);
    }
    println!("| scenes | patch SWD-MV | colour SWD | floaters | Diversity-MV |");
    println!("|---|---|---|---|---|");
    println!(
        "| stones layouts 1..={scenes} against layout 0 | {:.4} | {:.4} | {:.4} | {:.3} |",
        patch_swd_mv(&colour, &real_colour)?,
        colour_swd(&colour, &real_colour)?,
        floaters(&opacity, &real_alpha)?.unwrap_or(f64::NAN),
        diversity_mv(&colour, &real_colour)?,
    );
    Ok(())
}
