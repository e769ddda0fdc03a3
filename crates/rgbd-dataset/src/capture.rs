//! The fields of a photographed capture's `transforms.json` beyond the NeRF core, as nerfstudio
//! (`ns-process-data`) writes them: the lens (`camera_model` with the distortion coefficients
//! `k1`..`k4`, `p1`, `p2`) and a foreground mask per frame (`mask_path`). Each may be given at
//! the top level or per frame (a frame's value wins), as the intrinsics are.

use serde_json::Value;

use crate::lens::Lens;

/// The `camera_model` values volgen reads, for messages.
const CAMERA_MODELS: &str = "\"OPENCV\", \"OPENCV_FISHEYE\", \"PINHOLE\" or \"SIMPLE_PINHOLE\"";

/// A distortion coefficient of the frame (0 when absent).
fn coefficient(root: &Value, frame: &Value, key: &str) -> Result<f64, String> {
    match frame.get(key).or_else(|| root.get(key)) {
        None | Some(Value::Null) => Ok(0.0),
        Some(v) => v
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("field `{key}` must be a finite number, got {v}")),
    }
}

/// The frame's lens: `camera_model` (nerfstudio's default, `OPENCV`, when absent) with its
/// coefficients. Errors name the field: an unknown model, a coefficient that is not a number,
/// or distortion coefficients on a pinhole model (which would otherwise be dropped silently).
pub(super) fn frame_lens(root: &Value, frame: &Value) -> Result<Lens, String> {
    let model = match frame
        .get("camera_model")
        .or_else(|| root.get("camera_model"))
    {
        None => "OPENCV",
        Some(Value::String(name)) => name.as_str(),
        Some(other) => {
            return Err(format!(
                "field `camera_model` must be a string ({CAMERA_MODELS}), got {other}"
            ))
        }
    };
    let k = |key| coefficient(root, frame, key);
    let radial = [k("k1")?, k("k2")?, k("k3")?, k("k4")?];
    let tangential = [k("p1")?, k("p2")?];
    match model {
        "OPENCV" => Ok(Lens::BrownConrady { radial, tangential }),
        "OPENCV_FISHEYE" if tangential == [0.0; 2] => Ok(Lens::Fisheye { radial }),
        "OPENCV_FISHEYE" => Err(format!(
            "fields `p1`, `p2` ({tangential:?}) are not part of `camera_model` OPENCV_FISHEYE \
             (k1 to k4 only)"
        )),
        "PINHOLE" | "SIMPLE_PINHOLE" if radial == [0.0; 4] && tangential == [0.0; 2] => {
            Ok(Lens::Pinhole)
        }
        "PINHOLE" | "SIMPLE_PINHOLE" => Err(format!(
            "`camera_model` {model} has no distortion, but the frame gives k1..k4 = {radial:?}, \
             p1, p2 = {tangential:?}: say OPENCV (or OPENCV_FISHEYE) for a lens with distortion"
        )),
        other => Err(format!(
            "field `camera_model` {other:?} is not a camera volgen reads: it reads \
             {CAMERA_MODELS} (equirectangular and other models need their photos turned into \
             pinhole ones first)"
        )),
    }
}

/// The frame's `mask_path`, if it has one.
pub(super) fn mask_path(frame: &Value) -> Result<Option<&str>, String> {
    match frame.get("mask_path") {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(path)) => Ok(Some(path)),
        Some(other) => Err(format!(
            "field `mask_path` must be a file name (a grey image, white on the scene), got {other}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn lenses_come_from_the_model_and_coefficients() {
        let root = json!({"camera_model": "OPENCV", "k1": -0.1, "p2": 0.01});
        assert_eq!(
            frame_lens(&root, &json!({"k2": 0.05})).unwrap(),
            Lens::BrownConrady {
                radial: [-0.1, 0.05, 0.0, 0.0],
                tangential: [0.0, 0.01],
            }
        );
        assert!(frame_lens(&json!({}), &json!({})).unwrap().is_pinhole());
        assert_eq!(
            frame_lens(
                &json!({"camera_model": "OPENCV_FISHEYE", "k3": 0.2}),
                &json!({})
            )
            .unwrap(),
            Lens::Fisheye {
                radial: [0.0, 0.0, 0.2, 0.0]
            }
        );
        assert_eq!(
            frame_lens(&json!({"camera_model": "PINHOLE"}), &json!({})).unwrap(),
            Lens::Pinhole
        );
    }

    #[test]
    fn what_cannot_be_read_is_refused_by_field() {
        let refused = |root: Value| frame_lens(&root, &json!({})).unwrap_err();
        let err = refused(json!({"camera_model": "EQUIRECTANGULAR"}));
        assert!(
            err.contains("camera_model") && err.contains("EQUIRECTANGULAR"),
            "{err}"
        );
        let err = refused(json!({"camera_model": "PINHOLE", "k1": 0.1}));
        assert!(err.contains("PINHOLE") && err.contains("OPENCV"), "{err}");
        let err = refused(json!({"k1": "strong"}));
        assert!(err.contains("`k1`"), "{err}");
        let err = refused(json!({"camera_model": "OPENCV_FISHEYE", "p1": 0.1}));
        assert!(err.contains("p1"), "{err}");
        let err = mask_path(&json!({"mask_path": 3})).unwrap_err();
        assert!(err.contains("mask_path"), "{err}");
    }
}
