//! Command-line parsing and dispatch; each subcommand lives in its own module.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod animate;
mod compose;
mod demo;
mod device_check;
mod edit;
mod eval;
mod export;
mod extent;
mod fit;
mod harmonize;
mod import;
mod info;
mod mesh;
mod model_io;
mod render;
mod sample;
mod scene;
mod scene_boxes;
mod settings;
mod to_capture;
mod train;
mod view;

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
    /// Write a volume's surface as a coloured triangle mesh (.glb, .gltf, .ply, .obj).
    Mesh(mesh::MeshArgs),
    /// Render a volume from the cameras of a transforms.json to EXR (R, G, B, A, Z) and PNG.
    Render(render::RenderArgs),
    /// Reconstruct a dataset's scene directly as one radiance volume (no networks): VDB/EXR, PSNR.
    Fit(fit::FitArgs),
    /// Render a built-in scene into an RGB-D transforms.json dataset.
    Scene(scene::SceneArgs),
    /// Turn a capture of your own photos (a COLMAP reconstruction or a nerfstudio capture) into a dataset.
    Import(import::ImportArgs),
    /// Train SinGRAV on a transforms.json RGB-D dataset (progress bar, log, checkpoints).
    Train(train::TrainArgs),
    /// Generate new scenes from a trained model: volumes, VDB/EXR on request, PNG views.
    Sample(sample::SampleArgs),
    /// Animate a generated scene (a smoothed random walk on the finer scales' noise), frame by frame.
    Animate(animate::AnimateArgs),
    /// Explore a trained model in the browser: a local web server drawing scenes live (WebGL2).
    View(view::ViewArgs),
    /// Edit a generated scene (remove, duplicate, move boxes) and harmonise it with the generators.
    Edit(edit::EditArgs),
    /// Compose objects of several generated scenes into one and harmonise it with the generators.
    Compose(compose::ComposeArgs),
    /// The whole pipeline: dataset of a built-in scene, training (`tiny`, or --preset), samples, pictures, VDB.
    Demo(demo::DemoArgs),
    /// Every quality number of a trained model: V*, patch and colour SWD, floaters, layout, objects, Diversity-MV, SIFID-MV.
    Eval(eval::EvalArgs),
    /// Check a device (a CUDA GPU) against the CPU and time training on it: one JSON line per check.
    DeviceCheck(device_check::DeviceCheckArgs),
}

/// Parses the command line, runs the subcommand and turns errors into a message and exit code 1.
pub fn run() -> ExitCode {
    // The process-wide speed settings (allocator, candle's pool, rayon's pool with this thread
    // in it), before any other thread exists.
    if let Err(e) = singrav::runtime::init(&singrav::runtime::RuntimeOptions::default()) {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(&args),
        Command::Export(args) => export::run(&args),
        Command::Mesh(args) => mesh::run(&args),
        Command::Render(args) => render::run(&args),
        Command::Fit(args) => fit::run(&args),
        Command::Import(args) => import::run(&args),
        Command::Scene(args) => scene::run(&args),
        Command::Train(args) => train::run(&args),
        Command::Sample(args) => sample::run(&args),
        Command::Animate(args) => animate::run(&args),
        Command::View(args) => view::run(&args),
        Command::Edit(args) => edit::run(&args),
        Command::Compose(args) => compose::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::DeviceCheck(args) => device_check::run(&args),
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
