//! How closely a volume's mesh (`volume_mesh::Mesh::from_volume`) looks like the volume: both
//! seen from a dataset's cameras, the mesh by a z-buffer rasteriser of its triangles with their
//! vertex colours interpolated (unlit: a radiance volume's colour is what a camera sees), the
//! volume by volgen's renderer, both over a white background. Per surface level: the silhouette
//! IoU (mesh coverage against volume opacity >= 1/2) and the colour PSNR of the whole images;
//! at the default level also after `--smooth` and `--decimate`, with the `.glb` file's size.
//! Used for docs/formats.md ("Meshes") and docs/journal/2026-12-arrangement.md.
//!
//! `cargo run --release -p research --example mesh_accuracy -- VOLUME.safetensors DATASET [VIEWS]`
//! (default 8 views spread over the dataset's frames, at the dataset's resolution).

use glam::{Vec3, Vec4Swizzles};
use radiance_volume::RadianceVolume;
use rgbd_dataset::Dataset;
use volrender::{render_image, Camera, RenderConfig, Sampler};
use volume_mesh::{Mesh, MeshOptions};

/// Surface levels compared (opacity across one voxel; 0.25 is `volgen mesh`'s default).
const LEVELS: [f32; 5] = [0.1, 0.25, 0.5, 0.75, 0.9];
/// Smoothing rounds compared at the default level (`--smooth`).
const SMOOTHING: [usize; 3] = [2, 5, 10];
/// Shares of the triangles compared at the default level (`--decimate`).
const DECIMATION: [f32; 3] = [0.5, 0.25, 0.1];

/// A rasterised mesh: colour over white, and whether each pixel is covered.
struct Raster {
    rgb: Vec<[f32; 3]>,
    covered: Vec<bool>,
}

/// Draws `mesh` from `camera`: each triangle's pixels whose centres it covers, nearest first
/// (depth along the view axis, interpolated in screen space), colours interpolated by the
/// screen-space barycentric weights.
fn rasterise(mesh: &Mesh, camera: &Camera) -> Raster {
    let (w, h) = (camera.width, camera.height);
    let w2c = camera.c2w.inverse();
    // Screen position (col, row) and depth of every vertex; None behind the camera.
    let projected: Vec<Option<(f32, f32, f32)>> = mesh
        .positions
        .iter()
        .map(|p| {
            let c = (w2c * Vec3::from(*p).extend(1.0)).xyz();
            let depth = -c.z;
            (depth > 1e-4).then(|| {
                let col = camera.cx + camera.fx * c.x / depth;
                let row = camera.cy - camera.fy * c.y / depth;
                (col, row, depth)
            })
        })
        .collect();
    let mut rgb = vec![[1.0f32; 3]; w * h];
    let mut covered = vec![false; w * h];
    let mut nearest = vec![f32::INFINITY; w * h];
    for tri in &mesh.triangles {
        let corners: Option<Vec<(f32, f32, f32)>> =
            tri.iter().map(|&i| projected[i as usize]).collect();
        let Some(c) = corners else { continue };
        let area = (c[1].0 - c[0].0) * (c[2].1 - c[0].1) - (c[2].0 - c[0].0) * (c[1].1 - c[0].1);
        if area.abs() < 1e-12 {
            continue;
        }
        let (min_col, max_col) = pixel_span(c.iter().map(|v| v.0), w);
        let (min_row, max_row) = pixel_span(c.iter().map(|v| v.1), h);
        for row in min_row..max_row {
            for col in min_col..max_col {
                let (x, y) = (col as f32 + 0.5, row as f32 + 0.5);
                let edge = |a: (f32, f32, f32), b: (f32, f32, f32)| {
                    (b.0 - a.0) * (y - a.1) - (x - a.0) * (b.1 - a.1)
                };
                let b0 = edge(c[1], c[2]) / area;
                let b1 = edge(c[2], c[0]) / area;
                let b2 = 1.0 - b0 - b1;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                let depth = b0 * c[0].2 + b1 * c[1].2 + b2 * c[2].2;
                let pixel = row * w + col;
                if depth < nearest[pixel] {
                    nearest[pixel] = depth;
                    covered[pixel] = true;
                    let colour = |k: usize| mesh.colours[tri[k] as usize];
                    rgb[pixel] = [0, 1, 2]
                        .map(|ch| b0 * colour(0)[ch] + b1 * colour(1)[ch] + b2 * colour(2)[ch]);
                }
            }
        }
    }
    Raster { rgb, covered }
}

/// The pixels `0..limit` whose centres a triangle with these screen coordinates (along one
/// axis) may cover: from the floor of the least to the ceiling of the greatest.
fn pixel_span(coordinates: impl Iterator<Item = f32> + Clone, limit: usize) -> (usize, usize) {
    let low = coordinates.clone().fold(f32::INFINITY, f32::min);
    let high = coordinates.fold(f32::NEG_INFINITY, f32::max);
    (
        low.floor().max(0.0) as usize,
        (high.ceil() as usize).min(limit),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: mesh_accuracy VOLUME.safetensors DATASET [VIEWS]";
    let volume = RadianceVolume::load_safetensors(args.first().expect(usage)).unwrap();
    let data = Dataset::load(args.get(1).expect(usage).as_ref(), [1.0; 3]).unwrap();
    let views: usize = args.get(2).map_or(8, |v| v.parse().unwrap());
    let cameras: Vec<Camera> = (0..views)
        .map(|i| data.cameras()[i * data.len() / views])
        .collect();
    let config = RenderConfig::default()
        .with_sampler(Sampler::Uniform { samples: 256 })
        .with_background([1.0; 3]);
    let rendered: Vec<volrender::Image> = cameras
        .iter()
        .map(|camera| render_image(&volume, camera, &config).unwrap())
        .collect();
    println!(
        "| mesh | vertices | triangles | .glb bytes | silhouette IoU | colour PSNR (dB) | colour PSNR where both cover (dB) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let default_level = MeshOptions::default().level;
    for level in LEVELS {
        let mesh = Mesh::from_volume(&volume, &MeshOptions { level }).unwrap();
        print_row(&format!("level {level}"), &mesh, &cameras, &rendered);
        if level != default_level {
            continue;
        }
        // At the default level, what smoothing and decimation change.
        for iterations in SMOOTHING {
            let name = format!("level {level}, --smooth {iterations}");
            print_row(&name, &mesh.smoothed(iterations), &cameras, &rendered);
        }
        for fraction in DECIMATION {
            let name = format!("level {level}, --decimate {fraction}");
            print_row(
                &name,
                &mesh.decimated(fraction).unwrap(),
                &cameras,
                &rendered,
            );
        }
    }
}

/// One row of the table: `mesh` rasterised from `cameras` against the volume's renderings.
fn print_row(name: &str, mesh: &Mesh, cameras: &[Camera], rendered: &[volrender::Image]) {
    let (mut both, mut either, mut squared, mut pixels) = (0usize, 0usize, 0f64, 0usize);
    let (mut squared_both, mut channels_both) = (0f64, 0usize);
    for (camera, image) in cameras.iter().zip(rendered) {
        let raster = rasterise(mesh, camera);
        for (i, (&mesh_covers, colour)) in raster.covered.iter().zip(&raster.rgb).enumerate() {
            let volume_covers = image.opacity[i] >= 0.5;
            both += usize::from(mesh_covers && volume_covers);
            either += usize::from(mesh_covers || volume_covers);
            let error: f64 = (0..3)
                .map(|c| f64::from(colour[c] - image.rgb[i][c]).powi(2))
                .sum();
            squared += error;
            pixels += 3;
            if mesh_covers && volume_covers {
                squared_both += error;
                channels_both += 3;
            }
        }
    }
    let file = std::env::temp_dir().join(format!("mesh_accuracy_{}.glb", std::process::id()));
    mesh.write(&file).unwrap();
    let bytes = std::fs::metadata(&file).unwrap().len();
    std::fs::remove_file(&file).unwrap();
    let psnr = |sum: f64, n: usize| 10.0 * (n as f64 / sum).log10();
    println!(
        "| {name} | {} | {} | {bytes} | {:.3} | {:.2} | {:.2} |",
        mesh.vertex_count(),
        mesh.triangles.len(),
        both as f64 / either.max(1) as f64,
        psnr(squared, pixels),
        psnr(squared_both, channels_both)
    );
}
