//! `volgen export VOLUME --vdb out.vdb --exr-slices out_dir/ [--to-capture DATASET]`: write a
//! volume for Blender and other OpenVDB / EXR tools.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use radiance_volume::{RadianceVolume, VolumeSource};

use super::to_capture::CaptureFrame;

/// Arguments of `volgen export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A volume in volgen's safetensors format.
    volume: PathBuf,
    /// Write an OpenVDB file with a `density` float grid and a `color` vec3 grid.
    #[arg(long, value_name = "FILE")]
    vdb: Option<PathBuf>,
    /// Write one EXR per z slice (`NAME.0000.exr`, ...) and a `NAME.json` sidecar into this directory.
    #[arg(long, value_name = "DIR")]
    exr_slices: Option<PathBuf>,
    /// Base name of the EXR slice files (default: the volume file's stem).
    #[arg(long, value_name = "NAME")]
    exr_name: Option<String>,
    /// Write the VDB in the frame of the capture DATASET was imported from (`volgen import`
    /// records it): an affine grid transform, density per unit length of that frame. For
    /// volumes made in DATASET's frame (samples of a model trained on it, fits of it).
    #[arg(long, value_name = "DATASET")]
    to_capture: Option<PathBuf>,
    #[command(flatten)]
    encoding: Encoding,
}

/// How volumes are encoded in VDB and EXR files (shared by `export` and `sample`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Encoding {
    /// Store values as half floats (VDB and EXR).
    #[arg(long)]
    half: bool,
    /// Compress VDB leaf buffers with zlib.
    #[arg(long)]
    zlib: bool,
    /// Write only VDB leaves holding a voxel with density above this.
    #[arg(long, default_value_t = 0.0)]
    threshold: f32,
    /// Also write feature channels (beyond sigma, r, g, b) as VDB float grids.
    #[arg(long)]
    feature_grids: bool,
    /// Replace NaN and infinite values with this value instead of failing.
    #[arg(long, value_name = "VALUE")]
    replace_non_finite: Option<f32>,
}

/// Loads the volume and writes each requested format, printing what it wrote.
pub fn run(args: &ExportArgs) -> Result<()> {
    if args.vdb.is_none() && args.exr_slices.is_none() {
        bail!("nothing to export: give --vdb FILE and/or --exr-slices DIR");
    }
    if args.to_capture.is_some() && args.exr_slices.is_some() {
        bail!(
            "--to-capture applies to --vdb: EXR slices are axis-aligned in the volume's box, \
             which the capture's frame is turned against; export the slices without it"
        );
    }
    let volume = RadianceVolume::load_safetensors(&args.volume)?;
    if let Some(path) = &args.vdb {
        match &args.to_capture {
            None => write_vdb(&volume, path, &args.encoding),
            Some(dataset) => {
                let frame = CaptureFrame::of(dataset)?;
                let volume = frame.density_for(&volume)?;
                println!("writing the VDB {}", frame.describe(dataset));
                write_vdb_placed(&volume, path, &args.encoding, Some(frame.map))
            }
        }
        .with_context(|| format!("exporting {} to OpenVDB", args.volume.display()))?;
    }
    if let Some(dir) = &args.exr_slices {
        let name = match &args.exr_name {
            Some(name) => name.clone(),
            None => args
                .volume
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "volume".to_string()),
        };
        write_exr_slices(&volume, dir, &name, &args.encoding)
            .with_context(|| format!("exporting {} to EXR slices", args.volume.display()))?;
    }
    Ok(())
}

/// Writes `volume` as OpenVDB with the encoding `args`, saying what it wrote.
pub fn write_vdb(volume: &dyn VolumeSource, path: &std::path::Path, args: &Encoding) -> Result<()> {
    write_vdb_placed(volume, path, args, None)
}

/// [`write_vdb`], the grid placed by the affine map `placed` when given.
#[cfg(feature = "vdb")]
pub fn write_vdb_placed(
    volume: &dyn VolumeSource,
    path: &std::path::Path,
    args: &Encoding,
    placed: Option<glam::DMat4>,
) -> Result<()> {
    let mut writer = vdb_writer(volume, args);
    if let Some(map) = placed {
        writer = writer.placed(map);
    }
    let stats = writer.to_file(path)?;
    println!(
        "wrote {} ({} leaves, {} active voxels, {} bytes)",
        path.display(),
        stats.leaves,
        stats.active_voxels,
        stats.bytes
    );
    Ok(())
}

/// The bytes [`write_vdb`] writes for `volume` (for `volgen view`'s downloads).
#[cfg(feature = "vdb")]
pub fn vdb_bytes(volume: &dyn VolumeSource, args: &Encoding) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    vdb_writer(volume, args).to_writer(&mut bytes)?;
    Ok(bytes)
}

/// The OpenVDB writer of `volume` with the encoding `args`.
#[cfg(feature = "vdb")]
fn vdb_writer<'a>(
    volume: &'a dyn VolumeSource,
    args: &Encoding,
) -> radiance_volume::io::VdbWriter<'a> {
    radiance_volume::io::VdbWriter::new(volume)
        .half(args.half)
        .zlib(args.zlib)
        .threshold(args.threshold)
        .feature_grids(args.feature_grids)
        .replace_non_finite(args.replace_non_finite)
}

#[cfg(not(feature = "vdb"))]
pub fn vdb_bytes(_: &dyn VolumeSource, _: &Encoding) -> Result<Vec<u8>> {
    bail!("this volgen was built without the `vdb` feature; rebuild with `--features vdb`")
}

#[cfg(not(feature = "vdb"))]
pub fn write_vdb_placed(
    _: &dyn VolumeSource,
    _: &std::path::Path,
    _: &Encoding,
    _: Option<glam::DMat4>,
) -> Result<()> {
    bail!("this volgen was built without the `vdb` feature; rebuild with `--features vdb`")
}

#[cfg(feature = "exr")]
pub fn write_exr_slices(
    volume: &dyn VolumeSource,
    dir: &std::path::Path,
    name: &str,
    args: &Encoding,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let files = radiance_volume::io::ExrSlicesWriter::new(volume)
        .half(args.half)
        .replace_non_finite(args.replace_non_finite)
        .to_dir(dir, name)?;
    println!(
        "wrote {} files into {} ({name}.0000.exr ..., {name}.json)",
        files.len(),
        dir.display()
    );
    Ok(())
}

#[cfg(not(feature = "exr"))]
pub fn write_exr_slices(
    _: &dyn VolumeSource,
    _: &std::path::Path,
    _: &str,
    _: &Encoding,
) -> Result<()> {
    bail!("this volgen was built without the `exr` feature; rebuild with `--features exr`")
}
