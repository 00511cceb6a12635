//! Loading, welding and validating triangle meshes.
//!
//! [`load`] reads binary or ASCII STL (told apart by content and size, not by a leading
//! `solid`) or OBJ (through tobj, triangulated), welds corners with bit-identical
//! coordinates into shared vertices, builds the edge table the slicer chains through,
//! and produces a [`MeshReport`] like admesh's. Defective meshes load with warnings;
//! only files that hold no usable geometry are errors.

mod obj;
mod stl;

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::path::Path;

/// A welded triangle mesh with its edge table.
#[derive(Debug, Clone)]
pub struct Mesh {
    /// Welded vertex positions, mm.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as vertex indices, in file order (degenerate ones removed).
    pub triangles: Vec<[u32; 3]>,
    /// For each triangle, the edge ids of its edges (v0→v1, v1→v2, v2→v0).
    pub tri_edges: Vec<[u32; 3]>,
    /// Number of distinct edges.
    pub edge_count: usize,
    /// Validation report.
    pub report: MeshReport,
}

/// What the loader found wrong (or right) with a mesh, in the spirit of admesh.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshReport {
    /// File format read: "stl-binary", "stl-ascii" or "obj".
    pub format: String,
    /// Triangles in the file.
    pub triangles_in_file: u64,
    /// Triangles kept (file triangles minus those with repeated vertices).
    pub triangles: u64,
    /// Distinct vertices after welding.
    pub vertices: u64,
    /// Distinct edges.
    pub edges: u64,
    /// Connected pieces (triangles sharing edges).
    pub shells: u64,
    /// Edges used by one triangle only (holes in the surface).
    pub open_edges: u64,
    /// Edges used by more than two triangles.
    pub nonmanifold_edges: u64,
    /// Edges whose two triangles traverse them in the same direction (one of them is flipped).
    pub backwards_edges: u64,
    /// Triangles with a repeated vertex (removed) or zero area (kept).
    pub degenerate_triangles: u64,
    /// Signed enclosed volume, mm³ (negative: normals point inwards).
    pub volume_mm3: f64,
    /// True when the surface is closed, 2-manifold and consistently oriented.
    pub closed_manifold: bool,
}

impl MeshReport {
    /// Human-readable warnings for the defects found (empty for a clean mesh).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.open_edges > 0 {
            w.push(format!(
                "mesh has {} open edges (holes); open section contours are closed or dropped (see README)",
                self.open_edges
            ));
        }
        if self.nonmanifold_edges > 0 {
            w.push(format!(
                "mesh has {} non-manifold edges",
                self.nonmanifold_edges
            ));
        }
        if self.backwards_edges > 0 {
            w.push(format!(
                "mesh has {} backwards edges (inconsistently oriented facets); contours are oriented by majority",
                self.backwards_edges
            ));
        }
        if self.degenerate_triangles > 0 {
            w.push(format!(
                "mesh has {} degenerate triangles",
                self.degenerate_triangles
            ));
        }
        if self.volume_mm3 < 0.0 {
            w.push(
                "mesh normals point inwards (negative volume); orientation is flipped for slicing"
                    .into(),
            );
        }
        w
    }
}

/// A triangle soup straight from a file: corner positions, file order.
pub(crate) type Soup = Vec<[[f32; 3]; 3]>;

/// Loads a mesh file (STL binary/ASCII or OBJ), welds and validates it.
pub fn load(path: &Path) -> Result<Mesh> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Err(Error::input(path, "is a directory, not a mesh file"));
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    load_bytes(path, &bytes)
}

/// Like [`load`] on bytes already read; `path` names the file in errors and picks the
/// format by extension (`.obj` is OBJ, anything else STL).
pub fn load_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh> {
    if bytes.is_empty() {
        return Err(Error::input(path, "file is empty"));
    }
    let is_obj = path
        .extension()
        .map(|e| e.eq_ignore_ascii_case("obj"))
        .unwrap_or(false);
    let (soup, format) = if is_obj {
        (obj::parse(path, bytes)?, "obj")
    } else {
        stl::parse(path, bytes)?
    };
    if soup.is_empty() {
        return Err(Error::input(path, "contains no triangles"));
    }
    for (i, t) in soup.iter().enumerate() {
        if t.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::input(
                path,
                format!("triangle {i} has a non-finite (NaN or infinite) coordinate"),
            ));
        }
    }
    Ok(Mesh::from_soup(&soup, format))
}

#[derive(Default)]
struct FxHasher(u64);
impl Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(*b as u64);
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(i as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}
type FxMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;

impl Mesh {
    /// Welds a triangle soup (corners with bit-identical coordinates become one vertex),
    /// drops triangles with a repeated vertex, builds the edge table and the report.
    pub(crate) fn from_soup(soup: &[[[f32; 3]; 3]], format: &str) -> Mesh {
        let mut vmap: FxMap<[u32; 3], u32> = FxMap::default();
        vmap.reserve(soup.len() / 2 + 16);
        let mut vertices: Vec<[f64; 3]> = Vec::with_capacity(soup.len() / 2 + 16);
        let mut triangles = Vec::with_capacity(soup.len());
        let mut degenerate = 0u64;
        for t in soup {
            let mut ids = [0u32; 3];
            for (k, c) in t.iter().enumerate() {
                // +0.0 folds -0.0 into 0.0 so both weld together.
                let key = [
                    (c[0] + 0.0).to_bits(),
                    (c[1] + 0.0).to_bits(),
                    (c[2] + 0.0).to_bits(),
                ];
                let next = vertices.len() as u32;
                let id = *vmap.entry(key).or_insert_with(|| {
                    vertices.push([c[0] as f64, c[1] as f64, c[2] as f64]);
                    next
                });
                ids[k] = id;
            }
            if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
                degenerate += 1;
                continue;
            }
            triangles.push(ids);
        }
        drop(vmap);

        // Edge table: key (lo, hi) -> edge id; per edge: faces and orientation balance.
        let mut emap: FxMap<u64, u32> = FxMap::default();
        emap.reserve(triangles.len() * 3 / 2 + 16);
        let mut tri_edges = Vec::with_capacity(triangles.len());
        let mut faces: Vec<u32> = Vec::with_capacity(triangles.len() * 3 / 2 + 16);
        let mut fwd: Vec<u32> = Vec::with_capacity(triangles.len() * 3 / 2 + 16);
        let mut first_face: Vec<u32> = Vec::with_capacity(triangles.len() * 3 / 2 + 16);
        for (ti, t) in triangles.iter().enumerate() {
            let mut te = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                let key = (lo as u64) << 32 | hi as u64;
                let next = faces.len() as u32;
                let id = *emap.entry(key).or_insert_with(|| {
                    faces.push(0);
                    fwd.push(0);
                    first_face.push(ti as u32);
                    next
                });
                faces[id as usize] += 1;
                if a < b {
                    fwd[id as usize] += 1;
                }
                te[k] = id;
            }
            tri_edges.push(te);
        }
        let edge_count = faces.len();
        let mut open = 0;
        let mut nonmanifold = 0;
        let mut backwards = 0;
        for e in 0..edge_count {
            match faces[e] {
                1 => open += 1,
                2 => {
                    if fwd[e] != 1 {
                        backwards += 1
                    }
                }
                _ => nonmanifold += 1,
            }
        }

        // Shells: union-find over triangles sharing an edge.
        let mut parent: Vec<u32> = (0..triangles.len() as u32).collect();
        fn find(p: &mut [u32], mut x: u32) -> u32 {
            while p[x as usize] != x {
                p[x as usize] = p[p[x as usize] as usize];
                x = p[x as usize];
            }
            x
        }
        for (ti, te) in tri_edges.iter().enumerate() {
            for &e in te {
                let a = find(&mut parent, ti as u32);
                let b = find(&mut parent, first_face[e as usize]);
                if a != b {
                    parent[a as usize] = b;
                }
            }
        }
        let shells = (0..triangles.len() as u32)
            .filter(|&i| find(&mut parent, i) == i)
            .count() as u64;

        let mut volume = 0.0;
        for t in &triangles {
            let [a, b, c] = [
                vertices[t[0] as usize],
                vertices[t[1] as usize],
                vertices[t[2] as usize],
            ];
            let cross = [
                b[1] * c[2] - b[2] * c[1],
                b[2] * c[0] - b[0] * c[2],
                b[0] * c[1] - b[1] * c[0],
            ];
            volume += (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0;
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            if n[0] == 0.0 && n[1] == 0.0 && n[2] == 0.0 {
                degenerate += 1;
            }
        }

        let report = MeshReport {
            format: format.to_string(),
            triangles_in_file: soup.len() as u64,
            triangles: triangles.len() as u64,
            vertices: vertices.len() as u64,
            edges: edge_count as u64,
            shells,
            open_edges: open,
            nonmanifold_edges: nonmanifold,
            backwards_edges: backwards,
            degenerate_triangles: degenerate,
            volume_mm3: volume,
            closed_manifold: open == 0 && nonmanifold == 0 && backwards == 0,
        };
        Mesh {
            vertices,
            triangles,
            tri_edges,
            edge_count,
            report,
        }
    }

    /// Axis-aligned bounding box: [min, max].
    pub fn bbox(&self) -> [[f64; 3]; 2] {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in &self.triangles {
            for &v in t {
                let p = self.vertices[v as usize];
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        [lo, hi]
    }

    /// Adds `d` to every vertex.
    pub fn translate(&mut self, d: [f64; 3]) {
        for v in &mut self.vertices {
            for k in 0..3 {
                v[k] += d[k];
            }
        }
    }
}

/// An outward-facing cube of edge `s` with its lowest corner at `at` (test helper).
#[cfg(test)]
pub(crate) fn cube_soup(s: f32, at: [f32; 3]) -> Soup {
    let p = |x: f32, y: f32, z: f32| [at[0] + x * s, at[1] + y * s, at[2] + z * s];
    let v = [
        p(0., 0., 0.),
        p(1., 0., 0.),
        p(1., 1., 0.),
        p(0., 1., 0.),
        p(0., 0., 1.),
        p(1., 0., 1.),
        p(1., 1., 1.),
        p(0., 1., 1.),
    ];
    let f = [
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    f.iter().map(|t| [v[t[0]], v[t[1]], v[t[2]]]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_is_clean() {
        let m = Mesh::from_soup(&cube_soup(10.0, [0.0; 3]), "test");
        let r = &m.report;
        assert_eq!((r.triangles, r.vertices, r.edges, r.shells), (12, 8, 18, 1));
        assert!(r.closed_manifold, "{r:?}");
        assert!((r.volume_mm3 - 1000.0).abs() < 1e-9);
        assert!(r.warnings().is_empty());
    }

    #[test]
    fn defects_are_counted() {
        let mut s = cube_soup(10.0, [0.0; 3]);
        s.pop(); // hole: 3 open edges
        let t = s[0];
        s[0] = [t[0], t[2], t[1]]; // flip one facet: 3 backwards edges (one is open now? no)
        s.push([[0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]]); // repeated vertex: removed
        let m = Mesh::from_soup(&s, "test");
        let r = &m.report;
        assert_eq!(r.open_edges, 3);
        assert_eq!(r.backwards_edges, 3);
        assert_eq!(r.degenerate_triangles, 1);
        assert_eq!(r.triangles, 11);
        assert!(!r.closed_manifold);
        assert!(!r.warnings().is_empty());
    }
}
