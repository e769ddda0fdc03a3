//! Meshes of known volumes against hand-derived areas, volumes and colours, and the files read
//! back by independent readers (the `gltf`, `tobj` and `ply-rs` crates).

use std::f64::consts::PI;

use radiance_volume::{Aabb, GridDims, RadianceVolume, Resampled, SlabLimit};
use volume_mesh::{srgb_to_linear, Error, Mesh, MeshOptions, DEFAULT_LEVEL};

/// Grid edge of the test volumes.
const N: usize = 48;

/// A volume over `aabb` whose opacity across a voxel falls linearly from twice the default
/// level to 0 over two voxels across the surface `distance(p) = 0` (negative inside), so the
/// default level lies on it and both voxel centres of every edge the surface crosses are on
/// the linear ramp; colour from `colour(p)`.
fn smooth(
    aabb: Aabb,
    distance: impl Fn(glam::Vec3) -> f32 + Sync,
    colour: impl Fn(glam::Vec3) -> [f32; 3] + Sync,
) -> RadianceVolume {
    let voxel = (aabb.max - aabb.min).x / N as f32;
    RadianceVolume::from_fn(GridDims::cube(N), aabb, 4, |p, out| {
        let opacity = (DEFAULT_LEVEL * (1.0 - distance(p) / voxel)).clamp(0.0, 0.999);
        out[0] = -(1.0 - opacity).ln() / voxel;
        out[1..4].copy_from_slice(&colour(p));
    })
    .unwrap()
}

fn ball(radius: f32) -> RadianceVolume {
    smooth(
        Aabb::CUBE,
        |p| p.length() - radius,
        |p| {
            if p.z > 0.0 {
                [0.9, 0.1, 0.1]
            } else {
                [0.1, 0.1, 0.9]
            }
        },
    )
}

#[test]
fn a_ball_gives_a_closed_sphere_of_the_right_area_volume_and_colours() {
    let r = 0.6f64;
    let mesh = Mesh::from_volume(&ball(r as f32), &MeshOptions::default()).unwrap();
    assert!(mesh.is_closed());
    assert_eq!(mesh.non_manifold_edges(), 0);
    let area = 4.0 * PI * r * r;
    let volume = 4.0 / 3.0 * PI * r.powi(3);
    assert!(
        (mesh.area() / area - 1.0).abs() < 0.02,
        "area {} against {area}",
        mesh.area()
    );
    assert!(
        (mesh.enclosed_volume() / volume - 1.0).abs() < 0.02,
        "volume {} against {volume}",
        mesh.enclosed_volume()
    );
    for ((p, n), c) in mesh.positions.iter().zip(&mesh.normals).zip(&mesh.colours) {
        let p = glam::Vec3::from(*p);
        // On the sphere to a tenth of a voxel, the normal pointing out.
        assert!((p.length() - r as f32).abs() < 0.1 * 2.0 / N as f32, "{p}");
        assert!(
            glam::Vec3::from(*n).dot(p.normalize()) > 0.95,
            "{n:?} at {p}"
        );
        // Away from the equator, the hemisphere's colour exactly.
        if p.z.abs() > 0.1 {
            let want = if p.z > 0.0 { 0.9 } else { 0.1 };
            assert!((c[0] - want).abs() < 1e-5, "{c:?} at {p}");
        }
    }
}

/// A source read block by block gives the mesh of the whole volume, whether it is read in the
/// usual slabs or one plane at a time (the colours of vertices between two slabs included),
/// and a volume computed on a finer grid the mesh of that grid held whole.
#[test]
fn meshes_of_sources_read_in_slabs_are_the_meshes_of_the_whole() {
    let v = ball(0.6);
    let whole = Mesh::from_volume(&v, &MeshOptions::default()).unwrap();
    let thin = Mesh::from_source(&SlabLimit::new(&v, 1), &MeshOptions::default()).unwrap();
    assert_eq!(thin, whole);

    let fine = Resampled::finer(v, 2).unwrap();
    let held = Mesh::from_volume(&fine.to_volume().unwrap(), &MeshOptions::default()).unwrap();
    let streamed =
        Mesh::from_source(&SlabLimit::new(&fine, 5000), &MeshOptions::default()).unwrap();
    assert_eq!(streamed, held);
    assert!(held.triangles.len() > 3 * whole.triangles.len());
}

#[test]
fn a_box_in_a_scene_box_lands_in_the_scene_coordinates() {
    // A box of half-size (0.5, 0.3, 0.4) round (2, -1, 0.5), in a scene box of edge 4.
    let aabb = Aabb::try_new(
        glam::Vec3::new(0.0, -3.0, -1.5),
        glam::Vec3::new(4.0, 1.0, 2.5),
    )
    .unwrap();
    let centre = glam::Vec3::new(2.0, -1.0, 0.5);
    let half = glam::Vec3::new(0.5, 0.3, 0.4);
    let volume = smooth(
        aabb,
        |p| {
            // The exact signed distance of a box.
            let q = (p - centre).abs() - half;
            q.max(glam::Vec3::ZERO).length() + q.max_element().min(0.0)
        },
        |_| [0.5; 3],
    );
    let mesh = Mesh::from_volume(&volume, &MeshOptions::default()).unwrap();
    assert!(mesh.is_closed());
    let size = 2.0 * half.as_dvec3();
    let volume_want = size.x * size.y * size.z;
    let area_want = 2.0 * (size.x * size.y + size.y * size.z + size.z * size.x);
    // Surface Nets rounds the edges to about a voxel's radius: each edge of length L loses at
    // most (2 - pi / 2) x voxel x L of area (a quarter cylinder for two flat strips), and a
    // little volume.
    let voxel = 4.0 / N as f64;
    let edges = 4.0 * (size.x + size.y + size.z);
    let rounding = (2.0 - PI / 2.0) * voxel * edges;
    let area = mesh.area();
    assert!(
        area < area_want * 1.01 && area > area_want - rounding,
        "{area} of {area_want}"
    );
    assert!((mesh.enclosed_volume() / volume_want - 1.0).abs() < 0.05);
    let (min, max) = mesh.positions.iter().fold(
        (glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min((*p).into()), hi.max((*p).into())),
    );
    let voxel = voxel as f32;
    assert!(
        (min - (centre - half)).abs().max_element() < 0.5 * voxel,
        "{min}"
    );
    assert!(
        (max - (centre + half)).abs().max_element() < 0.5 * voxel,
        "{max}"
    );
}

#[test]
fn matter_touching_the_box_still_gives_a_closed_surface() {
    // Solid everywhere: the surface is the box itself (through the outer voxels' centres'
    // halfway point to the padding).
    let full = RadianceVolume::from_fn(GridDims::cube(8), Aabb::CUBE, 4, |_, out| {
        out[0] = 100.0;
        out[1..4].fill(0.3);
    })
    .unwrap();
    let mesh = Mesh::from_volume(&full, &MeshOptions::default()).unwrap();
    assert!(mesh.is_closed());
    assert!(mesh.enclosed_volume() > 0.0);
}

#[test]
fn two_cubes_touching_along_an_edge_close_with_four_triangles_there() {
    // Two solid voxels meeting along one edge only (diagonal neighbours in the x-y plane).
    let n = 4;
    let diagonal = RadianceVolume::from_fn(GridDims::cube(n), Aabb::CUBE, 4, |p, out| {
        let cell = ((p + 1.0) / 2.0 * n as f32).floor();
        let solid =
            cell.z == 1.0 && ((cell.x, cell.y) == (1.0, 1.0) || (cell.x, cell.y) == (2.0, 2.0));
        out[0] = if solid { 100.0 } else { 0.0 };
    })
    .unwrap();
    let mesh = Mesh::from_volume(&diagonal, &MeshOptions::default()).unwrap();
    assert!(mesh.is_closed());
    assert_eq!(mesh.non_manifold_edges(), 1);
    // An open square is neither.
    let square = Mesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        colours: vec![[1.0; 3]; 4],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    };
    assert!(!square.is_closed());
}

#[test]
fn files_read_back_by_independent_readers() {
    let mesh = Mesh::from_volume(&ball(0.5), &MeshOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // glTF, binary and embedded, by the `gltf` crate (which validates the document).
    for name in ["ball.glb", "ball.gltf"] {
        let path = dir.path().join(name);
        mesh.write(&path).unwrap();
        let (document, buffers, _) = gltf::import(&path).unwrap();
        let primitive = document
            .meshes()
            .next()
            .unwrap()
            .primitives()
            .next()
            .unwrap();
        let reader = primitive.reader(|b| Some(&buffers[b.index()]));
        // y up in the file: volgen's (x, y, z) is glTF's (x, z, -y).
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .unwrap()
            .map(|[x, y, z]| [x, -z, y])
            .collect();
        let colours: Vec<[f32; 3]> = reader.read_colors(0).unwrap().into_rgb_f32().collect();
        let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(positions, mesh.positions, "{name}");
        let linear: Vec<[f32; 3]> = mesh.colours.iter().map(|c| c.map(srgb_to_linear)).collect();
        assert_eq!(colours, linear, "{name}");
        assert_eq!(indices.len(), mesh.triangles.len() * 3, "{name}");
        assert_eq!(&indices[..3], &mesh.triangles[0], "{name}");
        assert_eq!(reader.read_normals().unwrap().count(), mesh.vertex_count());
    }
    // OBJ with vertex colours, by `tobj`.
    let path = dir.path().join("ball.obj");
    mesh.write(&path).unwrap();
    let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions::default()).unwrap();
    let obj = &models[0].mesh;
    assert_eq!(obj.positions.len(), mesh.vertex_count() * 3);
    assert_eq!(obj.indices.len(), mesh.triangles.len() * 3);
    // The first face's corners, wherever the reader puts its vertices.
    for (corner, &i) in obj.indices[..3].iter().zip(&mesh.triangles[0]) {
        let at = *corner as usize * 3;
        let [x, y, z] = mesh.positions[i as usize];
        assert_eq!(obj.positions[at..at + 3], [x, z, -y]);
        let colour = &obj.vertex_color[at..at + 3];
        let want = mesh.colours[i as usize];
        assert!(colour.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-4));
    }
    // Binary PLY, by `ply-rs`.
    let path = dir.path().join("ball.ply");
    mesh.write(&path).unwrap();
    let parser = ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut std::io::BufReader::new(
            std::fs::File::open(&path).unwrap(),
        ))
        .unwrap();
    let vertices = &ply.payload["vertex"];
    let faces = &ply.payload["face"];
    assert_eq!(vertices.len(), mesh.vertex_count());
    assert_eq!(faces.len(), mesh.triangles.len());
    use ply_rs::ply::Property;
    match (&vertices[3]["y"], &vertices[3]["red"]) {
        (Property::Float(y), Property::UChar(red)) => {
            assert_eq!(*y, mesh.positions[3][1]);
            assert_eq!(*red, (mesh.colours[3][0] * 255.0).round() as u8);
        }
        other => panic!("unexpected vertex properties {other:?}"),
    }
    match &faces[0]["vertex_indices"] {
        Property::ListUInt(ids) => assert_eq!(ids[..], mesh.triangles[0]),
        other => panic!("unexpected face property {other:?}"),
    }
}

#[test]
fn srgb_decoding_matches_the_standard() {
    // IEC 61966-2-1: 0 and 1 fixed, the linear toe below 0.04045, 0.5 -> 0.2140.
    assert_eq!(srgb_to_linear(0.0), 0.0);
    assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
    assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-7);
    assert!((srgb_to_linear(0.5) - 0.21404).abs() < 1e-4);
}

#[test]
fn bad_arguments_and_empty_volumes_are_refused_by_name() {
    let empty = RadianceVolume::from_fn(GridDims::cube(4), Aabb::CUBE, 4, |_, _| {}).unwrap();
    let err = Mesh::from_volume(&empty, &MeshOptions::default()).unwrap_err();
    assert!(matches!(err, Error::NoSurface { .. }), "{err}");
    assert!(err.to_string().contains("--level"), "{err}");
    let volume = ball(0.5);
    for level in [0.0, 1.0, -0.5, f32::NAN] {
        let err = Mesh::from_volume(&volume, &MeshOptions { level }).unwrap_err();
        assert!(err.to_string().contains("`level`"), "{err}");
    }
    let mesh = Mesh::from_volume(&volume, &MeshOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let err = mesh.write(&dir.path().join("ball.stl")).unwrap_err();
    assert!(err.to_string().contains("ball.stl") && err.to_string().contains(".glb"));
    // Nothing is left behind by a refused write.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    let err = Mesh::default()
        .write(&dir.path().join("empty.glb"))
        .unwrap_err();
    assert!(matches!(err, Error::NoSurface { .. }), "{err}");
}

#[test]
fn a_lower_level_takes_in_thinner_matter() {
    // Fog of opacity 0.3 per voxel round a dense core: a level above the fog sees the core only.
    let voxel = 2.0 / N as f32;
    let fog = RadianceVolume::from_fn(GridDims::cube(N), Aabb::CUBE, 4, |p, out| {
        let opacity: f32 = if p.length() < 0.3 {
            0.99
        } else if p.length() < 0.7 {
            0.3
        } else {
            0.0
        };
        out[0] = -(1.0 - opacity).ln() / voxel;
        out[1..4].fill(0.5);
    })
    .unwrap();
    let core = Mesh::from_volume(&fog, &MeshOptions { level: 0.5 }).unwrap();
    let cloud = Mesh::from_volume(&fog, &MeshOptions { level: 0.2 }).unwrap();
    let volume = |r: f64| 4.0 / 3.0 * PI * r.powi(3);
    assert!((core.enclosed_volume() / volume(0.3) - 1.0).abs() < 0.1);
    assert!((cloud.enclosed_volume() / volume(0.7) - 1.0).abs() < 0.1);
}
