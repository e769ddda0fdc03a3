//! `volgen import colmap SPARSE_DIR --images DIR --out DATASET [--masks DIR]`: a COLMAP
//! reconstruction of your own photos as a dataset `train` and `fit` read (no depth maps: they go
//! without the depth loss). `volgen import nerfstudio TRANSFORMS --out DATASET`: a nerfstudio
//! capture placed the same way.

use std::path::PathBuf;

use anyhow::{Context, Result};
use rgbd_dataset::placement::{Placement, UpFrom};
use rgbd_dataset::{colmap, nerfstudio};

/// Arguments of `volgen import`.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    #[command(subcommand)]
    source: Source,
}

/// Where the capture comes from.
#[derive(Debug, clap::Subcommand)]
enum Source {
    /// A COLMAP sparse model (`colmap mapper`'s output, e.g. sparse/0: cameras, images and
    /// points3D as .bin or .txt). Photos of SIMPLE_RADIAL, RADIAL, OPENCV and OPENCV_FISHEYE
    /// cameras are undistorted into pinhole ones; other lens models are refused (`colmap
    /// image_undistorter` undistorts them).
    Colmap(ColmapArgs),
    /// A nerfstudio capture (`ns-process-data`'s transforms.json, or its directory) with its
    /// sparse points (`ply_file_path`, or --points): written as a copy whose cameras are placed
    /// in the model's cube (the photos and masks copied as they are).
    Nerfstudio(NerfstudioArgs),
}

/// Arguments of `volgen import nerfstudio`.
#[derive(Debug, clap::Args)]
struct NerfstudioArgs {
    /// The capture's transforms.json, or its directory.
    transforms: PathBuf,
    /// The sparse points (PLY) that place the scene; default: the file's `ply_file_path`.
    #[arg(long, value_name = "FILE")]
    points: Option<PathBuf>,
    /// The dataset directory to write (images/, masks/, transforms.json).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Which way is up, as for `import colmap`.
    #[arg(long, value_name = "ground|cameras", default_value = "ground")]
    up: UpFrom,
}

/// Arguments of `volgen import colmap`.
#[derive(Debug, clap::Args)]
struct ColmapArgs {
    /// The sparse model's directory.
    sparse: PathBuf,
    /// The photos the model was made from (names as in its images file).
    #[arg(long, value_name = "DIR")]
    images: PathBuf,
    /// Foreground masks, one per photo with its name (or its name as .png), white on the
    /// scene; without them the photos' alpha channel is the foreground.
    #[arg(long, value_name = "DIR")]
    masks: Option<PathBuf>,
    /// The dataset directory to write (images/, transforms.json).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Which way is up: `ground`, the normal of the plane most sparse points lie on (the
    /// cameras' mean up where no credible plane is found), or `cameras`, the cameras' mean up
    /// direction (nerfstudio's `orientation_method up`).
    #[arg(long, value_name = "ground|cameras", default_value = "ground")]
    up: UpFrom,
}

/// Imports the capture and says where it went and how it was placed.
pub fn run(args: &ImportArgs) -> Result<()> {
    match &args.source {
        Source::Colmap(args) => run_colmap(args),
        Source::Nerfstudio(args) => run_nerfstudio(args),
    }
}

fn run_colmap(args: &ColmapArgs) -> Result<()> {
    let options = colmap::ImportOptions {
        images: args.images.clone(),
        masks: args.masks.clone(),
        up: args.up,
    };
    let summary = colmap::import(&args.sparse, &options, &args.out)
        .with_context(|| format!("importing the COLMAP model {}", args.sparse.display()))?;
    println!(
        "wrote {} photos at {} x {} (no depth maps): {}",
        summary.frames,
        summary.width,
        summary.height,
        summary.transforms.display()
    );
    for camera in &summary.undistorted {
        println!(
            "undistorted the photos of camera {} ({}) into a pinhole camera: focal length {:.2} x {:.2} \
             pixels (the photos' {:.2} x {:.2}), so that every pixel is seen",
            camera.id,
            camera.model,
            camera.pinhole[0],
            camera.pinhole[1],
            camera.photo[0],
            camera.photo[1]
        );
    }
    print_placement(&summary.placement, args.up);
    print_next(&args.out);
    Ok(())
}

fn run_nerfstudio(args: &NerfstudioArgs) -> Result<()> {
    let options = nerfstudio::ImportOptions {
        points: args.points.clone(),
        up: args.up,
    };
    let summary = nerfstudio::import(&args.transforms, &options, &args.out).with_context(|| {
        format!(
            "importing the nerfstudio capture {}",
            args.transforms.display()
        )
    })?;
    println!(
        "wrote {} frames placed in the model's cube (photos and masks copied, no depth maps): {}",
        summary.frames,
        summary.transforms.display()
    );
    println!(
        "read {} sparse points from {}",
        summary.points.1,
        summary.points.0.display()
    );
    print_placement(&summary.placement, args.up);
    print_next(&args.out);
    Ok(())
}

/// Says which way up the capture was turned, from what, and how it was centred and scaled.
fn print_placement(p: &Placement, asked: UpFrom) {
    let up = p.up_in_capture();
    println!(
        "placed the capture in the model's cube: up was ({:.3}, {:.3}, {:.3}) ({}), \
         centre ({:.3}, {:.3}, {:.3}), scale {:.4} (the foreground's visual hull across and the \
         sparse points up and down fill 1 / 1.1 of the half side)",
        up.x,
        up.y,
        up.z,
        match p.up {
            UpFrom::Ground => "the sparse points' ground plane",
            UpFrom::Cameras if asked == UpFrom::Ground =>
                "the cameras' mean: no credible ground plane in the sparse points",
            UpFrom::Cameras => "the cameras' mean",
        },
        p.centre.x,
        p.centre.y,
        p.centre.z,
        p.scale
    );
}

fn print_next(out: &std::path::Path) {
    println!(
        "next: volgen fit {0} --out fit.safetensors --holdout 10, or volgen train {0} --out runs/mine --preset tiny",
        out.display()
    );
}
