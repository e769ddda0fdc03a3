//! `nerfstudio::read_points` against PLY files written by an independent writer (the ply-rs
//! crate): every encoding, coordinates of mixed types among other properties, an element of
//! fixed-size rows before the points and one with lists after them.

use glam::DVec3;
use ply_rs::ply::{
    Addable, DefaultElement, ElementDef, Encoding, Ply, Property, PropertyDef, PropertyType,
    ScalarType,
};
use rgbd_dataset::nerfstudio::read_points;

fn scalar(name: &str, kind: ScalarType) -> PropertyDef {
    PropertyDef::new(name.to_owned(), PropertyType::Scalar(kind))
}

fn element(name: &str, properties: Vec<PropertyDef>) -> ElementDef {
    let mut element = ElementDef::new(name.to_owned());
    for p in properties {
        element.properties.add(p);
    }
    element
}

fn row(values: Vec<(&str, Property)>) -> DefaultElement {
    let mut row = DefaultElement::new();
    for (name, value) in values {
        row.insert(name.to_owned(), value);
    }
    row
}

/// A PLY of `points` in `encoding`: a camera element before them, faces after.
fn written(points: &[DVec3], encoding: Encoding) -> Vec<u8> {
    let mut ply = Ply::<DefaultElement>::new();
    ply.header.encoding = encoding;
    ply.header.elements.add(element(
        "camera",
        vec![
            scalar("id", ScalarType::Int),
            scalar("f", ScalarType::Double),
        ],
    ));
    ply.header.elements.add(element(
        "vertex",
        vec![
            scalar("red", ScalarType::UChar),
            scalar("x", ScalarType::Double),
            scalar("y", ScalarType::Float),
            scalar("z", ScalarType::Double),
            scalar("confidence", ScalarType::Short),
        ],
    ));
    ply.header.elements.add(element(
        "face",
        vec![PropertyDef::new(
            "vertex_indices".to_owned(),
            PropertyType::List(ScalarType::UChar, ScalarType::Int),
        )],
    ));
    let camera = row(vec![
        ("id", Property::Int(3)),
        ("f", Property::Double(500.0)),
    ]);
    ply.payload.insert("camera".to_owned(), vec![camera]);
    let vertices = points
        .iter()
        .map(|p| {
            row(vec![
                ("red", Property::UChar(200)),
                ("x", Property::Double(p.x)),
                ("y", Property::Float(p.y as f32)),
                ("z", Property::Double(p.z)),
                ("confidence", Property::Short(-7)),
            ])
        })
        .collect();
    ply.payload.insert("vertex".to_owned(), vertices);
    let face = row(vec![("vertex_indices", Property::ListInt(vec![0, 1, 2]))]);
    ply.payload.insert("face".to_owned(), vec![face]);
    let mut bytes = Vec::new();
    ply_rs::writer::Writer::new()
        .write_ply(&mut bytes, &mut ply)
        .unwrap();
    bytes
}

#[test]
fn points_written_by_ply_rs_read_back_in_every_encoding() {
    let points = [
        DVec3::new(1.25, -2.5, 3.0),
        DVec3::new(-0.125, 0.5, 1e-3),
        DVec3::new(1e3, 7.0, -4.75),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (name, encoding) in [
        ("ascii", Encoding::Ascii),
        ("little", Encoding::BinaryLittleEndian),
        ("big", Encoding::BinaryBigEndian),
    ] {
        let path = dir.path().join(format!("{name}.ply"));
        let bytes = written(&points, encoding);
        std::fs::write(&path, &bytes).unwrap();
        let read = read_points(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(read.len(), points.len(), "{name}");
        for (r, p) in read.iter().zip(&points) {
            // y went through f32; ASCII through ply-rs's decimal text.
            assert!(
                (*r - *p).abs().max_element() < 1e-6 * (1.0 + p.abs().max_element()),
                "{name}: {r} vs {p}"
            );
        }
    }
}
