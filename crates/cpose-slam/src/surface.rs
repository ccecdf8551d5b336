//! How well a map's mesh matches the true surface, measured against the surface the depth
//! images show from the true poses (no ground-truth mesh needed): accuracy is the median distance
//! from a mesh vertex to the nearest true surface point, completion the fraction of true surface
//! points with a mesh vertex within [`COMPLETION_RADIUS`].

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3};

use crate::data::{RgbdError, RgbdSequence};
use cpose_nerf::mesh::Mesh;

/// A true surface point counts as covered with a mesh vertex this close, metres.
pub const COMPLETION_RADIUS: f64 = 0.05;

/// Every this many frames and pixels (in x and y) a depth reading becomes a true surface point.
const FRAME_STRIDE: usize = 10;
const PIXEL_STRIDE: usize = 4;

/// Mesh quality against the true surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceScore {
    /// Median distance from a mesh vertex to the true surface points, metres (capped at
    /// [`COMPLETION_RADIUS`]: farther vertices count as that far).
    pub accuracy_m: f64,
    /// Fraction of true surface points within [`COMPLETION_RADIUS`] of a mesh vertex.
    pub completion: f64,
}

/// Points bucketed in cubes of side `radius`, for nearest-neighbour queries within `radius`.
struct PointIndex {
    radius: f64,
    cells: HashMap<[i64; 3], Vec<Point3<f64>>>,
}

impl PointIndex {
    fn new(radius: f64, points: impl IntoIterator<Item = Point3<f64>>) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<Point3<f64>>> = HashMap::new();
        for p in points {
            cells.entry(Self::cell(radius, &p)).or_default().push(p);
        }
        Self { radius, cells }
    }

    fn cell(radius: f64, p: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|a| (p[a] / radius).floor() as i64)
    }

    /// Distance to the nearest point if it is within `radius`.
    fn nearest_within(&self, p: &Point3<f64>) -> Option<f64> {
        let c = Self::cell(self.radius, p);
        let mut best = f64::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(points) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for q in points {
                            best = best.min((p - q).norm());
                        }
                    }
                }
            }
        }
        (best <= self.radius).then_some(best)
    }
}

/// Scores `mesh` against the true surface of the first `frames` frames of `seq`: the depth
/// readings of every tenth frame with a true pose, every fourth pixel. `None` without true poses
/// or mesh vertices.
pub fn score_mesh(
    mesh: &Mesh,
    seq: &RgbdSequence,
    truth: &[Option<Isometry3<f64>>],
    frames: usize,
) -> Result<Option<SurfaceScore>, RgbdError> {
    let camera = &seq.camera;
    let mut surface = Vec::new();
    for i in (0..frames).step_by(FRAME_STRIDE) {
        let Some(pose) = truth.get(i).copied().flatten() else {
            continue;
        };
        let frame = seq.load(i)?;
        for y in (0..camera.height).step_by(PIXEL_STRIDE) {
            for x in (0..camera.width).step_by(PIXEL_STRIDE) {
                let z = frame.depth.at(x, y) as f64;
                if z > 0.0 {
                    let d = camera.ray_direction_cam(x, y);
                    surface.push(pose * Point3::new(d[0] * z, d[1] * z, d[2] * z));
                }
            }
        }
    }
    if surface.is_empty() || mesh.vertices.is_empty() {
        return Ok(None);
    }
    let r = COMPLETION_RADIUS;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64));
    let truth_index = PointIndex::new(r, surface.iter().copied());
    let mut distances: Vec<f64> = vertices
        .clone()
        .map(|v| truth_index.nearest_within(&v).unwrap_or(r))
        .collect();
    let mid = distances.len() / 2;
    let accuracy_m = *distances.select_nth_unstable_by(mid, f64::total_cmp).1;
    let mesh_index = PointIndex::new(r, vertices);
    let covered = surface
        .iter()
        .filter(|p| mesh_index.nearest_within(p).is_some())
        .count();
    Ok(Some(SurfaceScore {
        accuracy_m,
        completion: covered as f64 / surface.len() as f64,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_within_finds_neighbours_across_cells_and_nothing_beyond_the_radius() {
        let index = PointIndex::new(
            0.05,
            [Point3::new(0.049, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0)],
        );
        // Across a cell boundary.
        let d = index.nearest_within(&Point3::new(0.051, 0.0, 0.0)).unwrap();
        assert!((d - 0.002).abs() < 1e-12);
        assert_eq!(index.nearest_within(&Point3::new(0.2, 0.0, 0.0)), None);
        // Within a neighbouring cell but farther than the radius.
        assert_eq!(index.nearest_within(&Point3::new(0.0, 0.0, -0.06)), None);
    }
}
