//! Command-line parsing and dispatch; each subcommand lives in its own module.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod export;
mod info;
mod render;

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
}

/// Parses the command line, runs the subcommand and turns errors into a message and exit code 1.
pub fn run() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(&args),
        Command::Export(args) => export::run(&args),
        Command::Render(args) => render::run(&args),
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
