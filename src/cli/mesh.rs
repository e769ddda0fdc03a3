//! `volgen mesh VOLUME --out FILE.glb|.gltf|.ply|.obj [--level L]`: a volume's surface as a
//! coloured triangle mesh, in the volume's own coordinates; and the `--mesh` outputs of the
//! commands that write volumes.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use radiance_volume::RadianceVolume;
use volume_mesh::{Mesh, MeshFormat, MeshOptions, DEFAULT_LEVEL};

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
    let mesh = write_mesh(&volume, &args.out, args.level)
        .with_context(|| format!("meshing {}", args.volume.display()))?;
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

/// The surface of `volume` at opacity `level`, written to `path` (its extension picks the
/// format).
pub fn write_mesh(volume: &RadianceVolume, path: &Path, level: f32) -> Result<Mesh> {
    let mesh = Mesh::from_volume(volume, &MeshOptions { level })?;
    mesh.write(path)?;
    Ok(mesh)
}
