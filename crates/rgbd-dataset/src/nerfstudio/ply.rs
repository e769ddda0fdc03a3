//! The points of a PLY file (`x`, `y`, `z` of its `vertex` element), as nerfstudio's
//! `ns-process-data` writes its sparse cloud (`sparse_pc.ply`: ASCII, float coordinates, uint8
//! colours) and as other tools write theirs (Open3D: binary little-endian, doubles): ASCII or
//! binary of either byte order, coordinates of any numeric type, other properties skipped. In binary files, elements
//! before `vertex` must have fixed-size rows (lists there would have to be parsed to be skipped).

use std::path::Path;

use glam::DVec3;

use crate::error::{io_error, Error, Result};

/// How the rows are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

/// A PLY scalar type, by its size in bytes and kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    Int(usize),
    Uint(usize),
    Float(usize),
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::Int(1),
            "uchar" | "uint8" => Self::Uint(1),
            "short" | "int16" => Self::Int(2),
            "ushort" | "uint16" => Self::Uint(2),
            "int" | "int32" => Self::Int(4),
            "uint" | "uint32" => Self::Uint(4),
            "float" | "float32" => Self::Float(4),
            "double" | "float64" => Self::Float(8),
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::Int(n) | Self::Uint(n) | Self::Float(n) => n,
        }
    }

    /// The value of `bytes` (exactly [`Scalar::size`] of them) in `encoding`'s byte order.
    fn read(self, bytes: &[u8], encoding: Encoding) -> f64 {
        let mut b = [0u8; 8];
        let n = bytes.len();
        if encoding == Encoding::BigEndian {
            for (i, &v) in bytes.iter().rev().enumerate() {
                b[i] = v;
            }
        } else {
            b[..n].copy_from_slice(bytes);
        }
        match self {
            Self::Float(4) => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Self::Float(_) => f64::from_le_bytes(b),
            Self::Uint(_) => u64::from_le_bytes(b) as f64,
            Self::Int(_) => {
                // Sign-extend from n bytes.
                let shift = 64 - 8 * n as u32;
                ((i64::from_le_bytes(b) << shift) >> shift) as f64
            }
        }
    }
}

/// One element of the header: its name, row count and properties (`None`: a list property).
struct Element {
    name: String,
    count: usize,
    properties: Vec<(String, Option<Scalar>)>,
}

/// The points of the PLY file at `path`; errors name the file and what is wrong (not a PLY, no
/// `vertex` element or no `x`, `y`, `z`, an unknown type, a file shorter than its header says,
/// a coordinate that is not a finite number).
pub fn read_points(path: &Path) -> Result<Vec<DVec3>> {
    let bytes = std::fs::read(path).map_err(io_error(path))?;
    let error = |why: String| Error::Dataset {
        path: path.to_path_buf(),
        frame: None,
        why,
    };
    let (encoding, elements, body) = header(&bytes).map_err(error)?;
    let mut skipped_rows = 0usize;
    let mut skipped_bytes = 0usize;
    for element in &elements {
        if element.name == "vertex" {
            // ASCII rows are lines, skipped by count; binary ones by their bytes.
            let body = match encoding {
                Encoding::Ascii => body,
                _ => &body[skipped_bytes.min(body.len())..],
            };
            return vertices(element, encoding, body, skipped_rows).map_err(error);
        }
        let mut row = 0;
        for (name, scalar) in &element.properties {
            let Some(scalar) = scalar else {
                if encoding == Encoding::Ascii {
                    continue;
                }
                return Err(error(format!(
                    "element `{}` comes before `vertex` and has the list property `{name}`: \
                     volgen reads binary files whose `vertex` element comes first or after \
                     fixed-size ones",
                    element.name
                )));
            };
            row += scalar.size();
        }
        skipped_rows += element.count;
        skipped_bytes += element.count * row;
    }
    Err(error(
        "no `vertex` element: expected the points as `element vertex N` with x, y, z".into(),
    ))
}

/// The header's encoding and elements, and the bytes after `end_header`.
fn header(bytes: &[u8]) -> Result<(Encoding, Vec<Element>, &[u8]), String> {
    let end = b"end_header";
    let at = bytes
        .windows(end.len())
        .position(|w| w == end)
        .ok_or("not a PLY file: no `end_header` line")?;
    let mut body_start = at + end.len();
    // The header ends with its newline (\n, or \r\n).
    if bytes.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if bytes.get(body_start) == Some(&b'\n') {
        body_start += 1;
    }
    let text = std::str::from_utf8(&bytes[..at]).map_err(|_| "the header is not text")?;
    let mut lines = text.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err("not a PLY file: the first line is not `ply`".into());
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", format, _version] => {
                encoding = Some(match *format {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::LittleEndian,
                    "binary_big_endian" => Encoding::BigEndian,
                    other => return Err(format!("unknown format `{other}`")),
                });
            }
            ["element", name, count] => elements.push(Element {
                name: (*name).to_owned(),
                count: count
                    .parse()
                    .map_err(|_| format!("element `{name}`: count `{count}` is not a number"))?,
                properties: Vec::new(),
            }),
            ["property", "list", _, _, name] => last(&mut elements, line)?
                .properties
                .push(((*name).to_owned(), None)),
            ["property", kind, name] => {
                let scalar = Scalar::parse(kind)
                    .ok_or_else(|| format!("property `{name}` has the unknown type `{kind}`"))?;
                last(&mut elements, line)?
                    .properties
                    .push(((*name).to_owned(), Some(scalar)));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => return Err(format!("header line `{line}` is not PLY")),
        }
    }
    let encoding = encoding.ok_or("the header has no `format` line")?;
    Ok((encoding, elements, &bytes[body_start..]))
}

fn last<'a>(elements: &'a mut [Element], line: &str) -> Result<&'a mut Element, String> {
    elements
        .last_mut()
        .ok_or_else(|| format!("`{line}` comes before any `element` line"))
}

/// The `x`, `y`, `z` of every row of `vertex`, read from `body` (binary: starting at its rows;
/// ASCII: after `skipped_rows` lines of earlier elements).
fn vertices(
    vertex: &Element,
    encoding: Encoding,
    body: &[u8],
    skipped_rows: usize,
) -> Result<Vec<DVec3>, String> {
    let index = |axis: &str| {
        vertex
            .properties
            .iter()
            .position(|(name, _)| name == axis)
            .ok_or_else(|| format!("element `vertex` has no property `{axis}`"))
    };
    let axes = [index("x")?, index("y")?, index("z")?];
    let mut points = Vec::with_capacity(vertex.count);
    if encoding == Encoding::Ascii {
        let text = std::str::from_utf8(body).map_err(|_| "the ASCII body is not text")?;
        let mut rows = text
            .lines()
            .filter(|l| !l.trim().is_empty())
            .skip(skipped_rows);
        for i in 0..vertex.count {
            let row = rows.next().ok_or_else(|| {
                format!(
                    "vertex {i}: the file ends, the header says {}",
                    vertex.count
                )
            })?;
            let values: Vec<&str> = row.split_whitespace().collect();
            let coordinate = |at: usize| {
                values
                    .get(at)
                    .and_then(|v| v.parse::<f64>().ok())
                    .ok_or_else(|| format!("vertex {i}: `{row}` has no number at column {at}"))
            };
            points.push(point(
                i,
                [
                    coordinate(axes[0])?,
                    coordinate(axes[1])?,
                    coordinate(axes[2])?,
                ],
            )?);
        }
        return Ok(points);
    }
    let mut offsets = Vec::with_capacity(vertex.properties.len());
    let mut row = 0;
    for (name, scalar) in &vertex.properties {
        let scalar = scalar.ok_or_else(|| {
            format!(
                "element `vertex` has the list property `{name}`: volgen reads fixed-size points"
            )
        })?;
        offsets.push((row, scalar));
        row += scalar.size();
    }
    if body.len() < vertex.count * row {
        return Err(format!(
            "the file ends after {} of its {} points",
            body.len() / row.max(1),
            vertex.count
        ));
    }
    for (i, bytes) in body.chunks_exact(row).take(vertex.count).enumerate() {
        let value = |axis: usize| {
            let (at, scalar) = offsets[axis];
            scalar.read(&bytes[at..at + scalar.size()], encoding)
        };
        points.push(point(i, [value(axes[0]), value(axes[1]), value(axes[2])])?);
    }
    Ok(points)
}

fn point(i: usize, xyz: [f64; 3]) -> Result<DVec3, String> {
    if xyz.iter().all(|v| v.is_finite()) {
        Ok(DVec3::from(xyz))
    } else {
        Err(format!("vertex {i} is at {xyz:?}, not a finite point"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn written(bytes: &[u8]) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("points.ply");
        std::fs::write(&path, bytes).unwrap();
        (dir, path)
    }

    /// Open3D's layout (doubles, then colours as bytes), and big-endian floats after another
    /// element.
    #[test]
    fn binary_points_of_every_byte_order_and_type_are_read() {
        let points = [[1.5, -2.0, 0.25], [-3.0, 4.0, 1e-3]];
        let mut le = b"ply\nformat binary_little_endian 1.0\ncomment made here\nelement vertex 2\n\
            property double x\nproperty double y\nproperty double z\nproperty uchar red\n\
            property uchar green\nproperty uchar blue\nend_header\n"
            .to_vec();
        let mut be =
            b"ply\r\nformat binary_big_endian 1.0\r\nelement camera 1\r\nproperty int id\r\n\
            element vertex 2\r\nproperty short s\r\nproperty float x\r\nproperty float y\r\n\
            property float z\r\nend_header\r\n"
                .to_vec();
        be.extend(7i32.to_be_bytes());
        for p in points {
            for v in p {
                le.extend(f64::to_le_bytes(v));
            }
            le.extend([200, 100, 50]);
            be.extend((-5i16).to_be_bytes());
            for v in p {
                be.extend((v as f32).to_be_bytes());
            }
        }
        for bytes in [le, be] {
            let (_dir, path) = written(&bytes);
            let read = read_points(&path).unwrap();
            for (r, p) in read.iter().zip(points) {
                assert!(
                    (*r - DVec3::from(p)).abs().max_element() < 1e-6,
                    "{r} {p:?}"
                );
            }
            assert_eq!(read.len(), 2);
        }
        // Integer coordinates, sign-extended.
        assert_eq!(
            Scalar::Int(2).read(&(-3i16).to_le_bytes(), Encoding::LittleEndian),
            -3.0
        );
        assert_eq!(
            Scalar::Uint(2).read(&(65000u16).to_be_bytes(), Encoding::BigEndian),
            65000.0
        );
    }

    #[test]
    fn ascii_points_after_other_elements_are_read() {
        let text = "ply\nformat ascii 1.0\nelement note 1\nproperty int n\nelement vertex 2\n\
                    property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n\
                    9\n1 2 3 255\n-1 0.5 2e2 0\n3 0 1 1\n";
        let (_dir, path) = written(text.as_bytes());
        assert_eq!(
            read_points(&path).unwrap(),
            vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(-1.0, 0.5, 200.0)]
        );
    }

    #[test]
    fn malformed_files_are_refused_naming_the_file_and_the_problem() {
        let cases: [(&[u8], &str); 7] = [
            (b"solid mesh\nend_header\n", "first line is not `ply`"),
            (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no `end_header`"),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
                "no property `z`",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n",
                "the header says 2",
            ),
            (
                b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0",
                "ends after 0 of its 2 points",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
                "unknown type `half`",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 nan 3\n",
                "not a finite point",
            ),
        ];
        for (bytes, expected) in cases {
            let (_dir, path) = written(bytes);
            let err = read_points(&path).unwrap_err().to_string();
            assert!(
                err.contains("points.ply") && err.contains(expected),
                "{err}"
            );
        }
        let err = read_points(Path::new("/nonexistent/sparse_pc.ply")).unwrap_err();
        assert!(err.to_string().contains("sparse_pc.ply"));
    }
}
