//! Surface meshes of radiance fields: the level set `σ(x) = level` of the density, sampled on a
//! regular grid and triangulated by marching tetrahedra, coloured by the field at the vertices,
//! written as binary PLY (MeshLab, Open3D and CloudCompare read it).
//!
//! Each grid cell is split into the six tetrahedra of Kuhn's triangulation (the paths from corner
//! `000` to `111` along the axes in every order). Neighbouring cells split their shared faces the
//! same way, so the surface has no cracks, and a tetrahedron's four corners have no ambiguous
//! case: one corner apart gives a triangle, two against two a quad.

use std::collections::HashMap;
use std::io::Write as _;
use std::path::Path;

use anyhow::Context as _;

use crate::field3d::RadianceField;

/// A triangle mesh with optional per-vertex colours.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, world coordinates.
    pub vertices: Vec<[f32; 3]>,
    /// Vertex colours (empty, or one per vertex).
    pub colors: Vec<[u8; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from outside (normals point from
    /// high density into free space).
    pub triangles: Vec<[u32; 3]>,
}

/// A regular grid of sample nodes: node `(i, j, k)` lies at `origin + voxel · (i, j, k)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Position of node `(0, 0, 0)`.
    pub origin: [f64; 3],
    /// Node spacing.
    pub voxel: f64,
    /// Nodes per axis (each ≥ 2).
    pub dims: [usize; 3],
}

impl Grid {
    /// The grid of spacing `voxel` covering the box `[min, max]`.
    pub fn covering(min: [f64; 3], max: [f64; 3], voxel: f64) -> anyhow::Result<Self> {
        if !(voxel > 0.0 && voxel.is_finite()) {
            anyhow::bail!("mesh voxel size must be a positive number, got {voxel}");
        }
        let mut dims = [0.0; 3];
        for a in 0..3 {
            let extent = max[a] - min[a];
            if !(extent > 0.0 && extent.is_finite()) {
                anyhow::bail!("mesh box {min:?}..{max:?} is empty along axis {a}");
            }
            dims[a] = (extent / voxel).ceil() + 1.0;
        }
        // Counted in f64: a tiny voxel must be refused, not overflow the count.
        let nodes = dims.iter().product::<f64>();
        if nodes > MAX_NODES as f64 {
            anyhow::bail!(
                "a {voxel} m mesh grid over {min:?}..{max:?} has {nodes} nodes (at most \
                 {MAX_NODES}): choose a larger voxel"
            );
        }
        Ok(Self {
            origin: min,
            voxel,
            dims: dims.map(|d| d as usize),
        })
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// `true` if the grid has no node.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Flat index of node `(i, j, k)` (x fastest).
    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Integer coordinates `(i, j, k)` of the node with flat index `n`.
    fn lattice(&self, n: usize) -> [i64; 3] {
        [
            (n % self.dims[0]) as i64,
            ((n / self.dims[0]) % self.dims[1]) as i64,
            (n / (self.dims[0] * self.dims[1])) as i64,
        ]
    }

    /// Sign of `det(b − a, c − a, d − a)` for nodes given by flat index (exact).
    fn orientation(&self, a: usize, b: usize, c: usize, d: usize) -> i64 {
        let [a, b, c, d] = [a, b, c, d].map(|n| self.lattice(n));
        let [u, v, w] = [b, c, d].map(|p| [p[0] - a[0], p[1] - a[1], p[2] - a[2]]);
        (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))
            .signum()
    }

    /// Position of the node with flat index `n`.
    pub fn node(&self, n: usize) -> [f64; 3] {
        let l = self.lattice(n);
        std::array::from_fn(|a| self.origin[a] + self.voxel * l[a] as f64)
    }
}

/// Upper bound on grid nodes (≈ 1 GB of samples and positions).
const MAX_NODES: usize = 1 << 27;

/// Cube corner `c` (bits: x = 1, y = 2, z = 4) → offsets.
const fn corner(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// Kuhn's six tetrahedra of the unit cube, as cube corners.
const TETRAHEDRA: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// The surface `values = level` of samples on `grid` (`values[grid.index(i, j, k)]`; "inside"
/// is above `level`). Non-finite samples count as outside.
pub fn isosurface(values: &[f32], grid: &Grid, level: f32) -> Mesh {
    assert_eq!(values.len(), grid.len(), "one sample per grid node");
    let inside = |n: usize| values[n] > level; // NaN compares false: outside.
    let mut mesh = Mesh::default();
    let mut edge_vertex: HashMap<(u32, u32), u32> = HashMap::new();
    let [nx, ny, nz] = grid.dims;
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let nodes: [usize; 8] = std::array::from_fn(|c| {
                    let [di, dj, dk] = corner(c);
                    grid.index(i + di, j + dj, k + dk)
                });
                let count = nodes.iter().filter(|&&n| inside(n)).count();
                if count == 0 || count == 8 {
                    continue;
                }
                for tet in TETRAHEDRA {
                    let t = tet.map(|c| nodes[c]);
                    polygonise(
                        &t,
                        values,
                        grid,
                        level,
                        &inside,
                        &mut edge_vertex,
                        &mut mesh,
                    );
                }
            }
        }
    }
    mesh
}

/// Adds the surface inside one tetrahedron (node indices `t`). The winding follows from the
/// sign of the tetrahedron's volume, exact on the integer node lattice: for a positively oriented
/// `(i, o₁, o₂, o₃)` the triangle on the edges `i–o₁, i–o₂, i–o₃` faces away from `i`, and for a
/// positively oriented `(a, b, c, d)` the quad on `a–c, a–d, b–d, b–c` faces from `a, b` towards
/// `c, d`; both stay true wherever the crossings lie on their edges.
fn polygonise(
    t: &[usize; 4],
    values: &[f32],
    grid: &Grid,
    level: f32,
    inside: &impl Fn(usize) -> bool,
    edge_vertex: &mut HashMap<(u32, u32), u32>,
    mesh: &mut Mesh,
) {
    let (mut ins, mut outs) = ([0; 4], [0; 4]);
    let (mut ni, mut no) = (0, 0);
    for &n in t {
        if inside(n) {
            ins[ni] = n;
            ni += 1;
        } else {
            outs[no] = n;
            no += 1;
        }
    }
    let mut vertex = |a: usize, b: usize| -> u32 {
        let key = (a.min(b) as u32, a.max(b) as u32);
        *edge_vertex.entry(key).or_insert_with(|| {
            // Linear interpolation of the crossing on edge a–b.
            let (va, vb) = (values[a] as f64, values[b] as f64);
            let s = if va.is_finite() && vb.is_finite() && va != vb {
                ((level as f64 - va) / (vb - va)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            let (pa, pb) = (grid.node(a), grid.node(b));
            mesh.vertices.push(std::array::from_fn(|c| {
                (pa[c] + s * (pb[c] - pa[c])) as f32
            }));
            (mesh.vertices.len() - 1) as u32
        })
    };
    let positive = |a: usize, b: usize, c: usize, d: usize| grid.orientation(a, b, c, d) > 0;
    let polygon: [u32; 4] = match ni {
        1 => {
            let (i, [o1, o2, o3]) = (ins[0], [outs[0], outs[1], outs[2]]);
            let (o2, o3) = if positive(i, o1, o2, o3) {
                (o2, o3)
            } else {
                (o3, o2)
            };
            let v = [vertex(i, o1), vertex(i, o2), vertex(i, o3)];
            [v[0], v[1], v[2], u32::MAX]
        }
        3 => {
            let (o, [i1, i2, i3]) = (outs[0], [ins[0], ins[1], ins[2]]);
            let (i2, i3) = if positive(o, i1, i2, i3) {
                (i3, i2)
            } else {
                (i2, i3)
            };
            let v = [vertex(i1, o), vertex(i2, o), vertex(i3, o)];
            [v[0], v[1], v[2], u32::MAX]
        }
        2 => {
            let (a, b) = (ins[0], ins[1]);
            let (c, d) = if positive(a, b, outs[0], outs[1]) {
                (outs[0], outs[1])
            } else {
                (outs[1], outs[0])
            };
            [vertex(a, c), vertex(a, d), vertex(b, d), vertex(b, c)]
        }
        _ => return,
    };
    let corners = if polygon[3] == u32::MAX { 3 } else { 4 };
    for tri in [[0, 1, 2], [0, 2, 3]].iter().take(corners - 2) {
        let tri = tri.map(|c| polygon[c]);
        if tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2] {
            mesh.triangles.push(tri);
        }
    }
}

/// Points per field evaluation (bounds the field's buffers).
const CHUNK: usize = 1 << 16;

/// Evaluates `field` at `points` (`n × 3`) in chunks into densities and colours.
fn evaluate<F: RadianceField<f32> + ?Sized>(
    field: &mut F,
    points: impl ExactSizeIterator<Item = [f64; 3]>,
    sigma: &mut Vec<f32>,
    rgb: &mut Vec<f32>,
) {
    let n = points.len();
    sigma.resize(n, 0.0);
    rgb.resize(3 * n, 0.0);
    let mut buffer = Vec::with_capacity(3 * CHUNK);
    let mut start = 0;
    let mut points = points.peekable();
    while points.peek().is_some() {
        buffer.clear();
        for p in points.by_ref().take(CHUNK) {
            buffer.extend(p.map(|x| x as f32));
        }
        let m = buffer.len() / 3;
        field.forward(
            &buffer,
            &mut sigma[start..start + m],
            &mut rgb[3 * start..3 * (start + m)],
        );
        start += m;
    }
}

/// The coloured surface `σ = level` of `field` on `grid`, keeping the triangles whose centroid
/// satisfies `keep` (e.g. space observed by a camera; unobserved space holds arbitrary density).
pub fn extract<F: RadianceField<f32> + ?Sized>(
    field: &mut F,
    grid: &Grid,
    level: f32,
    keep: impl Fn([f64; 3]) -> bool,
) -> Mesh {
    let (mut sigma, mut rgb) = (Vec::new(), Vec::new());
    evaluate(
        field,
        (0..grid.len()).map(|n| grid.node(n)),
        &mut sigma,
        &mut rgb,
    );
    let mut mesh = isosurface(&sigma, grid, level);
    mesh.retain_triangles(|tri, vertices| {
        let c = tri.map(|v| vertices[v as usize]);
        keep(std::array::from_fn(|k| {
            (c[0][k] as f64 + c[1][k] as f64 + c[2][k] as f64) / 3.0
        }))
    });
    evaluate(
        field,
        mesh.vertices.iter().map(|v| v.map(f64::from)),
        &mut sigma,
        &mut rgb,
    );
    let byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    mesh.colors = rgb
        .chunks_exact(3)
        .map(|c| [byte(c[0]), byte(c[1]), byte(c[2])])
        .collect();
    mesh
}

impl Mesh {
    /// Keeps the triangles for which `keep(triangle, vertices)` holds and drops the vertices
    /// (and their colours) no triangle uses any more.
    pub fn retain_triangles(&mut self, keep: impl Fn(&[u32; 3], &[[f32; 3]]) -> bool) {
        let vertices = &self.vertices;
        self.triangles.retain(|t| keep(t, vertices));
        let mut remap = vec![u32::MAX; self.vertices.len()];
        let mut next = 0u32;
        for t in &mut self.triangles {
            for v in t.iter_mut() {
                let r = &mut remap[*v as usize];
                if *r == u32::MAX {
                    *r = next;
                    next += 1;
                }
                *v = *r;
            }
        }
        let mut vertices = vec![[0.0; 3]; next as usize];
        let mut colors = vec![
            [0; 3];
            if self.colors.is_empty() {
                0
            } else {
                next as usize
            }
        ];
        for (old, &new) in remap.iter().enumerate() {
            if new != u32::MAX {
                vertices[new as usize] = self.vertices[old];
                if let Some(c) = self.colors.get(old) {
                    colors[new as usize] = *c;
                }
            }
        }
        self.vertices = vertices;
        self.colors = colors;
    }

    /// Writes binary little-endian PLY: `x y z` as float, `red green blue` as uchar when the
    /// mesh has colours, faces as a uchar-counted list of int.
    pub fn write_ply(&self, path: &Path) -> anyhow::Result<()> {
        let with_colors = !self.colors.is_empty();
        if with_colors && self.colors.len() != self.vertices.len() {
            anyhow::bail!(
                "mesh has {} colours for {} vertices",
                self.colors.len(),
                self.vertices.len()
            );
        }
        let mut out = Vec::with_capacity(32 * self.vertices.len() + 16 * self.triangles.len());
        write!(
            out,
            "ply\nformat binary_little_endian 1.0\ncomment written by cpose\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
            self.vertices.len()
        )?;
        if with_colors {
            out.extend_from_slice(
                b"property uchar red\nproperty uchar green\nproperty uchar blue\n",
            );
        }
        write!(
            out,
            "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            self.triangles.len()
        )?;
        for (n, v) in self.vertices.iter().enumerate() {
            for x in v {
                out.extend_from_slice(&x.to_le_bytes());
            }
            if with_colors {
                out.extend_from_slice(&self.colors[n]);
            }
        }
        for t in &self.triangles {
            out.push(3);
            for v in t {
                out.extend_from_slice(&(*v as i32).to_le_bytes());
            }
        }
        std::fs::write(path, out).with_context(|| format!("cannot write {}", path.display()))
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.vertices[v as usize].map(f64::from));
                let u: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
                let v: [f64; 3] = std::array::from_fn(|k| c[k] - a[k]);
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .sum()
    }

    /// Enclosed volume by the divergence theorem (positive for outward-facing closed meshes).
    pub fn volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.vertices[v as usize].map(f64::from));
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples `f` on `grid`.
    fn sample(grid: &Grid, f: impl Fn([f64; 3]) -> f64) -> Vec<f32> {
        (0..grid.len()).map(|n| f(grid.node(n)) as f32).collect()
    }

    #[test]
    fn sphere_is_closed_outward_and_on_the_level_set() {
        let grid = Grid::covering([-1.0; 3], [1.0; 3], 0.05).unwrap();
        let r = 0.7;
        let values = sample(&grid, |p| {
            r - (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
        });
        let mesh = isosurface(&values, &grid, 0.0);
        assert!(mesh.triangles.len() > 1000);
        // Every vertex within a small fraction of a voxel of the sphere (linear interpolation of
        // a distance along an edge of length ≤ √3 voxel).
        let worst = mesh
            .vertices
            .iter()
            .map(|v| (v.map(f64::from).iter().map(|x| x * x).sum::<f64>().sqrt() - r).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.1 * 0.05, "vertex off the sphere by {worst}");
        // Closed and consistently oriented: every directed edge appears once, its reverse once.
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "edge {a}–{b} used {n} times in one direction");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "edge {a}–{b} is on a boundary"
            );
        }
        // Outward normals: positive volume close to the sphere's; area close to 4πr².
        let (vol, area) = (mesh.volume(), mesh.area());
        let (v_true, a_true) = (
            4.0 / 3.0 * std::f64::consts::PI * r.powi(3),
            4.0 * std::f64::consts::PI * r * r,
        );
        assert!(
            (vol / v_true - 1.0).abs() < 0.01,
            "volume {vol} vs {v_true}"
        );
        assert!(
            (area / a_true - 1.0).abs() < 0.02,
            "area {area} vs {a_true}"
        );
    }

    #[test]
    fn plane_crossing_a_box_gives_its_section() {
        // Density above z = 0.3 (a half-space): the surface is the square section of the box.
        let grid = Grid::covering([0.0, 0.0, 0.0], [1.0, 2.0, 1.0], 0.1).unwrap();
        let values = sample(&grid, |p| p[2] - 0.3);
        let mesh = isosurface(&values, &grid, 0.0);
        assert!((mesh.area() - 2.0).abs() < 1e-6, "area {}", mesh.area());
        for v in &mesh.vertices {
            assert!((v[2] - 0.3).abs() < 1e-6);
        }
        // Normals point to −z (towards lower density).
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| mesh.vertices[v as usize]);
            let nz = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            assert!(nz <= 1e-12, "normal z {nz}");
        }
    }

    #[test]
    fn retain_drops_unused_vertices_and_keeps_colours_aligned() {
        let mut mesh = Mesh {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [5.0, 5.0, 5.0]],
            colors: vec![[1, 1, 1], [2, 2, 2], [3, 3, 3], [4, 4, 4]],
            triangles: vec![[3, 1, 2], [0, 1, 2]],
        };
        mesh.retain_triangles(|t, v| v[t[0] as usize][0] < 4.0);
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
        assert_eq!(
            mesh.vertices,
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        );
        assert_eq!(mesh.colors, vec![[1, 1, 1], [2, 2, 2], [3, 3, 3]]);
    }

    #[test]
    fn ply_header_and_size() {
        let mesh = Mesh {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            colors: vec![[255, 0, 0]; 3],
            triangles: vec![[0, 1, 2]],
        };
        let dir = cpose_core::testing::TempDir::new("mesh");
        let path = dir.join("m.ply");
        mesh.write_ply(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..at]).unwrap();
        assert!(header.contains("element vertex 3\n") && header.contains("element face 1\n"));
        assert!(header.contains("property uchar red\n"));
        assert_eq!(bytes.len() - at, 3 * (12 + 3) + (1 + 12));
    }

    #[test]
    fn bad_grids_are_refused() {
        assert!(Grid::covering([0.0; 3], [1.0; 3], 0.0).is_err());
        assert!(Grid::covering([0.0; 3], [1.0, 0.0, 1.0], 0.1).is_err());
        assert!(Grid::covering([0.0; 3], [100.0; 3], 1e-3).is_err());
        // A voxel so small that its node count would overflow is refused, not wrapped.
        assert!(Grid::covering([0.0; 3], [1.0; 3], 1e-9).is_err());
    }
}
