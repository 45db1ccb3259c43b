//! Binary STL: the part files a slicer opens one at a time.
//!
//! Owns the binary layout: an 80-byte header (ours says "mpc-rig binary STL, mm" and the
//! part's name, and never starts with `solid`, which readers take for ASCII), a `u32` facet
//! count, and per facet a unit normal, three corners as little-endian `f32` millimetres and a
//! zero attribute word. STL has no units: millimetres is what slicers assume.
//!
//! Reading welds corners with bit-identical coordinates back into one vertex (after mapping
//! −0.0 to 0.0) and recomputes nothing else: the stored facet normals are ignored, since the
//! corner order already says which way a face points. A mesh written and read back therefore
//! has the same triangles with its vertices rounded to `f32`; vertices come back in the order
//! the triangles first use them, and two vertices that round to the same `f32` point become
//! one. Reading does not check the mesh (use [`Mesh::check`]) and does not read ASCII STL.

use std::path::{Path, PathBuf};

use crate::geometry::mesh::Mesh;

/// Bytes before the facet count.
const HEADER_LEN: usize = 80;
/// Bytes per facet: normal, three corners (12 × f32) and the attribute word.
const FACET_LEN: usize = 50;

/// Why an STL file could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum StlError {
    /// The file could not be created, written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// The mesh cannot be written as STL, or the bytes are not a binary STL.
    #[error("{path}: {source}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: StlFormatError,
    },
}

/// What is wrong with a mesh to write or with the bytes read.
#[derive(Debug, thiserror::Error)]
pub enum StlFormatError {
    /// The mesh has more triangles than a binary STL can count (`u32`).
    #[error("{0} triangles do not fit a binary STL (at most {max})", max = u32::MAX)]
    TooManyTriangles(usize),
    /// A triangle refers to a vertex the mesh does not have.
    #[error("triangle {triangle} refers to vertex {vertex}, but the mesh has {vertices}")]
    BadIndex {
        /// Index of the triangle.
        triangle: usize,
        /// The index out of range.
        vertex: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// The length does not match a binary STL with the count in its header.
    #[error(
        "not a binary STL: the header counts {facets} facets ({expected} bytes) but the file \
         has {actual} bytes{hint}",
        hint = if *ascii { " (it starts with `solid`: ASCII STL is not read)" } else { "" }
    )]
    Length {
        /// Facets the header announces (0 when the file is shorter than a header).
        facets: u64,
        /// Length those facets need.
        expected: u64,
        /// Length of the file.
        actual: u64,
        /// The file starts with `solid`.
        ascii: bool,
    },
    /// A corner coordinate is NaN or infinite.
    #[error("facet {0} has a coordinate that is not a finite number")]
    NotFinite(usize),
}

/// Write `mesh` as a binary STL at `path`; `name` goes into the header (truncated to fit).
pub fn write_stl(path: &Path, mesh: &Mesh, name: &str) -> Result<(), StlError> {
    let bytes = stl_bytes(mesh, name).map_err(|source| StlError::Format {
        path: path.to_path_buf(),
        source,
    })?;
    std::fs::write(path, bytes).map_err(|source| StlError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The bytes of a binary STL of `mesh`.
pub fn stl_bytes(mesh: &Mesh, name: &str) -> Result<Vec<u8>, StlFormatError> {
    let count = u32::try_from(mesh.triangles.len())
        .map_err(|_| StlFormatError::TooManyTriangles(mesh.triangles.len()))?;
    let nv = mesh.vertices.len();
    let mut out = Vec::with_capacity(HEADER_LEN + 4 + FACET_LEN * mesh.triangles.len());
    let mut header = format!("mpc-rig binary STL, mm: {name}").into_bytes();
    header.resize(HEADER_LEN, b' ');
    out.extend_from_slice(&header[..HEADER_LEN]);
    out.extend_from_slice(&count.to_le_bytes());
    for (i, t) in mesh.triangles.iter().enumerate() {
        if let Some(&v) = t.iter().find(|&&v| v as usize >= nv) {
            return Err(StlFormatError::BadIndex {
                triangle: i,
                vertex: v,
                vertices: nv,
            });
        }
        for x in mesh.face_normal(i) {
            out.extend_from_slice(&(x as f32).to_le_bytes());
        }
        for &v in t {
            for x in mesh.vertices[v as usize] {
                out.extend_from_slice(&(x as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&0u16.to_le_bytes());
    }
    Ok(out)
}

/// Read a binary STL, welding bit-identical corners (see the module doc).
pub fn read_stl(path: &Path) -> Result<Mesh, StlError> {
    let bytes = std::fs::read(path).map_err(|source| StlError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_stl(&bytes).map_err(|source| StlError::Format {
        path: path.to_path_buf(),
        source,
    })
}

/// Parse the bytes of a binary STL, welding bit-identical corners (see the module doc).
pub fn parse_stl(bytes: &[u8]) -> Result<Mesh, StlFormatError> {
    let actual = bytes.len() as u64;
    let ascii = bytes.starts_with(b"solid");
    let facets = if bytes.len() >= HEADER_LEN + 4 {
        u64::from(u32::from_le_bytes(
            bytes[HEADER_LEN..HEADER_LEN + 4]
                .try_into()
                .expect("4 bytes"),
        ))
    } else {
        0
    };
    let expected = (HEADER_LEN + 4) as u64 + FACET_LEN as u64 * facets;
    if actual != expected {
        return Err(StlFormatError::Length {
            facets,
            expected,
            actual,
            ascii,
        });
    }
    let facets = facets as usize;
    let mut mesh = Mesh {
        vertices: Vec::with_capacity(facets / 2 + 3),
        triangles: Vec::with_capacity(facets),
    };
    let mut index =
        rustc_hash::FxHashMap::with_capacity_and_hasher(facets / 2 + 3, Default::default());
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    for f in 0..facets {
        let base = HEADER_LEN + 4 + f * FACET_LEN + 12;
        let mut t = [0u32; 3];
        for (c, slot) in t.iter_mut().enumerate() {
            let mut p = [0f32; 3];
            for (k, x) in p.iter_mut().enumerate() {
                *x = f32_at(base + 12 * c + 4 * k);
                if !x.is_finite() {
                    return Err(StlFormatError::NotFinite(f));
                }
                if *x == 0.0 {
                    *x = 0.0; // −0.0 and 0.0 are one point
                }
            }
            let key = p.map(f32::to_bits);
            *slot = *index.entry(key).or_insert_with(|| {
                mesh.vertices.push(p.map(f64::from));
                (mesh.vertices.len() - 1) as u32
            });
        }
        mesh.triangles.push(t);
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::{torus, uv_sphere};

    /// A written and read mesh has, triangle by triangle, the same corners rounded to f32,
    /// as many vertices (all distinct in f32) and still passes the edge check: the round
    /// trip loses nothing but f64 → f32.
    #[test]
    fn round_trip_equals_what_was_written() {
        let mut m = torus([10.0, -3.0, 2.5], 12.3, 4.1, 40, 24);
        m.translate([0.123_456_789, 0.0, 0.0]);
        let back = parse_stl(&stl_bytes(&m, "torus").unwrap()).unwrap();
        assert_eq!(back.triangles.len(), m.triangles.len());
        assert_eq!(back.vertices.len(), m.vertices.len());
        for f in 0..m.triangles.len() {
            let want = m.corners(f).map(|p| p.map(|x| f64::from(x as f32)));
            assert_eq!(back.corners(f), want, "triangle {f}");
        }
        assert!(back.check().is_closed_manifold());
    }

    /// The file is exactly 84 + 50·n bytes, its header names the part and does not start
    /// with `solid`, and each stored normal is the unit right-hand-rule normal.
    #[test]
    fn layout_and_normals() {
        let m = uv_sphere([0.0; 3], 2.0, 12, 6);
        let b = stl_bytes(&m, "follower").unwrap();
        assert_eq!(b.len(), 84 + 50 * m.triangles.len());
        assert!(b.starts_with(b"mpc-rig binary STL, mm: follower"));
        for f in 0..m.triangles.len() {
            let o = 84 + 50 * f;
            let n: Vec<f64> = (0..3)
                .map(|k| {
                    f64::from(f32::from_le_bytes(
                        b[o + 4 * k..o + 4 * k + 4].try_into().unwrap(),
                    ))
                })
                .collect();
            let e = m.face_normal(f);
            let d: f64 = (0..3).map(|k| n[k] * e[k]).sum();
            assert!((d - 1.0).abs() < 1e-6, "facet {f}: {n:?} vs {e:?}");
        }
    }

    /// Malformed files are refused with what is wrong: a truncated file, an ASCII file, a
    /// NaN coordinate, and a mesh with an index out of range on writing.
    #[test]
    fn malformed_input_is_named() {
        let m = uv_sphere([0.0; 3], 1.0, 6, 3);
        let b = stl_bytes(&m, "x").unwrap();
        let e = parse_stl(&b[..b.len() - 1]).unwrap_err().to_string();
        assert!(
            e.contains("header counts 24 facets (1284 bytes) but the file has 1283"),
            "{e}"
        );

        let e = parse_stl(b"solid cube\n facet normal 0 0 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("ASCII STL is not read"), "{e}");

        let mut nan = b.clone();
        let o = 84 + 50 * 5 + 12 + 4;
        nan[o..o + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = read_or_parse_error(&nan);
        assert!(
            e.contains("facet 5 has a coordinate that is not a finite number"),
            "{e}"
        );

        let mut bad = m.clone();
        bad.triangles[3][1] = 999;
        let e = stl_bytes(&bad, "x").unwrap_err().to_string();
        assert!(e.contains("triangle 3 refers to vertex 999"), "{e}");
    }

    fn read_or_parse_error(bytes: &[u8]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("part.stl");
        std::fs::write(&path, bytes).unwrap();
        let e = read_stl(&path).unwrap_err().to_string();
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        e
    }

    /// Corners at −0.0 and 0.0 weld into one vertex.
    #[test]
    fn negative_zero_welds() {
        let m = Mesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [-0.0, 0.0, 0.0],
            ],
            triangles: vec![[0, 1, 2], [3, 2, 1]],
        };
        let back = parse_stl(&stl_bytes(&m, "x").unwrap()).unwrap();
        assert_eq!(back.vertices.len(), 3);
        assert_eq!(back.triangles, vec![[0, 1, 2], [0, 2, 1]]);
    }
}
