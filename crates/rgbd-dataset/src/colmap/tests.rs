use std::path::Path;

use glam::{DMat3, DMat4, DQuat, DVec3};

use super::binary::write;
use super::*;
use crate::placement::{cameras_up, ground_plane, up_direction, SparseCapture, UpFrom};

/// A model with two cameras, three images (one name with a space) and three points, in both
/// encodings.
fn model() -> ColmapModel {
    let cameras = [
        ColmapCamera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 640,
            height: 480,
            params: vec![500.0, 510.0, 320.5, 239.5],
        },
        ColmapCamera {
            id: 4,
            model: CameraModel::OpenCv,
            width: 800,
            height: 600,
            params: vec![700.0, 701.0, 400.0, 300.0, -0.1, 0.01, 0.001, -0.002],
        },
    ];
    let q = DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
    let images = vec![
        ColmapImage {
            id: 3,
            rotation: [1.0, 0.0, 0.0, 0.0],
            translation: [0.0, 0.0, 4.0],
            camera_id: 1,
            name: "a.jpg".into(),
        },
        ColmapImage {
            id: 7,
            rotation: [q.w, q.x, q.y, q.z],
            translation: [0.5, -0.25, 3.0],
            camera_id: 4,
            name: "sub dir/b c.png".into(),
        },
        ColmapImage {
            id: 9,
            rotation: [0.0, 1.0, 0.0, 0.0],
            translation: [1.0, 2.0, 3.0],
            camera_id: 1,
            name: "d.jpg".into(),
        },
    ];
    let points = (0..3)
        .map(|i| ColmapPoint {
            id: 10 + i,
            position: [i as f64 * 0.5, -1.0, 0.25],
            colour: [10 * i as u8, 200, 30],
            error: 0.75,
            track_length: 2,
        })
        .collect();
    ColmapModel {
        cameras: cameras.into_iter().map(|c| (c.id, c)).collect(),
        images,
        points,
    }
}

/// The model in COLMAP's text encoding (with its header comments).
fn write_text(model: &ColmapModel, dir: &Path) {
    let mut cameras = String::from("# Camera list with one line of data per camera:\n");
    for c in model.cameras.values() {
        let params: Vec<String> = c.params.iter().map(|p| format!("{p:?}")).collect();
        cameras += &format!(
            "{} {} {} {} {}\n",
            c.id,
            c.model,
            c.width,
            c.height,
            params.join(" ")
        );
    }
    let mut images = String::from("# Image list with two lines of data per image:\n");
    for (k, im) in model.images.iter().enumerate() {
        let [w, x, y, z] = im.rotation;
        let [tx, ty, tz] = im.translation;
        images += &format!(
            "{} {w:?} {x:?} {y:?} {z:?} {tx:?} {ty:?} {tz:?} {} {}\n",
            im.id, im.camera_id, im.name
        );
        // The first image's 2D points, the others' blank.
        images += if k == 0 {
            "1.5 2.5 -1 3.0 4.0 10\n"
        } else {
            "\n"
        };
    }
    let mut points = String::from("# 3D point list with one line of data per point:\n");
    for p in &model.points {
        let [x, y, z] = p.position;
        let [r, g, b] = p.colour;
        points += &format!(
            "{} {x:?} {y:?} {z:?} {r} {g} {b} {:?} 3 0 9 1\n",
            p.id, p.error
        );
    }
    std::fs::write(dir.join("cameras.txt"), cameras).unwrap();
    std::fs::write(dir.join("images.txt"), images).unwrap();
    std::fs::write(dir.join("points3D.txt"), points).unwrap();
}

fn write_binary(model: &ColmapModel, dir: &Path) {
    let [cameras, images, points] = write::files(model, 4);
    std::fs::write(dir.join("cameras.bin"), cameras).unwrap();
    std::fs::write(dir.join("images.bin"), images).unwrap();
    std::fs::write(dir.join("points3D.bin"), points).unwrap();
}

#[test]
fn both_encodings_read_back_the_same_model() {
    let model = model();
    let (text, binary) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    write_text(&model, text.path());
    write_binary(&model, binary.path());
    assert_eq!(ColmapModel::read(text.path()).unwrap(), model);
    assert_eq!(ColmapModel::read(binary.path()).unwrap(), model);
}

/// A world point projects to the same pixel through COLMAP's camera model (world to camera,
/// `u = fx x / z + cx`) and through the converted NeRF camera-to-world (camera looking down
/// -z, y up), as a pinhole renderer projects.
#[test]
fn the_nerf_pose_sees_points_where_colmap_does() {
    let model = model();
    let points = [DVec3::new(0.1, 0.2, 0.3), DVec3::new(-0.4, 0.3, -0.2)];
    for image in &model.images {
        let camera = &model.cameras[&image.camera_id];
        // Both test cameras' models start with fx, fy, cx, cy.
        let [fx, fy, cx, cy] = [0, 1, 2, 3].map(|k| camera.params[k]);
        let r = image.world_to_camera_rotation();
        let w2c_nerf: DMat4 = image.camera_to_world().inverse();
        for x in points {
            let c = r * x + DVec3::from(image.translation);
            let colmap = (fx * c.x / c.z + cx, fy * c.y / c.z + cy);
            let n = w2c_nerf.transform_point3(x);
            let depth = -n.z;
            let nerf = (cx + fx * n.x / depth, cy - fy * n.y / depth);
            assert!((colmap.0 - nerf.0).abs() < 1e-9 && (colmap.1 - nerf.1).abs() < 1e-9);
            assert!((depth - c.z).abs() < 1e-12);
        }
        // A rigid transform: orthonormal axes, determinant +1, centre where -R^T t is.
        let c2w = image.camera_to_world();
        assert!((c2w.determinant() - 1.0).abs() < 1e-12);
        assert!((c2w.w_axis.truncate() - image.centre()).length() < 1e-12);
        assert!((r * image.centre() + DVec3::from(image.translation)).length() < 1e-12);
    }
}

#[test]
fn bad_models_are_refused_naming_the_file_and_the_place() {
    let dir = tempfile::tempdir().unwrap();
    let err = ColmapModel::read(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("cameras.txt") && err.contains("missing"),
        "{err}"
    );

    let model = model();
    write_text(&model, dir.path());
    let cameras = dir.path().join("cameras.txt");
    for (line, words) in [
        ("1 EQUIRECT 640 480 1 2 3", vec!["line 1", "EQUIRECT"]),
        (
            "1 PINHOLE 640 480 500 500 320",
            vec!["line 1", "PINHOLE", "4 parameters"],
        ),
        (
            "1 PINHOLE 640 x 500 500 320 240",
            vec!["line 1", "HEIGHT", "`x`"],
        ),
    ] {
        std::fs::write(&cameras, format!("{line}\n4 PINHOLE 1 1 1 1 0 0\n")).unwrap();
        let err = ColmapModel::read(dir.path()).unwrap_err().to_string();
        for word in words {
            assert!(
                err.contains(word) && err.contains("cameras.txt"),
                "{line}: {err}"
            );
        }
    }
    // An image's camera that the cameras file lacks.
    std::fs::write(&cameras, "1 PINHOLE 640 480 500 500 320 240\n").unwrap();
    let err = ColmapModel::read(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("camera 4") && err.contains("sub dir/b c.png"),
        "{err}"
    );

    // Binary: every truncation names the file; a wrong model id and trailing bytes too.
    let bin = tempfile::tempdir().unwrap();
    let [cameras, images, points] = write::files(&model, 2);
    for (stem, bytes) in [
        ("cameras", &cameras),
        ("images", &images),
        ("points3D", &points),
    ] {
        for cut in [1, 8, bytes.len() / 2, bytes.len() - 1] {
            write_binary(&model, bin.path());
            std::fs::write(bin.path().join(format!("{stem}.bin")), &bytes[..cut]).unwrap();
            let err = ColmapModel::read(bin.path()).unwrap_err().to_string();
            assert!(
                err.contains(&format!("{stem}.bin")),
                "{stem} cut at {cut}: {err}"
            );
        }
    }
    write_binary(&model, bin.path());
    let mut bad = cameras.clone();
    bad[12..16].copy_from_slice(&42i32.to_le_bytes()); // the first camera's model id
    std::fs::write(bin.path().join("cameras.bin"), &bad).unwrap();
    let err = ColmapModel::read(bin.path()).unwrap_err().to_string();
    assert!(err.contains("model id 42"), "{err}");
    let mut long = points.clone();
    long.push(0);
    write_binary(&model, bin.path());
    std::fs::write(bin.path().join("points3D.bin"), &long).unwrap();
    let err = ColmapModel::read(bin.path()).unwrap_err().to_string();
    assert!(err.contains("1 bytes follow"), "{err}");
}

#[test]
fn models_know_their_names_ids_and_parameter_counts() {
    for (id, (model, name, count)) in MODELS.iter().enumerate() {
        assert_eq!(CameraModel::from_id(id as i32), Some(*model));
        assert_eq!(CameraModel::from_name(name), Some(*model));
        assert_eq!(model.parameter_count(), *count);
    }
    assert_eq!(CameraModel::from_id(-1), None);
    assert_eq!(CameraModel::from_id(11), None);
}

#[test]
fn every_undistorted_model_gives_its_intrinsics_and_lens() {
    let camera = |model: CameraModel, params: &[f64]| ColmapCamera {
        id: 1,
        model,
        width: 64,
        height: 48,
        params: params.to_vec(),
    };
    let brown = |radial: [f64; 4], tangential: [f64; 2]| Lens::BrownConrady { radial, tangential };
    let cases = [
        (
            camera(CameraModel::SimplePinhole, &[50.0, 32.0, 24.0]),
            ([50.0, 50.0, 32.0, 24.0], Lens::Pinhole),
        ),
        (
            camera(CameraModel::Pinhole, &[50.0, 51.0, 32.0, 24.0]),
            ([50.0, 51.0, 32.0, 24.0], Lens::Pinhole),
        ),
        (
            camera(CameraModel::SimpleRadial, &[50.0, 32.0, 24.0, -0.1]),
            (
                [50.0, 50.0, 32.0, 24.0],
                brown([-0.1, 0.0, 0.0, 0.0], [0.0; 2]),
            ),
        ),
        (
            camera(CameraModel::Radial, &[50.0, 32.0, 24.0, -0.1, 0.02]),
            (
                [50.0, 50.0, 32.0, 24.0],
                brown([-0.1, 0.02, 0.0, 0.0], [0.0; 2]),
            ),
        ),
        (
            camera(
                CameraModel::OpenCv,
                &[50.0, 51.0, 32.0, 24.0, -0.1, 0.02, 0.003, -0.004],
            ),
            (
                [50.0, 51.0, 32.0, 24.0],
                brown([-0.1, 0.02, 0.0, 0.0], [0.003, -0.004]),
            ),
        ),
        (
            camera(
                CameraModel::OpenCvFisheye,
                &[50.0, 51.0, 32.0, 24.0, 0.1, 0.02, 0.003, 0.004],
            ),
            (
                [50.0, 51.0, 32.0, 24.0],
                Lens::Fisheye {
                    radial: [0.1, 0.02, 0.003, 0.004],
                },
            ),
        ),
    ];
    for (camera, expected) in cases {
        assert_eq!(camera.lens(), Some(expected), "{}", camera.model);
    }
    let full = camera(CameraModel::FullOpenCv, &[0.0; 12]);
    assert_eq!(full.lens(), None);
}

/// A model whose cameras look down from a ring above a tilted ground (points on the plane and,
/// above it, on a few boxes' faces), and another whose points float on a sphere.
fn ground_model(ground: bool) -> (ColmapModel, DVec3) {
    let normal = DVec3::new(0.2, -0.1, 1.0).normalize();
    let (u, v) = normal.any_orthonormal_pair();
    let mut points = Vec::new();
    let mut push = |p: DVec3| {
        points.push(ColmapPoint {
            id: points.len() as u64 + 1,
            position: p.to_array(),
            colour: [0; 3],
            error: 0.5,
            track_length: 3,
        })
    };
    for i in 0..400 {
        let (a, b) = ((i % 20) as f64 / 10.0 - 1.0, (i / 20) as f64 / 10.0 - 1.0);
        if ground {
            push(a * u + b * v);
            // A box's side: upright on the ground, a tenth as many points.
            if i % 10 == 0 {
                push(0.3 * u + 0.2 * a * v + (0.2 + 0.2 * b) * normal);
            }
        } else {
            let (theta, phi) = (a * 3.0, b * 1.5);
            push(DVec3::new(
                theta.cos() * phi.cos(),
                theta.sin() * phi.cos(),
                phi.sin(),
            ));
        }
    }
    let mut images = Vec::new();
    for k in 0..8 {
        let angle = k as f64 * std::f64::consts::TAU / 8.0;
        let centre = 3.0 * normal + 2.5 * (angle.cos() * u + angle.sin() * v);
        // Looking at the origin, up along the normal: COLMAP's camera y points down.
        let forward = (-centre).normalize();
        let right = forward.cross(normal).normalize();
        let down = forward.cross(right);
        let w2c = DMat3::from_cols(right, down, forward).transpose();
        let q = DQuat::from_mat3(&w2c);
        images.push(ColmapImage {
            id: k + 1,
            rotation: [q.w, q.x, q.y, q.z],
            translation: (-(w2c * centre)).to_array(),
            camera_id: 1,
            name: format!("{k}.png"),
        });
    }
    let model = ColmapModel {
        cameras: BTreeMap::new(),
        images,
        points,
    };
    (model, normal)
}

#[test]
fn up_comes_from_the_ground_plane_where_there_is_one() {
    let (model, normal) = ground_model(true);
    let model = SparseCapture::from(&model);
    let (found, share) = ground_plane(&model).unwrap();
    assert!(found.angle_between(normal).to_degrees() < 0.01, "{found}");
    assert!((share - 400.0 / 440.0).abs() < 0.01, "{share}");
    let (up, from) = up_direction(&model, UpFrom::Ground).unwrap();
    assert_eq!((up, from), (found, UpFrom::Ground));
    // The cameras' mean up: their ring is even here, so it is the normal too (the ring tilts
    // every camera's up towards the middle by the same angle).
    let cameras = cameras_up(&model).unwrap();
    assert!(
        cameras.angle_between(normal).to_degrees() < 1e-6,
        "{cameras}"
    );
    assert_eq!(
        up_direction(&model, UpFrom::Cameras).unwrap().1,
        UpFrom::Cameras
    );
    // Points on a sphere hold no plane worth the name: the cameras' up is used.
    let (floating, _) = ground_model(false);
    let floating = SparseCapture::from(&floating);
    let (up, from) = up_direction(&floating, UpFrom::Ground).unwrap();
    assert_eq!(from, UpFrom::Cameras);
    assert!(up.angle_between(normal).to_degrees() < 1e-6);
    assert_eq!("cameras".parse::<UpFrom>(), Ok(UpFrom::Cameras));
    assert!("sky"
        .parse::<UpFrom>()
        .unwrap_err()
        .contains("ground or cameras"));
}
