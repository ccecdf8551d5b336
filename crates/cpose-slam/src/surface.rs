//! How well a map's mesh matches the true surface, measured against the surface the depth
//! images show from the true poses (no ground-truth mesh needed): accuracy is the median distance
//! from a mesh vertex to the nearest true surface point, completion the fraction of true surface
//! points with a mesh vertex within [`COMPLETION_RADIUS`].

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
    /// Median distance from a mesh vertex to the nearest true surface point, metres.
    pub accuracy_m: f64,
    /// Fraction of true surface points within [`COMPLETION_RADIUS`] of a mesh vertex.
    pub completion: f64,
}

/// A k-d tree over points, stored in place: in every range of the array the middle element
/// splits the rest along the range's widest axis (smaller coordinates before it), recursively.
struct KdTree {
    points: Vec<Point3<f64>>,
    /// The split axis of the element at each position (unused at leaves).
    axes: Vec<u8>,
}

impl KdTree {
    fn new(points: impl IntoIterator<Item = Point3<f64>>) -> Self {
        let mut points: Vec<_> = points.into_iter().collect();
        let mut axes = vec![0; points.len()];
        Self::build(&mut points, &mut axes);
        Self { points, axes }
    }

    fn build(points: &mut [Point3<f64>], axes: &mut [u8]) {
        if points.len() <= 1 {
            return;
        }
        let spread = |a: usize| {
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p[a]), hi.max(p[a]))
                });
            hi - lo
        };
        let axis = (0..3)
            .max_by(|&a, &b| spread(a).total_cmp(&spread(b)))
            .unwrap_or(0);
        let mid = points.len() / 2;
        points.select_nth_unstable_by(mid, |p, q| p[axis].total_cmp(&q[axis]));
        axes[mid] = axis as u8;
        let (left, right) = points.split_at_mut(mid);
        let (axes_left, axes_right) = axes.split_at_mut(mid);
        Self::build(left, axes_left);
        Self::build(&mut right[1..], &mut axes_right[1..]);
    }

    /// Distance from `q` to the nearest point (infinite for an empty tree).
    fn nearest(&self, q: &Point3<f64>) -> f64 {
        let mut best = f64::INFINITY;
        Self::search(&self.points, &self.axes, q, &mut best);
        best
    }

    fn search(points: &[Point3<f64>], axes: &[u8], q: &Point3<f64>, best: &mut f64) {
        if points.is_empty() {
            return;
        }
        let mid = points.len() / 2;
        *best = best.min((points[mid] - q).norm());
        let axis = axes[mid] as usize;
        let d = q[axis] - points[mid][axis];
        let (left, right) = (
            (&points[..mid], &axes[..mid]),
            (&points[mid + 1..], &axes[mid + 1..]),
        );
        let (near, far) = if d < 0.0 {
            (left, right)
        } else {
            (right, left)
        };
        Self::search(near.0, near.1, q, best);
        // The far side holds only points at least |d| away along the split axis.
        if d.abs() < *best {
            Self::search(far.0, far.1, q, best);
        }
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
    let vertices: Vec<Point3<f64>> = mesh
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let truth_tree = KdTree::new(surface.iter().copied());
    let mut distances: Vec<f64> = vertices.iter().map(|v| truth_tree.nearest(v)).collect();
    let mid = distances.len() / 2;
    let accuracy_m = *distances.select_nth_unstable_by(mid, f64::total_cmp).1;
    let mesh_tree = KdTree::new(vertices);
    let covered = surface
        .iter()
        .filter(|p| mesh_tree.nearest(p) <= COMPLETION_RADIUS)
        .count();
    Ok(Some(SurfaceScore {
        accuracy_m,
        completion: covered as f64 / surface.len() as f64,
    }))
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The tree's nearest distance is the brute-force one, for queries inside the cloud, beyond
    /// it and on its points, on clouds with repeated coordinates.
    #[test]
    fn nearest_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for n in [1, 2, 7, 500] {
            let mut point = || {
                // Coarse coordinates, so many points share one along an axis.
                Point3::new(
                    rng.random_range(0..20) as f64 * 0.1,
                    rng.random_range(-1.0..1.0),
                    rng.random_range(0..3) as f64,
                )
            };
            let cloud: Vec<_> = (0..n).map(|_| point()).collect();
            let tree = KdTree::new(cloud.iter().copied());
            let mut queries: Vec<_> = (0..200).map(|_| point() + point().coords * 0.3).collect();
            queries.push(cloud[0]);
            queries.push(Point3::new(40.0, -30.0, 9.0));
            for q in &queries {
                let brute = cloud
                    .iter()
                    .map(|p| (p - q).norm())
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(tree.nearest(q), brute, "{n} points, query {q}");
            }
        }
        assert_eq!(KdTree::new([]).nearest(&Point3::origin()), f64::INFINITY);
    }
}
