//! Loading, welding and validating triangle meshes: [`load`] reads binary or ASCII STL
//! (told apart by content and size, not by a leading `solid`) or OBJ (through tobj,
//! triangulated), welds corners with bit-identical coordinates into shared vertices, builds
//! the edge table the slicer chains through and a [`MeshReport`] like admesh's.
//! [`binary_stl`] writes binary STL (`slice --supports-stl`, tests and tools that make
//! meshes).
//!
//! Invariants: all coordinates are finite; triangles with a repeated vertex are removed;
//! vertex and edge ids are in order of first appearance whatever the thread count; defects
//! are reported as warnings, never fatal (only a file with no usable geometry is an error).

mod obj;
mod stl;

pub use crate::input::MESH_MAX_BYTES;
pub use stl::binary_stl;

use crate::error::{Error, Result};
use crate::text::count;
use crate::warning::Warning;
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
    /// File format read: "stl-binary", "stl-ascii" or "obj"; "mixed" for a plate of parts
    /// in several formats.
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
    /// The warnings for the defects found (empty for a clean mesh). A count's figure is
    /// named after its code (`mesh.open-edges`: `open_edges`).
    pub fn warnings(&self) -> Vec<Warning> {
        let counts = [
            (
                "mesh.open-edges",
                self.open_edges,
                "open edge",
                " (holes); open section contours are closed or dropped",
            ),
            (
                "mesh.nonmanifold-edges",
                self.nonmanifold_edges,
                "non-manifold edge",
                "",
            ),
            (
                "mesh.backwards-edges",
                self.backwards_edges,
                "backwards edge",
                " (inconsistently oriented facets); contours are oriented by majority",
            ),
            (
                "mesh.degenerate-facets",
                self.degenerate_triangles,
                "degenerate triangle",
                "",
            ),
        ];
        let mut w: Vec<Warning> = counts
            .into_iter()
            .filter(|c| c.1 > 0)
            .map(|(code, n, what, more)| {
                let many = count(n, what, &format!("{what}s"));
                Warning::new(code, format!("mesh has {many}{more}"))
                    .with(&code[5..].replace('-', "_"), n)
            })
            .collect();
        if self.volume_mm3 < 0.0 {
            w.push(
                Warning::new(
                    "mesh.inverted-normals",
                    "mesh normals point inwards (negative volume); orientation is flipped for slicing",
                )
                .with("volume_mm3", self.volume_mm3),
            );
        }
        w
    }
}

/// A triangle soup straight from a file: corner positions, file order.
pub(crate) type Soup = Vec<[[f32; 3]; 3]>;

/// Loads a mesh file (STL binary/ASCII or OBJ), welds and validates it.
#[cfg(any(test, feature = "internals"))]
pub fn load(path: &Path) -> Result<Mesh> {
    let bytes = crate::input::read_file(path, "mesh file", crate::input::MESH_MAX_BYTES)?;
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
    use rayon::prelude::*;
    if let Some(i) = soup
        .par_iter()
        .with_min_len(4096)
        .position_first(|t| t.iter().flatten().any(|c| !c.is_finite()))
    {
        return Err(Error::input(
            path,
            format!("triangle {i} has a non-finite (NaN or infinite) coordinate"),
        ));
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

/// A corner position as bit patterns (+0.0 folds -0.0 into 0.0 so both weld together),
/// hashed as two words.
#[derive(Clone, Copy, PartialEq, Eq)]
struct CornerKey(u64, u32);

impl CornerKey {
    fn of(c: &[f32; 3]) -> CornerKey {
        let b = |v: f32| (v + 0.0).to_bits();
        CornerKey(b(c[0]) as u64 | (b(c[1]) as u64) << 32, b(c[2]))
    }

    /// The hash that picks a corner's shard (independent of the map's own hashing).
    fn shard_hash(self) -> u64 {
        (self.0 ^ (self.1 as u64).rotate_left(17)).wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }
}

impl std::hash::Hash for CornerKey {
    fn hash<H: Hasher>(&self, h: &mut H) {
        h.write_u64(self.0);
        h.write_u32(self.1);
    }
}

/// Welds the soup's corners: returns the distinct positions (in order of first
/// appearance) and each corner's vertex id (3 per triangle, file order).
///
/// The corners are split into shards by hash and each shard finds, in parallel, the first
/// corner with each of its positions; a sequential pass then numbers the first corners.
/// The result is the same for any number of shards.
fn weld(soup: &[[[f32; 3]; 3]]) -> (Vec<[f64; 3]>, Vec<u32>) {
    use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
    let corners: &[[f32; 3]] = soup.as_flattened();
    let nc = corners.len();
    let shards = rayon::current_num_threads().clamp(1, 16);
    // first[c]: index of the first corner at c's position (<= c).
    let first: Vec<AtomicU32> = (0..nc).map(|_| AtomicU32::new(0)).collect();
    let work = |s: usize| {
        let mut map: FxMap<CornerKey, u32> = FxMap::default();
        map.reserve(nc / (5 * shards) + 16);
        for (c, p) in corners.iter().enumerate() {
            let key = CornerKey::of(p);
            if shards > 1 && (key.shard_hash() >> 32) as usize % shards != s {
                continue;
            }
            let f = *map.entry(key).or_insert(c as u32);
            first[c].store(f, Relaxed);
        }
    };
    if shards == 1 {
        work(0);
    } else {
        use rayon::prelude::*;
        (0..shards).into_par_iter().for_each(work);
    }
    let mut ids = vec![0u32; nc];
    let mut vertices = Vec::with_capacity(nc / 5 + 16);
    for c in 0..nc {
        let f = first[c].load(Relaxed) as usize;
        ids[c] = if f == c {
            let p = corners[c];
            vertices.push([p[0] as f64, p[1] as f64, p[2] as f64]);
            vertices.len() as u32 - 1
        } else {
            ids[f]
        };
    }
    (vertices, ids)
}

/// Per-triangle edge ids and per-edge counts, see [`edge_table`].
struct EdgeTable {
    tri_edges: Vec<[u32; 3]>,
    /// Triangles using each edge.
    faces: Vec<u32>,
    /// Of those, how many traverse it from its lower to its higher vertex id.
    fwd: Vec<u32>,
    /// The first triangle using each edge.
    first_face: Vec<u32>,
}

/// Buckets bigger than this (a vertex that is the lower end of many edges, like the
/// centre of a large fan) are looked up in a hash map instead of scanned.
const BUCKET_SCAN: u32 = 32;

/// Numbers the edges (unordered vertex pairs) in order of first appearance. Each edge is
/// kept in the bucket of its lower vertex (buckets sized by a counting pass), so a lookup
/// scans a few neighbours of one vertex instead of probing a large hash table.
fn edge_table(triangles: &[[u32; 3]], nv: usize) -> EdgeTable {
    let mut start = vec![0u32; nv + 1];
    for t in triangles {
        for k in 0..3 {
            start[t[k].min(t[(k + 1) % 3]) as usize + 1] += 1;
        }
    }
    for i in 0..nv {
        start[i + 1] += start[i];
    }
    let mut fill: Vec<u32> = start[..nv].to_vec();
    // (hi, edge id) per slot.
    let mut slots = vec![(0u32, 0u32); start[nv] as usize];
    let mut big: FxMap<u64, u32> = FxMap::default();
    let cap = triangles.len() * 3 / 2 + 16;
    let mut table = EdgeTable {
        tri_edges: Vec::with_capacity(triangles.len()),
        faces: Vec::with_capacity(cap),
        fwd: Vec::with_capacity(cap),
        first_face: Vec::with_capacity(cap),
    };
    for (ti, t) in triangles.iter().enumerate() {
        let mut te = [0u32; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            let next = table.faces.len() as u32;
            let (s, f) = (start[lo as usize], fill[lo as usize]);
            let id = if start[lo as usize + 1] - s > BUCKET_SCAN {
                *big.entry((lo as u64) << 32 | hi as u64).or_insert(next)
            } else {
                match slots[s as usize..f as usize].iter().find(|e| e.0 == hi) {
                    Some(e) => e.1,
                    None => {
                        slots[f as usize] = (hi, next);
                        fill[lo as usize] += 1;
                        next
                    }
                }
            };
            if id == next {
                table.faces.push(0);
                table.fwd.push(0);
                table.first_face.push(ti as u32);
            }
            table.faces[id as usize] += 1;
            if a < b {
                table.fwd[id as usize] += 1;
            }
            te[k] = id;
        }
        table.tri_edges.push(te);
    }
    table
}

impl Mesh {
    /// Welds a triangle soup (corners with bit-identical coordinates become one vertex),
    /// drops triangles with a repeated vertex, builds the edge table and the report.
    ///
    /// Vertex and edge ids are numbered in order of first appearance (file order), so the
    /// result does not depend on how the work is split between threads.
    pub(crate) fn from_soup(soup: &[[[f32; 3]; 3]], format: &str) -> Mesh {
        let (vertices, corner_ids) = weld(soup);
        let mut triangles = Vec::with_capacity(soup.len());
        let mut degenerate = 0u64;
        for ids in corner_ids.chunks_exact(3) {
            if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
                degenerate += 1;
                continue;
            }
            triangles.push([ids[0], ids[1], ids[2]]);
        }
        drop(corner_ids);

        // Edge table: (lo, hi) -> edge id; per edge: faces and orientation balance.
        let EdgeTable {
            tri_edges,
            faces,
            fwd,
            first_face,
        } = edge_table(&triangles, vertices.len());
        let edge_count = faces.len();
        let open = faces.iter().filter(|&&n| n == 1).count() as u64;
        let backwards = faces
            .iter()
            .zip(&fwd)
            .filter(|&(&n, &f)| n == 2 && f != 1)
            .count() as u64;
        let nonmanifold = faces.iter().filter(|&&n| !(1..=2).contains(&n)).count() as u64;

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

        let cross = |u: [f64; 3], v: [f64; 3]| {
            [0, 1, 2].map(|i| u[(i + 1) % 3] * v[(i + 2) % 3] - u[(i + 2) % 3] * v[(i + 1) % 3])
        };
        let mut volume = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|v| vertices[v as usize]);
            let bc = cross(b, c);
            volume += (a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2]) / 6.0;
            let n = cross(
                [0, 1, 2].map(|i| b[i] - a[i]),
                [0, 1, 2].map(|i| c[i] - a[i]),
            );
            if n == [0.0; 3] {
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
            volume_mm3: crate::round::derived(volume),
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

    /// The triangles as corners (single precision, as an STL holds them).
    pub fn soup(&self) -> Soup {
        let f = |v: u32| self.vertices[v as usize].map(|c| c as f32);
        self.triangles.iter().map(|t| t.map(f)).collect()
    }

    /// Adds `d` to every vertex.
    pub fn translate(&mut self, d: [f64; 3]) {
        for v in &mut self.vertices {
            for k in 0..3 {
                v[k] += d[k];
            }
        }
    }

    /// Multiplies every vertex's coordinates by `f` (each > 0: the winding is kept).
    pub fn scale_axes(&mut self, f: [f64; 3]) {
        if f == [1.0; 3] {
            return;
        }
        for v in &mut self.vertices {
            for k in 0..3 {
                v[k] *= f[k];
            }
        }
    }

    /// Adds the triangles of `other` (a separate body: no vertex or edge is shared), its
    /// report's counts to this one's.
    pub fn append(&mut self, other: &Mesh) {
        let v0 = self.vertices.len() as u32;
        let e0 = self.edge_count as u32;
        self.vertices.extend_from_slice(&other.vertices);
        let shifted = |t: &[u32; 3], by: u32| t.map(|i| i + by);
        self.triangles
            .extend(other.triangles.iter().map(|t| shifted(t, v0)));
        self.tri_edges
            .extend(other.tri_edges.iter().map(|t| shifted(t, e0)));
        self.edge_count += other.edge_count;
        let (r, o) = (&mut self.report, &other.report);
        if r.format != o.format {
            r.format = "mixed".into();
        }
        r.triangles_in_file += o.triangles_in_file;
        r.triangles += o.triangles;
        r.vertices += o.vertices;
        r.edges += o.edges;
        r.shells += o.shells;
        r.open_edges += o.open_edges;
        r.nonmanifold_edges += o.nonmanifold_edges;
        r.backwards_edges += o.backwards_edges;
        r.degenerate_triangles += o.degenerate_triangles;
        r.volume_mm3 += o.volume_mm3;
        r.closed_manifold &= o.closed_manifold;
    }
}

/// An outward-facing cube of edge `s` with its lowest corner at `at` (for unit tests).
#[cfg(test)]
pub(crate) fn cube_soup(s: f32, at: [f32; 3]) -> Soup {
    // Corners 0..8 as bits x, y, z (in the order 0, x, xy, y, then z above them).
    const CORNERS: [u8; 8] = [0, 1, 3, 2, 4, 5, 7, 6];
    const FACES: [usize; 36] = [
        0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6,
        3, 0, 4, 3, 4, 7,
    ];
    let v = CORNERS.map(|b| [0, 1, 2].map(|k| at[k] + f32::from(b >> k & 1) * s));
    FACES
        .chunks(3)
        .map(|t| [v[t[0]], v[t[1]], v[t[2]]])
        .collect()
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
    fn appended_bodies_are_welded_as_one_soup_of_both_would_be() {
        let (a, b) = (cube_soup(10.0, [0.0; 3]), cube_soup(5.0, [20.0, 0.0, 0.0]));
        let mut m = Mesh::from_soup(&a, "stl-binary");
        m.append(&Mesh::from_soup(&b, "obj"));
        let both = Mesh::from_soup(&[a, b].concat(), "stl-binary");
        assert_eq!(
            (&m.vertices, &m.triangles, &m.tri_edges, m.edge_count),
            (
                &both.vertices,
                &both.triangles,
                &both.tri_edges,
                both.edge_count
            )
        );
        let r = &m.report;
        assert_eq!(
            (r.triangles, r.vertices, r.edges, r.shells),
            (24, 16, 36, 2)
        );
        assert!(r.closed_manifold && (r.volume_mm3 - 1125.0).abs() < 1e-9);
        assert_eq!(r.format, "mixed");
    }

    type Welded = (Vec<[f64; 3]>, Vec<[u32; 3]>, Vec<[u32; 3]>);

    /// The old single-threaded hash-map weld and edge numbering, as the reference.
    fn reference(soup: &[[[f32; 3]; 3]]) -> Welded {
        let mut vmap: HashMap<[u32; 3], u32> = HashMap::new();
        let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
        for t in soup {
            let ids = t.map(|c| {
                let key = c.map(|v| (v + 0.0).to_bits());
                let next = vmap.len() as u32;
                *vmap.entry(key).or_insert_with(|| {
                    vertices.push(c.map(|v| v as f64));
                    next
                })
            });
            if ids[0] != ids[1] && ids[1] != ids[2] && ids[0] != ids[2] {
                triangles.push(ids);
            }
        }
        let mut emap: HashMap<(u32, u32), u32> = HashMap::new();
        let tri_edges = triangles
            .iter()
            .map(|t| {
                [0, 1, 2].map(|k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    let next = emap.len() as u32;
                    *emap.entry((a.min(b), a.max(b))).or_insert(next)
                })
            })
            .collect();
        (vertices, triangles, tri_edges)
    }

    #[test]
    fn weld_and_edges_match_the_reference_at_any_thread_count() {
        // Fixed-seed soups on a small lattice (so corners repeat, in both -0.0 and 0.0),
        // with some big fans (buckets past BUCKET_SCAN) and degenerate triangles.
        let mut bits = crate::test_support::xorshift_bits(0x2545_f491_4f6c_dd1d);
        let mut rnd = |m: u64| bits() % m;
        for case in 0..6 {
            let lattice = [3, 6, 12, 40, 6, 3][case];
            let mut soup: Soup = Vec::new();
            for _ in 0..2000 {
                let mut t = [[0.0f32; 3]; 3];
                for c in &mut t {
                    for v in c.iter_mut() {
                        let q = rnd(lattice) as f32 - (lattice / 2) as f32;
                        *v = if q == 0.0 && rnd(2) == 0 {
                            -0.0
                        } else {
                            q * 0.5
                        };
                    }
                }
                soup.push(t);
            }
            if case >= 4 {
                // a fan of 200 triangles around the origin
                for i in 0..200 {
                    let a = i as f32 * 0.0314;
                    let b = (i + 1) as f32 * 0.0314;
                    soup.push([[0.0; 3], [a.cos(), a.sin(), 0.0], [b.cos(), b.sin(), 0.0]]);
                }
            }
            let (v, t, e) = reference(&soup);
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let m = pool.install(|| Mesh::from_soup(&soup, "test"));
                let got = (&m.vertices, &m.triangles, &m.tri_edges);
                assert_eq!(got, (&v, &t, &e), "case {case}, {threads} threads");
                let edges = e.iter().flatten().max().map_or(0, |&x| x as usize + 1);
                assert_eq!(m.edge_count, edges);
            }
        }
    }

    #[test]
    fn defects_are_counted() {
        let mut s = cube_soup(10.0, [0.0; 3]);
        s.pop(); // hole: 3 open edges
        let t = s[0];
        s[0] = [t[0], t[2], t[1]]; // flip a facet away from the hole: 3 backwards edges
        s.push([[0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]]); // repeated vertex: removed
        let m = Mesh::from_soup(&s, "test");
        let r = &m.report;
        let counts = (r.open_edges, r.backwards_edges, r.degenerate_triangles);
        assert_eq!((counts, r.triangles), ((3, 3, 1), 11));
        assert!(!r.closed_manifold);
        assert!(!r.warnings().is_empty());
    }
}
