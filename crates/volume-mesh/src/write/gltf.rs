//! glTF 2.0: the JSON document by `gltf-json`, the buffer either embedded as a base64 data URI
//! (`.gltf`) or as the BIN chunk of a binary container (`.glb`, written here: a 12-byte header
//! and two chunks, as the specification lays them out).

use std::collections::BTreeMap;

use base64::Engine as _;
use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use super::y_up;
use crate::error::{invalid, Result};
use crate::mesh::Mesh;

/// `.glb`: the JSON chunk, padded with spaces to 4 bytes, then the BIN chunk, padded with 0s.
pub(super) fn glb(mesh: &Mesh) -> Result<Vec<u8>> {
    let bin = buffer_bytes(mesh);
    let json_text = document(mesh, bin.len(), None)?;
    let mut json_chunk = json_text.into_bytes();
    pad(&mut json_chunk, b' ');
    let mut bin_chunk = bin;
    pad(&mut bin_chunk, 0);
    let total = 12 + 8 + json_chunk.len() + 8 + bin_chunk.len();
    let total = u32::try_from(total)
        .map_err(|_| invalid("mesh", format!("{total} bytes exceed binary glTF's 4 GiB")))?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    for (kind, chunk) in [(b"JSON", &json_chunk), (b"BIN\0", &bin_chunk)] {
        out.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
        out.extend_from_slice(kind);
        out.extend_from_slice(chunk);
    }
    Ok(out)
}

/// `.gltf`: one JSON file, the buffer inline as `data:application/octet-stream;base64,...`.
pub(super) fn gltf(mesh: &Mesh) -> Result<Vec<u8>> {
    let bin = buffer_bytes(mesh);
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    Ok(document(mesh, bin.len(), Some(uri))?.into_bytes())
}

/// Zero- (or space-) padding to a multiple of 4 bytes, as glTF's chunks and views need.
fn pad(bytes: &mut Vec<u8>, with: u8) {
    while !bytes.len().is_multiple_of(4) {
        bytes.push(with);
    }
}

/// Positions, normals and colours (each `count x 3` f32; colours made linear, as glTF's
/// `COLOR_0` is), then the indices (u32): every part a multiple of 4 bytes, so the views need no
/// padding between them.
fn buffer_bytes(mesh: &Mesh) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(mesh.vertex_count() * 36 + mesh.triangles.len() * 12);
    let linear: Vec<[f32; 3]> = mesh.colours.iter().map(|c| c.map(srgb_to_linear)).collect();
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|&p| y_up(p)).collect();
    let normals: Vec<[f32; 3]> = mesh.normals.iter().map(|&n| y_up(n)).collect();
    for part in [&positions, &normals, &linear] {
        for v in part.iter().flatten() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    for i in mesh.triangles.iter().flatten() {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    bytes
}

/// The glTF JSON: one buffer, four views, four accessors, one triangle primitive whose
/// `COLOR_0` is the vertex colours, one node, one scene.
fn document(mesh: &Mesh, buffer_length: usize, uri: Option<String>) -> Result<String> {
    let mut root = json::Root {
        asset: json::Asset {
            generator: Some("volgen (volume-mesh)".into()),
            ..Default::default()
        },
        ..Default::default()
    };
    let buffer = root.push(json::Buffer {
        byte_length: USize64::from(buffer_length),
        extensions: Default::default(),
        extras: Default::default(),
        name: None,
        uri,
    });
    let vertices = mesh.vertex_count();
    let vec3_bytes = vertices * 12;
    let mut offset = 0;
    let mut view = |root: &mut json::Root, length: usize, target: json::buffer::Target| {
        let index = root.push(json::buffer::View {
            buffer,
            byte_length: USize64::from(length),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: Default::default(),
            extras: Default::default(),
            name: None,
            target: Some(Valid(target)),
        });
        offset += length;
        index
    };
    let views = [
        view(&mut root, vec3_bytes, json::buffer::Target::ArrayBuffer),
        view(&mut root, vec3_bytes, json::buffer::Target::ArrayBuffer),
        view(&mut root, vec3_bytes, json::buffer::Target::ArrayBuffer),
        view(
            &mut root,
            mesh.triangles.len() * 12,
            json::buffer::Target::ElementArrayBuffer,
        ),
    ];
    let accessor = |root: &mut json::Root,
                    view: json::Index<json::buffer::View>,
                    count: usize,
                    component: json::accessor::ComponentType,
                    type_: json::accessor::Type,
                    bounds: Option<([f32; 3], [f32; 3])>| {
        root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: Some(USize64(0)),
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: Default::default(),
            extras: Default::default(),
            type_: Valid(type_),
            min: bounds.map(|(min, _)| json::Value::from(min.to_vec())),
            max: bounds.map(|(_, max)| json::Value::from(max.to_vec())),
            name: None,
            normalized: false,
            sparse: None,
        })
    };
    use json::accessor::{ComponentType, Type};
    // POSITION must state its bounds.
    let positions = accessor(
        &mut root,
        views[0],
        vertices,
        ComponentType::F32,
        Type::Vec3,
        Some(bounds(mesh.positions.iter().map(|&p| y_up(p)))),
    );
    let normals = accessor(
        &mut root,
        views[1],
        vertices,
        ComponentType::F32,
        Type::Vec3,
        None,
    );
    let colours = accessor(
        &mut root,
        views[2],
        vertices,
        ComponentType::F32,
        Type::Vec3,
        None,
    );
    let indices = accessor(
        &mut root,
        views[3],
        mesh.triangles.len() * 3,
        ComponentType::U32,
        Type::Scalar,
        None,
    );
    let attributes = BTreeMap::from([
        (Valid(json::mesh::Semantic::Positions), positions),
        (Valid(json::mesh::Semantic::Normals), normals),
        (Valid(json::mesh::Semantic::Colors(0)), colours),
    ]);
    let primitive = json::mesh::Primitive {
        attributes,
        extensions: Default::default(),
        extras: Default::default(),
        indices: Some(indices),
        material: None,
        mode: Valid(json::mesh::Mode::Triangles),
        targets: None,
    };
    let mesh_index = root.push(json::Mesh {
        extensions: Default::default(),
        extras: Default::default(),
        name: Some("volume".into()),
        primitives: vec![primitive],
        weights: None,
    });
    let node = root.push(json::Node {
        mesh: Some(mesh_index),
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        extensions: Default::default(),
        extras: Default::default(),
        name: None,
        nodes: vec![node],
    });
    root.scene = Some(scene);
    json::serialize::to_string(&root).map_err(|e| {
        invalid(
            "mesh",
            format!("could not serialise the glTF document: {e}"),
        )
    })
}

/// The sRGB transfer function undone (IEC 61966-2-1): volgen's colours are the values of the
/// datasets' sRGB PNGs, glTF's vertex colours linear. Values outside [0, 1] are clamped.
///
/// ```
/// use volume_mesh::srgb_to_linear;
/// assert_eq!(srgb_to_linear(0.0), 0.0);
/// assert!((srgb_to_linear(0.5) - 0.214).abs() < 1e-3);
/// assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
/// ```
pub fn srgb_to_linear(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The per-axis minimum and maximum of `points`.
fn bounds(points: impl Iterator<Item = [f32; 3]>) -> ([f32; 3], [f32; 3]) {
    points.fold(
        ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
        |(min, max), p| {
            (
                [0, 1, 2].map(|i| min[i].min(p[i])),
                [0, 1, 2].map(|i| max[i].max(p[i])),
            )
        },
    )
}
