//! `volgen mesh VOLUME --out FILE.glb|.gltf|.ply|.obj [--level L] [--smooth N] [--decimate F]
//! [--to-capture DATASET]`: a volume's surface as a coloured triangle mesh, in the volume's own
//! coordinates (or its capture's); and the
//! `--mesh` outputs of the commands that write volumes (`--mesh-level`, `--mesh-smooth`,
//! `--mesh-decimate`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use radiance_volume::{RadianceVolume, VolumeSource};
use volume_mesh::{Mesh, MeshFormat, MeshOptions, DEFAULT_LEVEL};

use super::to_capture::CaptureFrame;

/// Arguments of `volgen mesh`.
#[derive(Debug, clap::Args)]
pub struct MeshArgs {
    /// A volume in volgen's safetensors format (`volgen sample`, `fit`, `edit` write them).
    volume: PathBuf,
    /// The mesh file; its extension picks the format: .glb, .gltf (buffer embedded), .ply
    /// (binary), .obj (with vertex colours).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// The surface's opacity across one voxel, in (0, 1): lower takes in thinner matter.
    #[arg(long, default_value_t = DEFAULT_LEVEL, value_parser = surface_level)]
    level: f32,
    /// Rounds of Taubin smoothing: rounds off the voxel steps (docs/formats.md measures what
    /// it changes).
    #[arg(long, value_name = "N", default_value_t = 0)]
    smooth: usize,
    /// Keep about this share of the triangles, in (0, 1] (meshoptimizer's edge collapses):
    /// 0.25 writes a file a quarter the size that matches the volume as well (docs/formats.md).
    #[arg(long, value_name = "F", default_value_t = 1.0, value_parser = triangle_share)]
    decimate: f32,
    /// Write the mesh in the frame of the capture DATASET was imported from (`volgen import`
    /// records it). For volumes made in DATASET's frame (samples of a model trained on it,
    /// fits of it).
    #[arg(long, value_name = "DATASET")]
    to_capture: Option<PathBuf>,
}

/// How the meshes of `--mesh` are made, on the commands that write volumes.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct MeshFlags {
    /// The meshes' surface level: opacity across one voxel, in (0, 1).
    #[arg(long, value_name = "L", default_value_t = DEFAULT_LEVEL, value_parser = surface_level)]
    pub mesh_level: f32,
    /// Rounds of Taubin smoothing of the meshes (as `volgen mesh --smooth`).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub mesh_smooth: usize,
    /// Keep about this share of the meshes' triangles, in (0, 1] (as `volgen mesh --decimate`).
    #[arg(long, value_name = "F", default_value_t = 1.0, value_parser = triangle_share)]
    pub mesh_decimate: f32,
}

impl Default for MeshFlags {
    /// The flags' defaults: the default level, no smoothing, every triangle.
    fn default() -> Self {
        Self {
            mesh_level: DEFAULT_LEVEL,
            mesh_smooth: 0,
            mesh_decimate: 1.0,
        }
    }
}

impl MeshFlags {
    /// The mesh these flags ask for.
    pub fn shape(&self) -> MeshShape {
        MeshShape {
            level: self.mesh_level,
            smooth: self.mesh_smooth,
            decimate: self.mesh_decimate,
        }
    }
}

/// What [`write_mesh`] makes of a volume: the surface at `level`, smoothed `smooth` rounds,
/// then decimated to the share `decimate` of its triangles.
#[derive(Debug, Clone, Copy)]
pub struct MeshShape {
    pub level: f32,
    pub smooth: usize,
    pub decimate: f32,
}

/// Parses a share of triangles (`--decimate`, `--mesh-decimate`): in (0, 1].
fn triangle_share(text: &str) -> std::result::Result<f32, String> {
    match text.parse::<f32>() {
        Ok(share) if share > 0.0 && share <= 1.0 => Ok(share),
        _ => Err(format!(
            "expected a share of the triangles in (0, 1], got {text:?}"
        )),
    }
}

/// Parses a surface level (`--level`, `--mesh-level`): an opacity strictly between 0 and 1.
pub fn surface_level(text: &str) -> std::result::Result<f32, String> {
    match text.parse::<f32>() {
        Ok(level) if level > 0.0 && level < 1.0 => Ok(level),
        _ => Err(format!(
            "expected an opacity across one voxel strictly between 0 and 1, got {text:?}"
        )),
    }
}

/// Refuses a mesh file name whose extension names no mesh format, before any work.
pub fn check_mesh_file(path: &Path) -> Result<()> {
    MeshFormat::from_path(path)?;
    Ok(())
}

/// Parses `--mesh`'s format by its extension (glb, gltf, ply, obj).
pub fn mesh_format(text: &str) -> std::result::Result<MeshFormat, String> {
    MeshFormat::from_extension(text).ok_or_else(|| {
        let known: Vec<&str> = MeshFormat::ALL.iter().map(|f| f.extension()).collect();
        format!("expected one of {}, got {text:?}", known.join(", "))
    })
}

/// Loads the volume, extracts its surface and writes the mesh, saying what it wrote.
pub fn run(args: &MeshArgs) -> Result<()> {
    check_mesh_file(&args.out)?;
    let volume = RadianceVolume::load_safetensors(&args.volume)?;
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    let shape = MeshShape {
        level: args.level,
        smooth: args.smooth,
        decimate: args.decimate,
    };
    let mut mesh =
        mesh_of(&volume, shape).with_context(|| format!("meshing {}", args.volume.display()))?;
    if let Some(dataset) = &args.to_capture {
        let frame = CaptureFrame::of(dataset)?;
        mesh = mesh
            .transformed(frame.map)
            .context("the capture's frame is not an invertible map")?;
        println!("writing the mesh {}", frame.describe(dataset));
    }
    mesh.write(&args.out)?;
    println!(
        "wrote {} vertices, {} triangles ({}, {} non-manifold edges, area {:.4}) at opacity \
         level {}: {}",
        mesh.vertex_count(),
        mesh.triangles.len(),
        if mesh.is_closed() { "closed" } else { "open" },
        mesh.non_manifold_edges(),
        mesh.area(),
        args.level,
        args.out.display()
    );
    Ok(())
}

/// The surface of `volume` as `shape` asks, written to `path` (its extension picks the
/// format).
pub fn write_mesh(volume: &dyn VolumeSource, path: &Path, shape: MeshShape) -> Result<Mesh> {
    let mesh = mesh_of(volume, shape)?;
    mesh.write(path)?;
    Ok(mesh)
}

/// The surface of `volume` as `shape` asks.
pub fn mesh_of(volume: &dyn VolumeSource, shape: MeshShape) -> Result<Mesh> {
    Ok(
        Mesh::from_source(volume, &MeshOptions { level: shape.level })?
            .smoothed(shape.smooth)
            .decimated(shape.decimate)?,
    )
}
