//! Command-line parsing and dispatch; each subcommand lives in its own module.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod animate;
mod demo;
mod edit;
mod eval;
mod export;
mod fit;
mod info;
mod model_io;
mod render;
mod sample;
mod scene;
mod train;

/// volgen: generative radiance volumes (SinGRAV) and their building blocks.
#[derive(Debug, Parser)]
#[command(name = "volgen", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print a volume file's size, box, channels and value ranges.
    Info(info::InfoArgs),
    /// Export a volume to OpenVDB (Blender, Houdini) and/or a stack of EXR slices.
    Export(export::ExportArgs),
    /// Render a volume from the cameras of a transforms.json to EXR (R, G, B, A, Z) and PNG.
    Render(render::RenderArgs),
    /// Reconstruct a dataset's scene directly as one radiance volume (no networks): VDB/EXR, PSNR.
    Fit(fit::FitArgs),
    /// Render a built-in scene (stones, mushrooms, islands) into an RGB-D transforms.json dataset.
    Scene(scene::SceneArgs),
    /// Train SinGRAV on a transforms.json RGB-D dataset (progress bar, log, checkpoints).
    Train(train::TrainArgs),
    /// Generate new scenes from a trained model: volumes, VDB/EXR on request, PNG views.
    Sample(sample::SampleArgs),
    /// Animate a generated scene (a smoothed random walk on the finer scales' noise), frame by frame.
    Animate(animate::AnimateArgs),
    /// Edit a generated scene (remove, duplicate, move boxes) and harmonise it with the generators.
    Edit(edit::EditArgs),
    /// The whole pipeline: dataset of a built-in scene, tiny training, samples, pictures, VDB.
    Demo(demo::DemoArgs),
    /// The paper's metrics of a trained model: Diversity-MV, and SIFID-MV with InceptionV3 weights.
    Eval(eval::EvalArgs),
}

/// Parses the command line, runs the subcommand and turns errors into a message and exit code 1.
pub fn run() -> ExitCode {
    // On a GPU the critics' gradient penalty is candle's double backward, which it supports only
    // when this is set before the first backward pass; set here, at start-up, before any other
    // thread exists. On the CPU the penalty is a first-order graph and candle can drop every
    // backward graph as usual.
    #[cfg(feature = "cuda")]
    std::env::set_var("CANDLE_GRAD_DO_NOT_DETACH", "1");
    // candle's element-wise ops run on its own pool, whose worker spins 25 000 times after each
    // op before it sleeps; on a machine with as many cores as rayon threads that spin takes a
    // core from the convolutions that follow (13-19% of a training run's samples were the
    // spin). Parking at once made `tiny`'s scale-3 iterations 11% faster (docs/training.md).
    // A value the user set is kept.
    if std::env::var_os("CANDLE_BARRIER_POOL_SPIN_LIMIT").is_none() {
        std::env::set_var("CANDLE_BARRIER_POOL_SPIN_LIMIT", "1");
    }
    // And that pool runs on the calling thread alone: the work it gets between our own threaded
    // kernels is gradient bookkeeping (`zeros_like`, `add`) and small ops, where handing each op
    // to a parked worker (two `futex` calls) cost more than the second core gave back. `tiny`
    // trained 1.07x faster with it (docs/training.md). This pool only: the convolutions, the
    // renderer and candle's matmul keep rayon's threads. A value the user set is kept.
    if std::env::var_os("CANDLE_NUM_THREADS").is_none() {
        std::env::set_var("CANDLE_NUM_THREADS", "1");
    }
    // The parallel loops of training and rendering start on this thread: it is one of rayon's
    // threads rather than sleeping while they run (see the function). After the variables
    // above: the pool's threads are the program's first.
    if let Err(e) = volrender::join_global_pool(None) {
        eprintln!("error: could not start the worker threads: {e}");
        return ExitCode::FAILURE;
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(&args),
        Command::Export(args) => export::run(&args),
        Command::Render(args) => render::run(&args),
        Command::Fit(args) => fit::run(&args),
        Command::Scene(args) => scene::run(&args),
        Command::Train(args) => train::run(&args),
        Command::Sample(args) => sample::run(&args),
        Command::Animate(args) => animate::run(&args),
        Command::Edit(args) => edit::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Eval(args) => eval::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", error_message(&err));
            ExitCode::FAILURE
        }
    }
}

/// Joins an error's chain with ": ", leaving out causes whose text the previous message already
/// contains (library errors often print their source inline).
fn error_message(err: &anyhow::Error) -> String {
    let mut message = String::new();
    let mut previous = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if !previous.contains(&text) {
            if !message.is_empty() {
                message.push_str(": ");
            }
            message.push_str(&text);
        }
        previous = text;
    }
    message
}
