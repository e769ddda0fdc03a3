//! The non-tree parts of a VDB file: magic number and archive header, metadata entries, grid
//! descriptors and the index -> world transform (OpenVDB `io/Archive.cc`, `io/GridDescriptor.cc`,
//! `math/Maps.h`).

use glam::{DMat4, DVec3};

use super::bytes::PutBytes;
use crate::grid::VoxelGrid;

/// The 8-byte magic number every VDB file starts with (`" BDV"` then four zero bytes).
pub(crate) const MAGIC: i64 = 0x5644_4220;
/// The file format version written: 224 (`OPENVDB_FILE_VERSION_MULTIPASS_IO`), which every
/// OpenVDB from 6.x on (and so every Blender with volume objects) reads.
pub(crate) const FILE_VERSION: u32 = 224;
/// The oldest version we read: 222 introduced per-grid compression flags and per-node metadata
/// bytes, which the reader relies on.
pub(crate) const MIN_READ_VERSION: u32 = 222;
/// The library version recorded in the header. OpenVDB 10.0 writes file version 224, so readers
/// that gate behaviour on the pair see a consistent one.
const LIBRARY_VERSION: (u32, u32) = (10, 0);

/// Per-grid compression flag: leaf and node value arrays are zlib streams.
pub(crate) const COMPRESS_ZIP: u32 = 0x1;
/// Per-grid compression flag: only active values are stored when the inactive ones equal the
/// background.
pub(crate) const COMPRESS_ACTIVE_MASK: u32 = 0x2;
/// Per-grid compression flag: Blosc (read by vdb-rs, never written here).
pub(crate) const COMPRESS_BLOSC: u32 = 0x4;

/// A metadata value of one of the types OpenVDB registers.
pub(crate) enum MetaValue<'a> {
    Str(&'a str),
    Bool(bool),
    I64(i64),
    Vec3i([i32; 3]),
}

/// Appends a metadata map: `u32 count`, then per entry `string name, string type, u32 size,
/// value`. Entries must be sorted by name, the order of OpenVDB's `std::map`-backed `MetaMap`.
pub(crate) fn put_metadata(buf: &mut Vec<u8>, entries: &[(&str, MetaValue<'_>)]) {
    debug_assert!(entries.windows(2).all(|p| p[0].0 < p[1].0));
    buf.put_u32(entries.len() as u32);
    for (name, value) in entries {
        buf.put_str(name);
        match value {
            MetaValue::Str(s) => {
                buf.put_str("string");
                buf.put_str(s);
            }
            MetaValue::Bool(b) => {
                buf.put_str("bool");
                buf.put_u32(1);
                buf.put_u8(u8::from(*b));
            }
            MetaValue::I64(v) => {
                buf.put_str("int64");
                buf.put_u32(8);
                buf.put_i64(*v);
            }
            MetaValue::Vec3i(v) => {
                buf.put_str("vec3i");
                buf.put_u32(12);
                v.iter().for_each(|&c| buf.put_i32(c));
            }
        }
    }
}

/// Appends the archive header up to its UUID: magic, versions and `has_grid_offsets = 1` (so
/// readers can seek to each grid, and vdb-rs requires it). [`put_header_end`] follows the UUID.
pub(crate) fn put_header_start(buf: &mut Vec<u8>) {
    buf.put_i64(MAGIC);
    buf.put_u32(FILE_VERSION);
    buf.put_u32(LIBRARY_VERSION.0);
    buf.put_u32(LIBRARY_VERSION.1);
    buf.put_u8(1);
}

/// Appends the rest of the archive header after the 36-character UUID: empty file metadata and
/// the grid count.
pub(crate) fn put_header_end(buf: &mut Vec<u8>, grid_count: u32) {
    put_metadata(buf, &[]);
    buf.put_u32(grid_count);
}

/// A UUID-shaped 36-character id derived from the bytes of some parts (a 128-bit FNV-1a over
/// each part's 8-byte words, then its remaining bytes and its length, formatted as an RFC 9562
/// version-8 "custom" UUID), fed as the parts are written. OpenVDB only uses the UUID to tell
/// files apart; deriving it from the content keeps exports byte-for-byte reproducible.
pub(crate) struct ContentHash {
    a: u64,
    b: u64,
    /// The bytes of an incomplete word of the current part.
    word: Vec<u8>,
    part_len: u64,
}

const PRIME: u64 = 0x0000_0100_0000_01b3;

impl ContentHash {
    pub(crate) fn new() -> Self {
        Self {
            a: 0xcbf2_9ce4_8422_2325,
            b: 0x6c62_272e_07bb_0142,
            word: Vec::with_capacity(8),
            part_len: 0,
        }
    }

    /// Feeds bytes of the current part.
    pub(crate) fn update(&mut self, mut bytes: &[u8]) {
        self.part_len += bytes.len() as u64;
        if !self.word.is_empty() {
            let take = (8 - self.word.len()).min(bytes.len());
            self.word.extend_from_slice(&bytes[..take]);
            bytes = &bytes[take..];
            if self.word.len() < 8 {
                return;
            }
            let w = u64::from_le_bytes(self.word[..].try_into().expect("8 bytes"));
            self.mix_word(w);
            self.word.clear();
        }
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            self.mix_word(u64::from_le_bytes(w.try_into().expect("chunks of 8")));
        }
        self.word.extend_from_slice(words.remainder());
    }

    /// Ends the current part: its last bytes one by one, then its length.
    pub(crate) fn end_part(&mut self) {
        for &byte in &self.word {
            self.a = (self.a ^ u64::from(byte)).wrapping_mul(PRIME);
            self.b = (self.b ^ u64::from(byte)).wrapping_mul(PRIME);
        }
        self.word.clear();
        self.a ^= self.part_len;
        self.part_len = 0;
    }

    fn mix_word(&mut self, w: u64) {
        self.a = (self.a ^ w).wrapping_mul(PRIME);
        self.b = (self.b ^ w.rotate_left(29)).wrapping_mul(PRIME);
    }

    /// The UUID of the parts ended so far.
    pub(crate) fn uuid(&self) -> String {
        // Version 8 in the high nibble of the third group, variant 0b10 in the fourth.
        let a = (self.a & !0xf000) | 0x8000;
        let b = (self.b & !(0b11 << 62)) | (0b10 << 62);
        format!(
            "{:08x}-{:04x}-{:04x}-{:04x}-{:012x}",
            a >> 32,
            (a >> 16) & 0xffff,
            a & 0xffff,
            b >> 48,
            b & 0xffff_ffff_ffff
        )
    }
}

/// The linear index -> world map of an exported grid: `world = index * voxel_size + translation`,
/// with voxel centres at integer indices, then `placed` when the volume's coordinates are mapped
/// on to another frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Transform {
    pub(crate) voxel_size: DVec3,
    pub(crate) translation: DVec3,
    /// An affine map from the volume's coordinates to the file's world, if any.
    pub(crate) placed: Option<DMat4>,
}

impl Transform {
    /// Returns the map that puts index `(i, j, k)` = `(x, y, z)` at the centre of cell
    /// `(d=k, h=j, w=i)` of `grid`, computed in f64 from the f32 box.
    pub(crate) fn for_grid(grid: &VoxelGrid) -> Self {
        let [w, h, d] = grid.dims.xyz();
        let min = grid.aabb.min.as_dvec3();
        let voxel_size =
            (grid.aabb.max.as_dvec3() - min) / DVec3::new(w as f64, h as f64, d as f64);
        Self {
            voxel_size,
            translation: min + 0.5 * voxel_size,
            placed: None,
        }
    }

    /// Returns the OpenVDB map type: an affine map when placed, else uniform when the three
    /// voxel sizes are exactly equal.
    pub(crate) fn map_type(&self) -> &'static str {
        let s = self.voxel_size;
        if self.placed.is_some() {
            "AffineMap"
        } else if s.x == s.y && s.y == s.z {
            "UniformScaleTranslateMap"
        } else {
            "ScaleTranslateMap"
        }
    }

    /// The whole index -> world map as a matrix acting on column vectors.
    pub(crate) fn matrix(&self) -> DMat4 {
        let grid = DMat4::from_translation(self.translation) * DMat4::from_scale(self.voxel_size);
        self.placed.map_or(grid, |placed| placed * grid)
    }

    /// Appends the transform as OpenVDB's maps write themselves: the map type name, then for
    /// `AffineMap::write` its 4x4 matrix (row-major, for row vectors: the transpose of
    /// [`Transform::matrix`], so translation is the last row), for `ScaleTranslateMap::write`
    /// the translation and the five cached vectors of the scale map (scale, voxel size,
    /// 1/scale, 1/scale^2, 1/(2 scale)).
    pub(crate) fn put(&self, buf: &mut Vec<u8>) {
        buf.put_str(self.map_type());
        if self.placed.is_some() {
            // Column-major for column vectors is row-major for row vectors.
            for c in self.matrix().to_cols_array() {
                buf.put_f64(c);
            }
            return;
        }
        let s = self.voxel_size;
        for v in [
            self.translation,
            s,
            s.abs(),
            s.recip(),
            (s * s).recip(),
            (2.0 * s).recip(),
        ] {
            v.to_array().iter().for_each(|&c| buf.put_f64(c));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Aabb, GridDims};
    use glam::Vec3;

    #[test]
    fn uuid_is_well_formed_and_depends_on_content() {
        let uuid = |parts: &[&[u8]], split: usize| {
            let mut hash = ContentHash::new();
            for part in parts {
                let (head, tail) = part.split_at(split.min(part.len()));
                hash.update(head);
                hash.update(tail);
                hash.end_part();
            }
            hash.uuid()
        };
        let u1 = uuid(&[&b"abc"[..], &[0u8; 17][..]], 0);
        let u2 = uuid(&[&b"abd"[..], &[0u8; 17][..]], 0);
        // However a part is fed, its hash is the same.
        for split in 1..17 {
            assert_eq!(uuid(&[&b"abc"[..], &[0u8; 17][..]], split), u1);
        }
        assert_eq!(u1.len(), 36);
        assert_ne!(u1, u2);
        assert_eq!(u1.as_bytes()[14], b'8');
        assert!(u1.chars().all(|c| c == '-' || c.is_ascii_hexdigit()));
    }

    #[test]
    fn transform_centres_voxels_and_picks_the_map_type() {
        let g = VoxelGrid::new(Aabb::CUBE, GridDims::cube(4)).unwrap();
        let t = Transform::for_grid(&g);
        assert_eq!(t.voxel_size, DVec3::splat(0.5));
        assert_eq!(t.translation, DVec3::splat(-0.75));
        assert_eq!(t.map_type(), "UniformScaleTranslateMap");
        let aabb = Aabb::try_new(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0)).unwrap();
        let g = VoxelGrid::new(aabb, GridDims::cube(4)).unwrap();
        assert_eq!(Transform::for_grid(&g).map_type(), "ScaleTranslateMap");
        let mut buf = Vec::new();
        Transform::for_grid(&g).put(&mut buf);
        assert_eq!(buf.len(), 4 + "ScaleTranslateMap".len() + 18 * 8);
    }

    #[test]
    fn a_placed_transform_is_an_affine_map_of_row_vectors() {
        let g = VoxelGrid::new(Aabb::CUBE, GridDims::cube(4)).unwrap();
        let placed = DMat4::from_scale_rotation_translation(
            DVec3::splat(2.0),
            glam::DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
            DVec3::new(10.0, 0.0, 0.0),
        );
        let t = Transform {
            placed: Some(placed),
            ..Transform::for_grid(&g)
        };
        assert_eq!(t.map_type(), "AffineMap");
        let mut buf = Vec::new();
        t.put(&mut buf);
        let name = 4 + "AffineMap".len();
        assert_eq!(buf.len(), name + 16 * 8);
        // Rounded to 1e-12 (the quarter turn's cosine is not exactly 0).
        let m: Vec<f64> = buf[name..]
            .chunks(8)
            .map(|b| (f64::from_le_bytes(b.try_into().unwrap()) * 1e12).round() / 1e12)
            .collect();
        // Index (0, 0, 0) is the first voxel's centre (-0.75, -0.75, -0.75), turned a quarter
        // about z, doubled and moved: (10 + 1.5, -1.5, -1.5). As a row vector [0 0 0 1] times
        // the matrix, that is its last row.
        assert_eq!(&m[12..16], &[11.5, -1.5, -1.5, 1.0]);
        // Index x + 1 moves a voxel (0.5) along x, which lands along +y, doubled: the first row.
        assert_eq!(&m[0..4], &[0.0, 1.0, 0.0, 0.0]);
    }
}
