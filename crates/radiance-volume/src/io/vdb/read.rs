//! VDB import through vdb-rs: load the density and colour grids of any OpenVDB file (ours,
//! Blender's, Houdini's) and sample them at the cell centres of a chosen grid.
//!
//! vdb-rs 0.6 has limits that would otherwise turn bad or merely unusual files into panics or
//! wrong values, so a file is first walked here (header, descriptors, metadata, transform, root):
//! - it panics on transforms other than (uniform) scale(-translate) maps, on duplicate grid
//!   names, instanced grids, multi-buffer trees and on malformed metadata; these are refused with
//!   an error first (and any other panic inside vdb-rs is caught and reported as an invalid file);
//! - it reads the root background and root tile values as 4 bytes whatever the value type, so a
//!   vec3 grid's topology is misread. It is handed a view of the file without the 8 extra bytes of
//!   each such value ([`SkipReader`]); vdb-rs ignores root tiles, so nothing is lost;
//! - for half-float grids compressed with zip or Blosc (as OpenVDB, Blender and Houdini write
//!   them) it expects an 8-byte size where OpenVDB writes nothing (an empty value array), and
//!   reads vec3 inactive values as halves where OpenVDB stores floats. Such a tree is walked here
//!   ([`TreeWalk`]) and the view gets the missing (zero) sizes inserted and the extra bytes hidden.
//!   Without this, vdb-rs reads garbage sizes and can abort the process on a huge allocation;
//! - it allocates whatever byte count a compressed array claims before reading it, so a damaged
//!   count aborts the process (an allocation failure is not a panic `catch_unwind` could turn
//!   into an error). Every zip or Blosc tree is therefore walked first and refused if an array
//!   claims more bytes than the file has left, a Blosc header more values than the node holds,
//!   the leaf buffers do not start where the topology ends (vdb-rs reads on, OpenVDB seeks), or
//!   the `_HalfFloat` type and the `is_saved_as_half_float` metadata (which vdb-rs goes by)
//!   disagree.

use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;

use candle_core::{Device, Tensor};
use glam::{DVec3, IVec3};
use half::f16;
use rayon::prelude::*;
use vdb_rs::{Grid, Map, VdbLevel, VdbReader};

use super::bytes::Cursor;
use super::meta::{COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC, COMPRESS_ZIP, MAGIC, MIN_READ_VERSION};
use super::{vdb_error, DENSITY_GRID};
use crate::error::{io_error, Result};
use crate::grid::VoxelGrid;
use crate::volume::RadianceVolume;

/// Vec3 grids tried for colour on import, in order (`color`: Blender and this crate; `Cd`:
/// Houdini).
pub const COLOR_GRID_NAMES: [&str; 2] = ["color", "Cd"];
/// Triples of float grids tried for colour when there is no vec3 colour grid.
pub const COLOR_RGB_GRID_NAMES: [[&str; 3]; 3] = [
    ["r", "g", "b"],
    ["R", "G", "B"],
    ["color_r", "color_g", "color_b"],
];
/// The colour of an imported volume whose file has no colour grid: the default colour of
/// Blender's Principled Volume.
pub const DEFAULT_IMPORT_COLOR: [f32; 3] = [0.5, 0.5, 0.5];

/// Index-space offsets closer than this to an integer are snapped to it, so that sampling on the
/// grid a file was written from returns the stored values exactly despite f32/f64 rounding.
const SNAP: f64 = 1e-4;

/// What the pre-walk learnt about one grid.
struct GridLayout {
    name: String,
    /// The tree type without the `_HalfFloat` suffix, e.g. `Tree_float_5_4_3`.
    tree_type: String,
    half: bool,
    /// Why vdb-rs cannot read this grid, if it cannot.
    unreadable: Option<String>,
    /// Byte ranges vdb-rs must not see (the tails of wide values).
    holes: Vec<Range<u64>>,
    /// Positions where vdb-rs must see an 8-byte zero (the size of an empty array).
    inserts: Vec<u64>,
}

impl RadianceVolume {
    /// Loads an OpenVDB file onto `grid`: the `density` float grid, and the colour from a vec3
    /// grid ([`COLOR_GRID_NAMES`]) or three float grids ([`COLOR_RGB_GRID_NAMES`]), else
    /// [`DEFAULT_IMPORT_COLOR`]. Each is sampled trilinearly (as OpenVDB's `BoxSampler`, inactive
    /// voxels are the background 0) at the world positions of `grid`'s cell centres, so a file
    /// from Blender or Houdini lands where it sits in world space. Full and half floats and the
    /// zip and Blosc codecs are read; transforms must be (uniform) scale or scale-translate maps.
    ///
    /// ```
    /// use radiance_volume::{Aabb, GridDims, RadianceVolume, VoxelGrid};
    /// let v = RadianceVolume::from_fn(GridDims::cube(8), Aabb::CUBE, 4, |p, out| {
    ///     out.copy_from_slice(&[1.0 + p.x, 0.2, 0.4, 0.6]);
    /// })?;
    /// let dir = tempfile::tempdir()?;
    /// v.write_vdb().to_file(dir.path().join("v.vdb"))?;
    /// // Re-sample on a coarser grid over the same box.
    /// let coarse = VoxelGrid::new(Aabb::CUBE, GridDims::cube(4))?;
    /// let back = RadianceVolume::read_vdb(dir.path().join("v.vdb"), &coarse)?;
    /// assert_eq!(back.dims(), GridDims::cube(4));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn read_vdb(path: impl AsRef<Path>, grid: &VoxelGrid) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(io_error(path))?;
        Self::read_vdb_bytes(bytes, grid, path)
    }

    /// Like [`read_vdb`](Self::read_vdb), from the bytes of a file; `path` only names it in
    /// errors.
    pub fn read_vdb_bytes(bytes: Vec<u8>, grid: &VoxelGrid, path: &Path) -> Result<Self> {
        let grid = VoxelGrid::new(grid.aabb, grid.dims)?;
        let layouts = scan(&bytes).map_err(|why| vdb_error(path, why))?;
        let find = |name: &str| layouts.iter().find(|l| l.name == name);
        let density = find(DENSITY_GRID).ok_or_else(|| {
            let names: Vec<&str> = layouts.iter().map(|l| l.name.as_str()).collect();
            vdb_error(path, format!("no `density` grid (grids: {names:?})"))
        })?;
        let color = COLOR_GRID_NAMES.iter().find_map(|n| find(n));
        let rgb = COLOR_RGB_GRID_NAMES
            .iter()
            .find_map(|names| Some([find(names[0])?, find(names[1])?, find(names[2])?]));
        let mut wanted = vec![density];
        wanted.extend(color);
        if color.is_none() {
            wanted.extend(rgb.iter().flatten());
        }
        for l in &wanted {
            if let Some(why) = &l.unreadable {
                return Err(vdb_error(path, format!("grid `{}`: {why}", l.name)));
            }
        }
        let holes: Vec<Range<u64>> = wanted.iter().flat_map(|l| l.holes.clone()).collect();
        let inserts: Vec<u64> = wanted.iter().flat_map(|l| l.inserts.clone()).collect();
        let mut reader = open(SkipReader::new(bytes, holes, inserts), path)?;
        let density = load::<1>(&mut reader, density, path)?;
        let color = match (color, rgb) {
            (Some(c), _) => Color::Vec3(load::<3>(&mut reader, c, path)?),
            (None, Some([r, g, b])) => Color::Rgb(Box::new([
                load::<1>(&mut reader, r, path)?,
                load::<1>(&mut reader, g, path)?,
                load::<1>(&mut reader, b, path)?,
            ])),
            (None, None) => Color::Constant(DEFAULT_IMPORT_COLOR),
        };

        let dims = grid.dims;
        let n = dims.voxel_count();
        let mut planar = vec![0f32; 4 * n];
        let (sigma, rest) = planar.split_at_mut(n);
        let (r, rest) = rest.split_at_mut(n);
        let (g, b) = rest.split_at_mut(n);
        sigma
            .par_iter_mut()
            .zip(r.par_iter_mut().zip(g.par_iter_mut().zip(b.par_iter_mut())))
            .enumerate()
            .for_each(|(i, (s, (r, (g, b))))| {
                let (z, y, x) = (i / (dims.h * dims.w), i / dims.w % dims.h, i % dims.w);
                let p = grid.cell_center(z, y, x).as_dvec3();
                *s = density.sample(p)[0];
                [*r, *g, *b] = color.sample(p);
            });
        let data = Tensor::from_vec(planar, (4, dims.d, dims.h, dims.w), &Device::Cpu)?;
        let volume = Self::new(data, grid.aabb)?;
        volume.check_finite(&format!("{}", path.display()))?;
        Ok(volume)
    }
}

enum Color {
    Vec3(Sparse<3>),
    Rgb(Box<[Sparse<1>; 3]>),
    Constant([f32; 3]),
}

impl Color {
    fn sample(&self, p: DVec3) -> [f32; 3] {
        match self {
            Self::Vec3(s) => s.sample(p),
            Self::Rgb(c) => c.each_ref().map(|s| s.sample(p)[0]),
            Self::Constant(c) => *c,
        }
    }
}

/// A loaded grid: active values by leaf, and active tiles of 8^3 and 128^3 voxels, with the
/// grid's index -> world map; everything else is the background 0.
struct Sparse<const N: usize> {
    leaves: HashMap<IVec3, Box<[[f32; N]; 512]>>,
    tiles8: HashMap<IVec3, [f32; N]>,
    tiles128: HashMap<IVec3, [f32; N]>,
    scale: DVec3,
    translation: DVec3,
}

impl<const N: usize> Sparse<N> {
    fn from_grid<T: Copy>(grid: &Grid<T>, path: &Path, f: impl Fn(T) -> [f32; N]) -> Result<Self> {
        let (scale, translation) = match &grid.transform {
            Map::UniformScaleMap { scale_values, .. } => (scale_values, None),
            Map::ScaleTranslateMap {
                scale_values,
                translation,
                ..
            } => (scale_values, Some(translation)),
        };
        let scale = DVec3::new(scale.x, scale.y, scale.z);
        let translation = translation.map_or(DVec3::ZERO, |t| DVec3::new(t.x, t.y, t.z));
        if !(scale.is_finite() && translation.is_finite()) || scale.cmpeq(DVec3::ZERO).any() {
            return Err(vdb_error(
                path,
                format!(
                    "grid `{}` has a degenerate transform (scale {scale}, translation {translation})",
                    grid.descriptor.name
                ),
            ));
        }
        let mut out = Self {
            leaves: HashMap::new(),
            tiles8: HashMap::new(),
            tiles128: HashMap::new(),
            scale,
            translation,
        };
        for (p, value, level) in grid.iter() {
            let p = IVec3::new(p.x as i32, p.y as i32, p.z as i32);
            let value = f(value);
            match level {
                VdbLevel::Voxel => {
                    let leaf = out
                        .leaves
                        .entry(p & !7)
                        .or_insert_with(|| Box::new([[0.0; N]; 512]));
                    leaf[leaf_offset(p)] = value;
                }
                VdbLevel::Node3 => {
                    out.tiles8.insert(p, value);
                }
                VdbLevel::Node4 => {
                    out.tiles128.insert(p, value);
                }
            }
        }
        Ok(out)
    }

    fn get(&self, p: IVec3) -> [f32; N] {
        if let Some(leaf) = self.leaves.get(&(p & !7)) {
            return leaf[leaf_offset(p)];
        }
        let tile = self.tiles8.get(&(p & !7));
        let tile = tile.or_else(|| self.tiles128.get(&(p & !127)));
        tile.copied().unwrap_or([0.0; N])
    }

    /// Trilinear interpolation between the eight voxels around world point `p`.
    fn sample(&self, p: DVec3) -> [f32; N] {
        let q = (p - self.translation) / self.scale;
        let r = q.round();
        let q = DVec3::select((q - r).abs().cmplt(DVec3::splat(SNAP)), r, q);
        let base = q.floor();
        let f = q - base;
        let base = base.as_ivec3();
        let mut out = [0f32; N];
        for corner in 0..8 {
            let o = IVec3::new(corner >> 2 & 1, corner >> 1 & 1, corner & 1);
            let w = [0, 1, 2]
                .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                .iter()
                .product::<f64>();
            if w == 0.0 {
                continue;
            }
            let v = self.get(base + o);
            for (acc, v) in out.iter_mut().zip(v) {
                *acc += (w * f64::from(v)) as f32;
            }
        }
        out
    }
}

/// Offset of voxel `p` in its leaf, `x << 6 | y << 3 | z`.
fn leaf_offset(p: IVec3) -> usize {
    let l = p & 7;
    (l.x << 6 | l.y << 3 | l.z) as usize
}

/// Opens the bytes with vdb-rs behind the hole-skipping view.
fn open(reader: SkipReader, path: &Path) -> Result<VdbReader<SkipReader>> {
    guard(path, || VdbReader::new(reader))?.map_err(|e| vdb_error(path, e))
}

/// Reads one grid with vdb-rs, with the value type its tree type and precision call for.
fn load<const N: usize>(
    reader: &mut VdbReader<SkipReader>,
    layout: &GridLayout,
    path: &Path,
) -> Result<Sparse<N>> {
    let name = layout.name.as_str();
    let wrong_type = || {
        vdb_error(
            path,
            format!(
                "grid `{name}` is a {}, expected a {}",
                layout.tree_type,
                if N == 1 { "float grid" } else { "vec3s grid" }
            ),
        )
    };
    let read = |e| vdb_error(path, format!("grid `{name}`: {e}"));
    match (N, layout.tree_type.as_str(), layout.half) {
        // vdb-rs widens half floats to f32 for f32 grids itself.
        (1, "Tree_float_5_4_3", _) => {
            let grid = guard(path, || reader.read_grid::<f32>(name))?.map_err(read)?;
            Sparse::from_grid(&grid, path, |v| std::array::from_fn(|_| v))
        }
        (3, "Tree_vec3s_5_4_3", false) => {
            let grid = guard(path, || reader.read_grid::<[f32; 3]>(name))?.map_err(read)?;
            Sparse::from_grid(&grid, path, |v| std::array::from_fn(|i| v[i]))
        }
        // ... but not for vectors: read the stored halves and widen them here.
        (3, "Tree_vec3s_5_4_3", true) => {
            let grid = guard(path, || reader.read_grid::<[f16; 3]>(name))?.map_err(read)?;
            Sparse::from_grid(&grid, path, |v| std::array::from_fn(|i| v[i].to_f32()))
        }
        _ => Err(wrong_type()),
    }
}

/// Runs vdb-rs code, turning a panic (its way to report some malformed files) into an error.
fn guard<T>(path: &Path, f: impl FnOnce() -> T) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|panic| {
        let why = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("vdb-rs panicked");
        vdb_error(path, format!("vdb-rs could not read it: {why}"))
    })
}

/// Walks the header and every grid descriptor, checking what vdb-rs would panic on and locating
/// the wide root values it would misread.
fn scan(bytes: &[u8]) -> std::result::Result<Vec<GridLayout>, String> {
    let mut c = Cursor::new(bytes);
    if c.take(8, "the magic number")? != MAGIC.to_le_bytes() {
        return Err("not an OpenVDB file (bad magic number)".into());
    }
    let version = c.u32("the file version")?;
    if version < MIN_READ_VERSION {
        return Err(format!(
            "file format version {version} is older than the oldest supported ({MIN_READ_VERSION}); \
             re-save it with a current OpenVDB"
        ));
    }
    c.take(8, "the library version")?;
    if c.u8("the grid offsets flag")? != 1 {
        return Err(
            "the file has no grid offsets (a streamed archive), which vdb-rs cannot read".into(),
        );
    }
    c.take(36, "the UUID")?;
    skip_metadata(&mut c, "file metadata")?;
    let grid_count = c.u32("the grid count")?;
    let mut layouts: Vec<GridLayout> = Vec::new();
    for g in 0..grid_count {
        let name = c.string("a grid name")?;
        if layouts.iter().any(|l| l.name == name) {
            return Err(format!("two grids are named `{name}`"));
        }
        let what = format!("grid `{name}`");
        let grid_type = c.string(&what)?;
        let parent = c.string(&what)?;
        let (grid_pos, block_pos, end_pos) = (c.u64(&what)?, c.u64(&what)?, c.u64(&what)?);
        if !(grid_pos <= block_pos && block_pos <= end_pos) {
            return Err(format!(
                "{what}: offsets out of order ({grid_pos}, {block_pos}, {end_pos})"
            ));
        }
        c.seek(end_pos, &what)?;
        c.seek(grid_pos, &what)?;
        let compression = c.u32(&what)?;
        if compression & !(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC) != 0 {
            return Err(format!(
                "{what}: unknown compression flags {compression:#x}"
            ));
        }
        let saved_as_half = skip_metadata(&mut c, &what)?;
        let (tree_type, half) = match grid_type.strip_suffix("_HalfFloat") {
            Some(t) => (t.to_string(), true),
            None => (grid_type.clone(), false),
        };
        let mut layout = GridLayout {
            name,
            tree_type,
            half,
            unreadable: None,
            holes: Vec::new(),
            inserts: Vec::new(),
        };
        if saved_as_half != half {
            // vdb-rs picks the value width from the metadata, the tree walk below from the type.
            layout.unreadable = Some(format!(
                "the type `{grid_type}` and the metadata `is_saved_as_half_float` = \
                 {saved_as_half} disagree on the value precision"
            ));
        } else if !parent.is_empty() {
            layout.unreadable = Some(format!(
                "an instance of grid `{parent}`, not supported by vdb-rs"
            ));
        } else {
            let map = c.string(&what)?;
            let doubles = match map.as_str() {
                "UniformScaleMap" => 15,
                "UniformScaleTranslateMap" | "ScaleTranslateMap" => 18,
                _ => 0,
            };
            if doubles == 0 {
                layout.unreadable = Some(format!(
                    "transform `{map}` is not supported (vdb-rs reads UniformScaleMap and \
                     (Uniform)ScaleTranslateMap)"
                ));
            } else {
                c.take(doubles * 8, &what)?;
                if c.u32(&what)? != 1 {
                    layout.unreadable = Some("multi-buffer trees are not supported".into());
                }
                let value_size = match layout.tree_type.as_str() {
                    "Tree_vec3s_5_4_3" => 12,
                    _ => 4,
                };
                let background = c.pos() as u64;
                c.take(value_size, &what)?;
                let tiles = c.u32(&what)?;
                let children = c.u32(&what)?;
                if value_size > 4 {
                    layout
                        .holes
                        .push(background + 4..background + value_size as u64);
                }
                for _ in 0..tiles {
                    let value = c.pos() as u64 + 12;
                    c.take(12 + value_size + 1, &what)?;
                    if value_size > 4 {
                        layout.holes.push(value + 4..value + value_size as u64);
                    }
                }
                let known = matches!(
                    layout.tree_type.as_str(),
                    "Tree_float_5_4_3" | "Tree_vec3s_5_4_3"
                );
                if known && compression & (COMPRESS_ZIP | COMPRESS_BLOSC) != 0 {
                    let mut walk = TreeWalk {
                        c: &mut c,
                        what: &what,
                        value_size,
                        half: layout.half,
                        blosc: compression & COMPRESS_BLOSC != 0,
                        mask_compressed: compression & COMPRESS_ACTIVE_MASK != 0,
                        holes: Vec::new(),
                        inserts: Vec::new(),
                        leaves: 0,
                    };
                    match walk.tree(children, block_pos) {
                        Ok(()) => {
                            layout.holes.append(&mut walk.holes);
                            layout.inserts.append(&mut walk.inserts);
                        }
                        Err(why) => layout.unreadable = Some(why),
                    }
                }
            }
        }
        layouts.push(layout);
        if g + 1 < grid_count {
            c.seek(end_pos, &what)?;
        }
    }
    Ok(layouts)
}

/// Skips a metadata map, checking that each value has the size vdb-rs assumes for its type.
/// Returns whether it says `is_saved_as_half_float` (which vdb-rs reads values by).
fn skip_metadata(c: &mut Cursor<'_>, what: &str) -> std::result::Result<bool, String> {
    let mut saved_as_half = false;
    let count = c.u32(what)?;
    for _ in 0..count {
        let name = c.string(what)?;
        let type_name = c.string(what)?;
        let size = c.u32(what)? as usize;
        let expected = match type_name.as_str() {
            "bool" => Some(1),
            "int32" | "float" => Some(4),
            "int64" => Some(8),
            "vec3i" => Some(12),
            _ => None,
        };
        if expected.is_some_and(|e| e != size) {
            return Err(format!(
                "{what}: metadata `{name}` of type {type_name} has size {size}"
            ));
        }
        let value = c.take(size, what)?;
        if name == "is_saved_as_half_float" && type_name == "bool" {
            saved_as_half = value != [0];
        }
    }
    Ok(saved_as_half)
}

/// Walks the tree of a grid stored with zip or Blosc, checking that every compressed array's
/// byte count fits in the file (vdb-rs allocates the count it reads before reading the bytes, so
/// a damaged count would abort the process) and, for half-float grids (see the module docs),
/// recording where the view handed to vdb-rs must differ from the file.
struct TreeWalk<'c, 'a> {
    c: &'c mut Cursor<'a>,
    what: &'c str,
    /// Bytes of one full-precision value (inactive values are stored at full precision).
    value_size: usize,
    half: bool,
    blosc: bool,
    mask_compressed: bool,
    holes: Vec<Range<u64>>,
    inserts: Vec<u64>,
    leaves: usize,
}

/// Counts the set bits of a mask stored as little-endian u64 words.
fn count_ones(mask: &[u8]) -> usize {
    mask.iter().map(|b| b.count_ones() as usize).sum()
}

impl TreeWalk<'_, '_> {
    /// Walks the topology from the root's child list, then the leaf buffers, which must start at
    /// `block_pos`.
    fn tree(&mut self, children: u32, block_pos: u64) -> std::result::Result<(), String> {
        for _ in 0..children {
            self.c.take(12, self.what)?;
            self.node(5)?;
        }
        // OpenVDB records the buffers' offset right after writing the topology, and vdb-rs reads
        // on from there whatever the offset says: a file where the two differ is damaged.
        if self.c.pos() as u64 != block_pos {
            return Err(format!(
                "{}: the leaf buffers' offset {block_pos} is not where the topology ends ({})",
                self.what,
                self.c.pos()
            ));
        }
        for _ in 0..self.leaves {
            let mask = self.c.take(64, self.what)?;
            self.array(count_ones(mask), 512)?;
        }
        Ok(())
    }

    /// An internal node of `log2` (5 or 4): masks, values, then its children depth first.
    fn node(&mut self, log2: u32) -> std::result::Result<(), String> {
        let slots = 1usize << (3 * log2);
        let child_mask = self.c.take(slots / 8, self.what)?;
        let value_mask = self.c.take(slots / 8, self.what)?;
        self.array(count_ones(value_mask), slots)?;
        for i in 0..slots {
            if child_mask[i / 8] >> (i % 8) & 1 == 1 {
                if log2 == 5 {
                    self.node(4)?;
                } else {
                    self.c.take(64, self.what)?;
                    self.leaves += 1;
                }
            }
        }
        Ok(())
    }

    /// One `writeCompressedValues` array of `slots` values, `active` of them active.
    fn array(&mut self, active: usize, slots: usize) -> std::result::Result<(), String> {
        let meta = self.c.u8(self.what)?;
        if meta > 6 {
            return Err(format!("{}: invalid node metadata {meta}", self.what));
        }
        let inactive_values = match meta {
            2 | 4 => 1,
            5 => 2,
            _ => 0,
        };
        for _ in 0..inactive_values {
            let at = self.c.pos() as u64;
            self.c.take(self.value_size, self.what)?;
            if self.half && self.value_size == 12 {
                // vdb-rs reads a vec3 half grid's inactive value as three halves.
                self.holes.push(at + 6..at + 12);
            }
        }
        if matches!(meta, 3..=5) {
            self.c.take(slots / 8, self.what)?;
        }
        let count = if self.mask_compressed && meta != 6 {
            active
        } else {
            slots
        };
        if self.half && count == 0 {
            // OpenVDB's HalfWriter writes nothing here; vdb-rs reads a size.
            self.inserts.push(self.c.pos() as u64);
            return Ok(());
        }
        let size = i64::from_le_bytes(self.c.take(8, self.what)?.try_into().expect("took 8 bytes"));
        let len = usize::try_from(size.unsigned_abs())
            .map_err(|_| format!("{}: array size {size} is too large", self.what))?;
        // `take` refuses a count beyond the file's end, before vdb-rs would allocate it.
        let data = self.c.take(len, self.what)?;
        if self.blosc && size > 0 {
            // vdb-rs also allocates the decompressed size a Blosc header claims (bytes 4..8).
            let stored = count
                * if self.half {
                    self.value_size / 2
                } else {
                    self.value_size
                };
            let claimed = data
                .get(4..8)
                .map(|b| u32::from_le_bytes(b.try_into().expect("took 4 bytes")) as usize);
            if claimed.is_none_or(|claimed| claimed > stored) {
                return Err(format!(
                    "{}: a Blosc block claims {claimed:?} bytes for {count} values of {stored} bytes",
                    self.what
                ));
            }
        }
        Ok(())
    }
}

/// A view of a file with some byte ranges hidden and some 8-byte zeros inserted: reads step over
/// the former and produce the latter; seeks use positions in the real file (vdb-rs only seeks to
/// offsets it read from the file).
struct SkipReader {
    inner: std::io::Cursor<Vec<u8>>,
    holes: Vec<Range<u64>>,
    inserts: Vec<u64>,
    /// Zero bytes still to produce before the byte at the current position.
    pending: usize,
}

/// The size of an inserted array size.
const INSERT_LEN: usize = 8;

impl SkipReader {
    fn new(bytes: Vec<u8>, mut holes: Vec<Range<u64>>, mut inserts: Vec<u64>) -> Self {
        holes.sort_by_key(|h| h.start);
        inserts.sort_unstable();
        let mut r = Self {
            inner: std::io::Cursor::new(bytes),
            holes,
            inserts,
            pending: 0,
        };
        r.arrive();
        r
    }

    /// Sets up the insertion due at the current position.
    fn arrive(&mut self) {
        let pos = self.inner.position();
        self.pending = if self.inserts.binary_search(&pos).is_ok() {
            INSERT_LEN
        } else {
            0
        };
    }
}

impl Read for SkipReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.pending > 0 {
            let n = buf.len().min(self.pending);
            buf[..n].fill(0);
            self.pending -= n;
            return Ok(n);
        }
        let pos = self.inner.position();
        if let Some(h) = self.holes.iter().find(|h| h.contains(&pos)) {
            self.inner.set_position(h.end);
            self.arrive();
            return self.read(buf);
        }
        let next_hole = self.holes.iter().map(|h| h.start).filter(|&s| s > pos);
        let next_insert = self.inserts.iter().copied().filter(|&s| s > pos);
        let limit = next_hole
            .chain(next_insert)
            .min()
            .map_or(buf.len(), |s| buf.len().min((s - pos) as usize));
        let n = self.inner.read(&mut buf[..limit])?;
        if n > 0 {
            self.arrive();
        }
        Ok(n)
    }
}

impl Seek for SkipReader {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let pos = self.inner.seek(to)?;
        self.arrive();
        Ok(pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Aabb, GridDims};

    #[test]
    fn skip_reader_hides_ranges() {
        let mut r = SkipReader::new((1u8..21).collect(), vec![12..14, 4..8], vec![16]);
        let mut out = Vec::new();
        r.read_to_end(&mut out).unwrap();
        let mut want = vec![1, 2, 3, 4, 9, 10, 11, 12, 15, 16];
        want.extend([0; 8]);
        want.extend([17, 18, 19, 20]);
        assert_eq!(out, want);
        r.seek(SeekFrom::Start(6)).unwrap();
        let mut b = [0u8; 3];
        r.read_exact(&mut b).unwrap();
        assert_eq!(b, [9, 10, 11]);
    }

    /// The colour grid, read voxel by voxel through vdb-rs (behind the hole-skipping view),
    /// holds exactly the written colours at the active voxels, in full and half precision.
    #[test]
    fn color_grid_round_trips_through_vdb_rs() {
        let dims = GridDims::new(5, 9, 11);
        let v = RadianceVolume::from_fn(dims, Aabb::CUBE, 4, |p, out| {
            out[0] = if p.x > 0.2 { 1.0 + p.y } else { 0.0 };
            out[1..4].copy_from_slice(&[p.x * 0.3 + 0.5, p.y.abs() / 3.0, 0.123_456_7]);
        })
        .unwrap();
        let values: Vec<f32> = v.tensor().flatten_all().unwrap().to_vec1().unwrap();
        for (half, zlib) in [(false, false), (false, true), (true, false), (true, true)] {
            let mut bytes = Vec::new();
            v.write_vdb()
                .half(half)
                .zlib(zlib)
                .to_writer(&mut bytes)
                .unwrap();
            let layouts = scan(&bytes).unwrap();
            let color = layouts.iter().find(|l| l.name == "color").unwrap();
            assert_eq!(color.holes.len(), 1);
            assert!(color.inserts.is_empty(), "our files need no inserted sizes");
            let view = SkipReader::new(bytes.clone(), color.holes.clone(), Vec::new());
            let mut reader = open(view, Path::new("mem")).unwrap();
            let grid = load::<3>(&mut reader, color, Path::new("mem")).unwrap();
            let mut seen = 0;
            for z in 0..dims.d {
                for y in 0..dims.h {
                    for x in 0..dims.w {
                        let i = dims.index(z, y, x);
                        let got = grid.get(IVec3::new(x as i32, y as i32, z as i32));
                        if values[i] > 0.0 {
                            seen += 1;
                            for c in 0..3 {
                                let want = values[(c + 1) * dims.voxel_count() + i];
                                let want = if half {
                                    f16::from_f32(want).to_f32()
                                } else {
                                    want
                                };
                                assert_eq!(got[c], want, "({x},{y},{z}) c{c} half={half}");
                            }
                        } else {
                            assert_eq!(got, [0.0; 3]);
                        }
                    }
                }
            }
            assert!(seen > 0);
        }
    }
}
