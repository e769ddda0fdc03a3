//! One scene as the page draws it: the volume as volgen's renderer takes it, laid out as the
//! page's 3D texture, with the rest of what the page's ray marcher needs to render it as
//! volrender does (box, density rule, samples per ray, background), and the files it was made
//! from for the downloads.

use std::sync::Mutex;

use anyhow::Result;
use axum::body::Bytes;
use candle_core::Tensor;
use radiance_volume::{Aabb, GridDims, RadianceVolume};
use serde_json::json;
use volrender::DensityInterpolation;

use super::params::SceneKey;

/// The formats a scene downloads as: the files `volgen sample --vdb --mesh glb` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Safetensors,
    Vdb,
    Glb,
}

impl Format {
    /// Every format, in the order the page lists them.
    pub const ALL: [Format; 3] = [Format::Safetensors, Format::Vdb, Format::Glb];

    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Safetensors => "safetensors",
            Format::Vdb => "vdb",
            Format::Glb => "glb",
        }
    }

    /// The format of a file name's extension.
    pub fn of_extension(extension: &str) -> Option<Format> {
        Self::ALL.into_iter().find(|f| f.extension() == extension)
    }
}

/// What a scene was made from, which its downloads are made from.
pub enum Content {
    /// A model's raw volume `(1, 4, s, s, s)`; the generator sets the key's extent on the
    /// model before exporting it (the scene's box depends on it).
    Raw(Tensor),
    /// A physical volume read from a file.
    Volume(RadianceVolume),
}

/// A scene the viewer drew, as the page renders it.
pub struct Scene {
    /// Its number in the cache (the `/scenes/{id}/...` routes).
    pub id: u64,
    pub key: SceneKey,
    /// The downloads' file name without extension.
    pub stem: String,
    /// The page's 3D texture: 32-bit little-endian floats laid out `(D, H, W, 4)` (x fastest):
    /// density (raw under post-activation, physical otherwise) and colour in [0, 1].
    pub texture: Bytes,
    pub dims: GridDims,
    /// The volume's box in the scene's coordinates (the training cameras').
    pub aabb: Aabb,
    pub density: DensityInterpolation,
    /// Uniform midpoint samples per ray between box entry and exit.
    pub samples: usize,
    pub background: [f32; 3],
    /// Seconds the generator took (0 for files).
    pub seconds: f64,
    pub content: Content,
    /// Downloads made so far, kept with the scene (so repeated and concurrent downloads of
    /// one file share one buffer).
    exports: Mutex<Vec<(Format, Bytes)>>,
}

/// How a source renders a volume: the settings beside the volume itself.
#[derive(Debug, Clone, Copy)]
pub struct Rendering {
    pub density: DensityInterpolation,
    pub samples: usize,
    pub background: [f32; 3],
}

impl Scene {
    /// The scene of `volume` (as volgen's renderer takes it under `rendering.density`), made
    /// from `content` for `key`; its id is set when the cache takes it.
    pub fn new(
        key: SceneKey,
        stem: String,
        volume: &RadianceVolume,
        rendering: Rendering,
        seconds: f64,
        content: Content,
    ) -> Result<Self> {
        Ok(Self {
            id: 0,
            key,
            stem,
            texture: texture_bytes(volume)?,
            dims: volume.dims(),
            aabb: volume.aabb(),
            density: rendering.density,
            samples: rendering.samples,
            background: rendering.background,
            seconds,
            content,
            exports: Mutex::new(Vec::new()),
        })
    }

    /// The download in `format`, if it was made.
    pub fn export(&self, format: Format) -> Option<Bytes> {
        let exports = self.exports.lock().unwrap_or_else(|e| e.into_inner());
        exports
            .iter()
            .find(|(f, _)| *f == format)
            .map(|(_, b)| b.clone())
    }

    /// Keeps a download made for this scene.
    pub fn keep_export(&self, format: Format, bytes: Bytes) {
        let mut exports = self.exports.lock().unwrap_or_else(|e| e.into_inner());
        if !exports.iter().any(|(f, _)| *f == format) {
            exports.push((format, bytes));
        }
    }

    /// The memory the scene holds: texture, content and downloads.
    pub fn bytes(&self) -> usize {
        let content = match &self.content {
            Content::Raw(raw) => raw.elem_count() * raw.dtype().size_in_bytes(),
            Content::Volume(volume) => volume.tensor().elem_count() * 4,
        };
        let exports = self.exports.lock().unwrap_or_else(|e| e.into_inner());
        self.texture.len() + content + exports.iter().map(|(_, b)| b.len()).sum::<usize>()
    }

    /// The file name of the download in `format`.
    pub fn file_name(&self, format: Format) -> String {
        format!("{}.{}", self.stem, format.extension())
    }

    /// What the page needs to fetch and render the scene, as JSON.
    pub fn describe(&self) -> serde_json::Value {
        let b = self.aabb;
        let density = match self.density.post_activation() {
            Some([scale, shift]) => {
                json!({ "rule": "post-activated", "scale": scale, "shift": shift })
            }
            None => json!({ "rule": "physical" }),
        };
        let base = format!("/scenes/{}", self.id);
        let downloads: serde_json::Map<String, serde_json::Value> = Format::ALL
            .iter()
            .map(|f| {
                (
                    f.extension().to_string(),
                    json!(format!("{base}/{}", self.file_name(*f))),
                )
            })
            .collect();
        let mut description = json!({
            "id": self.id,
            "name": self.stem,
            "dims": [self.dims.w, self.dims.h, self.dims.d],
            "box": [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z],
            "density": density,
            "samples": self.samples,
            "background": self.background,
            "seconds": self.seconds,
            "volume": format!("{base}/volume"),
            "downloads": downloads,
        });
        if let SceneKey::Drawn {
            seed,
            vary,
            walk,
            extent,
            outside,
        } = &self.key
        {
            description["seed"] = json!(seed.to_string());
            description["vary"] = json!(vary);
            description["walk"] = json!(walk);
            description["extent"] = json!(extent.to_string());
            description["outside"] = json!(outside.to_string());
        }
        description
    }
}

/// A `(C >= 4, D, H, W)` volume's first four channels as `(D, H, W, 4)` little-endian f32
/// bytes, the layout of a WebGL2 RGBA32F 3D texture.
fn texture_bytes(volume: &RadianceVolume) -> Result<Bytes> {
    let planes = volume
        .tensor()
        .narrow(0, 0, 4)?
        .permute((1, 2, 3, 0))?
        .flatten_all()?
        .to_vec1::<f32>()?;
    let bytes: Vec<u8> = planes.iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok(Bytes::from(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_texture_interleaves_channels_with_x_fastest() {
        // Value = 1000 c + 100 z + 10 y + x on a 2 x 2 x 3 (D x H x W) grid.
        let volume =
            RadianceVolume::from_fn(GridDims::new(2, 2, 3), Aabb::CUBE, 4, |_, _| {}).unwrap();
        let data: Vec<f32> = (0..4)
            .flat_map(|c| {
                (0..2).flat_map(move |z| {
                    (0..2).flat_map(move |y| {
                        (0..3).map(move |x| (1000 * c + 100 * z + 10 * y + x) as f32)
                    })
                })
            })
            .collect();
        let tensor = Tensor::from_vec(data, (4, 2, 2, 3), &candle_core::Device::Cpu).unwrap();
        let volume = volume.with_tensor(tensor).unwrap();
        let bytes = texture_bytes(&volume).unwrap();
        let value = |i: usize| f32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
        // Texel (x, y, z) = (2, 1, 1), channel 3.
        let (x, y, z) = (2, 1, 1);
        let texel = (z * 2 + y) * 3 + x;
        assert_eq!(value(4 * texel + 3), 3112.0);
        assert_eq!(value(4 * texel), 112.0);
        assert_eq!(bytes.len(), 2 * 2 * 3 * 4 * 4);
    }

    #[test]
    fn formats_round_trip_their_extensions() {
        for format in Format::ALL {
            assert_eq!(Format::of_extension(format.extension()), Some(format));
        }
        assert_eq!(Format::of_extension("exe"), None);
    }
}
