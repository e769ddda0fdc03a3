//! Boxes and offsets on the command line (`x0,y0,z0,x1,y1,z1`, `dx,dy,dz`), in the scene's
//! coordinates, and their place in the model's cube for a run trained with `--bounds`: what
//! `volgen edit` and `volgen compose` take.

use glam::Vec3;
use radiance_volume::Aabb;
use rgbd_dataset::SceneBounds;

/// `N` comma-separated finite numbers, or a message naming the expected `format`.
fn parse_numbers<const N: usize>(text: &str, format: &str) -> Result<[f32; N], String> {
    let expected = || format!("expected {format}, got \"{text}\"");
    let numbers: Vec<f32> = text
        .split(',')
        .map(|part| part.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| expected())?;
    let numbers: [f32; N] = numbers.try_into().map_err(|_| expected())?;
    if numbers.iter().any(|v| !v.is_finite()) {
        return Err(expected());
    }
    Ok(numbers)
}

/// Parses `x0,y0,z0,x1,y1,z1` into a non-empty box.
pub fn parse_box(text: &str) -> Result<Aabb, String> {
    let [x0, y0, z0, x1, y1, z1] =
        parse_numbers(text, "six comma-separated numbers x0,y0,z0,x1,y1,z1")?;
    let (min, max) = (Vec3::new(x0, y0, z0), Vec3::new(x1, y1, z1));
    if min.cmpge(max).any() {
        return Err(format!(
            "the box \"{text}\" is empty: expected x0 < x1, y0 < y1 and z0 < z1"
        ));
    }
    Aabb::try_new(min, max).map_err(|e| e.to_string())
}

/// Parses `dx,dy,dz`.
pub fn parse_offset(text: &str) -> Result<Vec3, String> {
    let [dx, dy, dz] = parse_numbers(text, "three comma-separated numbers dx,dy,dz")?;
    Ok(Vec3::new(dx, dy, dz))
}

/// Where boxes and offsets in the scene's coordinates land in the model's cube: unchanged,
/// or through the `--bounds` a run was trained with.
#[derive(Debug, Clone, Copy)]
pub struct ModelFrame<'a> {
    pub bounds: Option<&'a SceneBounds>,
}

impl ModelFrame<'_> {
    /// A box of the scene in the model's cube.
    pub fn place(&self, region: &Aabb) -> Aabb {
        match self.bounds {
            Some(b) => Aabb {
                min: b.to_model(region.min),
                max: b.to_model(region.max),
            },
            None => *region,
        }
    }

    /// An offset of the scene in the model's cube.
    pub fn shift(&self, offset: &Vec3) -> Vec3 {
        self.bounds.map_or(*offset, |b| *offset / b.half_side())
    }
}
