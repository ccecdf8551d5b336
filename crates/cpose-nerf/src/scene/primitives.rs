//! Shapes with exact ray intersections, and procedural solid textures.
//!
//! Every intersection takes a ray `x(t) = o + t d` (`d` not necessarily unit length, so `t` is in
//! units of `|d|`; for a camera ray with `d_cam.z = 1` it is the camera depth) and returns the
//! **nearest** parameter `t ∈ (t_min, t_max)` with the shape's **outward** unit normal there. A
//! ray starting inside a closed shape (sphere, box, cylinder) hits its inside wall, so a room
//! seen from within works like an object seen from outside.
//!
//! Textures are solid (functions of the 3-D world point), so a surface point has one colour
//! whatever the viewing direction; see [`Texture`].

use nalgebra::{Unit, UnitQuaternion, Vector3};

/// Below this `|d·n|` (in units of `|d|`) a ray counts as parallel to a plane, disk or cap and
/// misses it (the hit would be at `t → ∞` or the ray lies in the plane).
const PARALLEL_EPS: f64 = 1e-12;

/// A geometric primitive in world coordinates.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// The sphere `|x − centre| = radius`.
    Sphere {
        /// Centre.
        centre: Vector3<f64>,
        /// Radius (> 0).
        radius: f64,
    },
    /// An oriented box: `x = centre + rotation · l` with `|l_k| ≤ half_extents_k`.
    Box {
        /// Centre.
        centre: Vector3<f64>,
        /// Half side lengths along the box's own axes (> 0).
        half_extents: Vector3<f64>,
        /// `world_from_box` rotation: the box's axes are the columns of its matrix.
        rotation: UnitQuaternion<f64>,
    },
    /// A capped cylinder: `x = centre + h a + p`, `p ⊥ a`, `|h| ≤ half_height`, `|p| ≤ radius`.
    Cylinder {
        /// Centre (half-way along the axis).
        centre: Vector3<f64>,
        /// Axis direction `a`.
        axis: Unit<Vector3<f64>>,
        /// Half the length along the axis (> 0).
        half_height: f64,
        /// Radius (> 0).
        radius: f64,
    },
    /// The infinite plane `(x − point) · normal = 0`; its outward side is the one `normal` points to.
    Plane {
        /// A point on the plane.
        point: Vector3<f64>,
        /// Unit normal.
        normal: Unit<Vector3<f64>>,
    },
    /// The flat disk `(x − centre) · normal = 0`, `|x − centre| ≤ radius` (two-sided, no thickness).
    Disk {
        /// Centre.
        centre: Vector3<f64>,
        /// Unit normal.
        normal: Unit<Vector3<f64>>,
        /// Radius (> 0).
        radius: f64,
    },
}

/// The smaller root of `a t² + 2 b t + c = 0` above `t_min` and below `t_max`, if any.
fn nearest_quadratic_root(a: f64, b: f64, c: f64, t_min: f64, t_max: f64) -> Option<f64> {
    let disc = b * b - a * c;
    // A NaN `a` or `disc` gives NaN roots, which fail the range test below.
    if a <= 0.0 || disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    [(-b - s) / a, (-b + s) / a]
        .into_iter()
        .find(|&t| t > t_min && t < t_max)
}

impl Shape {
    /// The nearest hit `(t, outward unit normal)` of the ray `o + t d` with `t_min < t < t_max`.
    pub fn intersect(
        &self,
        o: &Vector3<f64>,
        d: &Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<(f64, Vector3<f64>)> {
        match self {
            Shape::Sphere { centre, radius } => {
                // |o − c + t d|² = r²  →  (d·d) t² + 2 (d·(o − c)) t + |o − c|² − r² = 0.
                let oc = o - centre;
                let t = nearest_quadratic_root(
                    d.norm_squared(),
                    d.dot(&oc),
                    oc.norm_squared() - radius * radius,
                    t_min,
                    t_max,
                )?;
                Some((t, (oc + d * t) / *radius))
            }
            Shape::Box {
                centre,
                half_extents,
                rotation,
            } => intersect_box(
                &rotation.inverse_transform_vector(&(o - centre)),
                &rotation.inverse_transform_vector(d),
                half_extents,
                t_min,
                t_max,
            )
            .map(|(t, n_local)| (t, rotation * n_local)),
            Shape::Cylinder {
                centre,
                axis,
                half_height,
                radius,
            } => intersect_cylinder(&(o - centre), d, axis, *half_height, *radius, t_min, t_max),
            Shape::Plane { point, normal } => {
                let t = plane_parameter(o, d, point, normal)?;
                (t > t_min && t < t_max).then(|| (t, normal.into_inner()))
            }
            Shape::Disk {
                centre,
                normal,
                radius,
            } => {
                let t = plane_parameter(o, d, centre, normal)?;
                let inside = (o + d * t - centre).norm_squared() <= radius * radius;
                (inside && t > t_min && t < t_max).then(|| (t, normal.into_inner()))
            }
        }
    }

    /// The largest distance from `point` to a point of the shape (`∞` for a plane). Exact for
    /// every shape: sphere `|c − p| + r`; box the farthest corner; cylinder and disk the
    /// farthest rim point of a cap, `√(|q|² + r² + 2 r |q⊥|)` for a rim of centre `q` (relative
    /// to `point`) and `q⊥` its part orthogonal to the axis.
    pub fn farthest_distance(&self, point: &Vector3<f64>) -> f64 {
        let rim = |q: Vector3<f64>, axis: &Unit<Vector3<f64>>, r: f64| {
            let q_perp = q - axis.into_inner() * q.dot(axis);
            (q.norm_squared() + r * r + 2.0 * r * q_perp.norm()).sqrt()
        };
        match self {
            Shape::Sphere { centre, radius } => (centre - point).norm() + radius,
            Shape::Box {
                centre,
                half_extents,
                rotation,
            } => (0..8)
                .map(|k| {
                    let sign = |bit: usize| if k >> bit & 1 == 0 { -1.0 } else { 1.0 };
                    let corner = Vector3::new(
                        sign(0) * half_extents.x,
                        sign(1) * half_extents.y,
                        sign(2) * half_extents.z,
                    );
                    (centre + rotation * corner - point).norm()
                })
                .fold(0.0, f64::max),
            Shape::Cylinder {
                centre,
                axis,
                half_height,
                radius,
            } => {
                let q = centre - point;
                let h = axis.into_inner() * *half_height;
                rim(q + h, axis, *radius).max(rim(q - h, axis, *radius))
            }
            Shape::Plane { .. } => f64::INFINITY,
            Shape::Disk {
                centre,
                normal,
                radius,
            } => rim(centre - point, normal, *radius),
        }
    }
}

/// `t` of the ray's crossing with the plane through `point` with normal `n`, `None` if parallel.
fn plane_parameter(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    point: &Vector3<f64>,
    n: &Unit<Vector3<f64>>,
) -> Option<f64> {
    let denom = d.dot(n);
    (denom.abs() > PARALLEL_EPS * d.norm()).then(|| (point - o).dot(n) / denom)
}

/// Slab method for the axis-aligned box `|x_k| ≤ h_k` in its own frame. Returns the entry point
/// when it lies in `(t_min, t_max)`, else the exit point (the ray starts inside), with the
/// outward normal of the face crossed.
fn intersect_box(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    h: &Vector3<f64>,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, Vector3<f64>)> {
    let (mut t_near, mut t_far) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut near_axis, mut far_axis) = (0, 0);
    for k in 0..3 {
        if d[k] == 0.0 {
            // Parallel to this slab: inside it for every t, or never.
            if o[k].abs() > h[k] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((-h[k] - o[k]) / d[k], (h[k] - o[k]) / d[k]);
        let (lo, hi) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
        if lo > t_near {
            t_near = lo;
            near_axis = k;
        }
        if hi < t_far {
            t_far = hi;
            far_axis = k;
        }
    }
    if t_near > t_far {
        return None;
    }
    let face_normal = |k: usize, sign: f64| {
        let mut n = Vector3::zeros();
        n[k] = sign;
        n
    };
    if t_near > t_min && t_near < t_max {
        // Entering through the face the ray points into: normal against d.
        Some((t_near, face_normal(near_axis, -d[near_axis].signum())))
    } else if t_far > t_min && t_far < t_max && t_near <= t_min {
        Some((t_far, face_normal(far_axis, d[far_axis].signum())))
    } else {
        None
    }
}

/// The capped cylinder of [`Shape::Cylinder`] with `oc = o − centre`.
fn intersect_cylinder(
    oc: &Vector3<f64>,
    d: &Vector3<f64>,
    axis: &Unit<Vector3<f64>>,
    half_height: f64,
    radius: f64,
    t_min: f64,
    t_max: f64,
) -> Option<(f64, Vector3<f64>)> {
    let a = axis.into_inner();
    let (o_a, d_a) = (oc.dot(&a), d.dot(&a));
    let (o_p, d_p) = (oc - a * o_a, d - a * d_a);
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let mut consider = |t: f64, n: Vector3<f64>| {
        if t > t_min && t < t_max && best.is_none_or(|(tb, _)| t < tb) {
            best = Some((t, n));
        }
    };
    // Side: |o_p + t d_p|² = r², both roots, kept where |o_a + t d_a| ≤ half_height.
    let (qa, qb, qc) = (
        d_p.norm_squared(),
        d_p.dot(&o_p),
        o_p.norm_squared() - radius * radius,
    );
    let disc = qb * qb - qa * qc;
    if qa > 0.0 && disc >= 0.0 {
        let s = disc.sqrt();
        for t in [(-qb - s) / qa, (-qb + s) / qa] {
            if (o_a + t * d_a).abs() <= half_height {
                consider(t, (o_p + d_p * t) / radius);
            }
        }
    }
    // Caps: o_a + t d_a = ±half_height, kept where |o_p + t d_p| ≤ r.
    if d_a.abs() > PARALLEL_EPS * d.norm() {
        for sign in [-1.0, 1.0] {
            let t = (sign * half_height - o_a) / d_a;
            if (o_p + d_p * t).norm_squared() <= radius * radius {
                consider(t, a * sign);
            }
        }
    }
    best
}

/// A procedural solid texture: the albedo (linear RGB in `[0, 1]`) at a world point.
///
/// Patterns with hard edges (checker, stripes) alias unless rendered with supersampling.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// One colour.
    Solid([f64; 3]),
    /// 3-D checkerboard of cubes of side `scale`: `a` where `⌊x/s + o_x⌋ + ⌊y/s + o_y⌋ +
    /// ⌊z/s + o_z⌋` is even, else `b`, with the fixed offset `o =` [`CHECKER_OFFSET`] so that
    /// faces at round coordinates do not sit on a cell boundary (which would flicker).
    Checker {
        /// Colour of the even cells.
        a: [f64; 3],
        /// Colour of the odd cells.
        b: [f64; 3],
        /// Side of a cell (> 0).
        scale: f64,
    },
    /// Parallel slabs of width `period / 2` across `direction`: `a` where
    /// `frac(x·direction / period) < ½`, else `b`.
    Stripes {
        /// First colour.
        a: [f64; 3],
        /// Second colour.
        b: [f64; 3],
        /// Period (> 0).
        period: f64,
        /// Unit normal of the stripes.
        direction: Unit<Vector3<f64>>,
    },
    /// Smooth blotches: `mix(a, b, v)` with `v` the contrast-stretched fractal value noise
    /// [`fbm`] of `x / scale`.
    Noise {
        /// Colour at `v = 0`.
        a: [f64; 3],
        /// Colour at `v = 1`.
        b: [f64; 3],
        /// Feature size (> 0).
        scale: f64,
        /// Seed of the noise lattice.
        seed: u64,
    },
    /// Marble-like veins: `mix(a, b, ½ + ½ sin(2π (x·direction / period + turbulence ·
    /// fbm(x / period))))`.
    Marble {
        /// First colour.
        a: [f64; 3],
        /// Second colour.
        b: [f64; 3],
        /// Distance between veins (> 0).
        period: f64,
        /// Unit direction across the veins.
        direction: Unit<Vector3<f64>>,
        /// Strength of the distortion (periods per unit noise).
        turbulence: f64,
        /// Seed of the noise lattice.
        seed: u64,
    },
}

/// Offset of the checker lattice, in cells (irrational-looking values, so that no face of a
/// hand-made scene at round coordinates coincides with a cell boundary).
pub const CHECKER_OFFSET: [f64; 3] = [0.1234, 0.3719, 0.2468];

/// Octaves of [`fbm`].
pub const FBM_OCTAVES: u32 = 3;

/// `a + (b − a) s`, per channel.
fn mix(a: &[f64; 3], b: &[f64; 3], s: f64) -> [f64; 3] {
    [0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * s)
}

impl Texture {
    /// The albedo at world point `p`.
    pub fn albedo(&self, p: &Vector3<f64>) -> [f64; 3] {
        match self {
            Texture::Solid(c) => *c,
            Texture::Checker { a, b, scale } => {
                let cell: i64 = (0..3)
                    .map(|k| (p[k] / scale + CHECKER_OFFSET[k]).floor() as i64)
                    .sum();
                if cell.rem_euclid(2) == 0 { *a } else { *b }
            }
            Texture::Stripes {
                a,
                b,
                period,
                direction,
            } => {
                let u = p.dot(direction) / period;
                if u - u.floor() < 0.5 { *a } else { *b }
            }
            Texture::Noise { a, b, scale, seed } => {
                // fbm concentrates around ½ (std ≈ 0.15): stretch ×2.5 about ½ and clamp.
                let v = (0.5 + 2.5 * (fbm(&(p / *scale), *seed) - 0.5)).clamp(0.0, 1.0);
                mix(a, b, v)
            }
            Texture::Marble {
                a,
                b,
                period,
                direction,
                turbulence,
                seed,
            } => {
                let u = p.dot(direction) / period + turbulence * fbm(&(p / *period), *seed);
                mix(a, b, 0.5 + 0.5 * (std::f64::consts::TAU * u).sin())
            }
        }
    }
}

/// Fractal value noise in `[0, 1]`: `Σ_k 2⁻ᵏ n(2ᵏ p) / Σ_k 2⁻ᵏ` over [`FBM_OCTAVES`] octaves of
/// [`value_noise`] (each octave with its own lattice).
pub fn fbm(p: &Vector3<f64>, seed: u64) -> f64 {
    let (mut sum, mut weight, mut total, mut freq) = (0.0, 1.0, 0.0, 1.0);
    for octave in 0..FBM_OCTAVES {
        sum += weight * value_noise(&(p * freq), seed.wrapping_add(u64::from(octave)));
        total += weight;
        weight *= 0.5;
        freq *= 2.0;
    }
    sum / total
}

/// Value noise in `[0, 1]`: uniform values at the integer lattice (a hash of the cell corner and
/// `seed`), blended with the quintic fade `s³(6s² − 15s + 10)` (C² across cells).
pub fn value_noise(p: &Vector3<f64>, seed: u64) -> f64 {
    let base = p.map(f64::floor);
    let f = p - base;
    let fade = |s: f64| s * s * s * (s * (6.0 * s - 15.0) + 10.0);
    let w = f.map(fade);
    let cell = base.map(|v| v as i64);
    let corner = |dx: i64, dy: i64, dz: i64| {
        let h = hash3(seed, cell.x + dx, cell.y + dy, cell.z + dz);
        (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    };
    let lerp = |a: f64, b: f64, s: f64| a + (b - a) * s;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), w.x);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), w.x);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), w.x);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), w.x);
    lerp(lerp(x00, x10, w.y), lerp(x01, x11, w.y), w.z)
}

/// SplitMix64's finaliser (Steele, Lea, Flood 2014), a bijective 64-bit mixer.
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of a seed and a lattice cell.
fn hash3(seed: u64, x: i64, y: i64, z: i64) -> u64 {
    mix64(mix64(mix64(mix64(seed) ^ x as u64) ^ y as u64) ^ z as u64)
}

/// Unsigned distance from `p` to the surface of `shape` (test helper for depth maps).
#[cfg(test)]
pub(crate) fn surface_distance(shape: &Shape, p: &Vector3<f64>) -> f64 {
    match shape {
        Shape::Sphere { centre, radius } => ((p - centre).norm() - radius).abs(),
        Shape::Box {
            centre,
            half_extents,
            rotation,
        } => {
            let l = rotation.inverse_transform_vector(&(p - centre));
            let q = l.abs() - half_extents;
            let outside = q.map(|v| v.max(0.0)).norm();
            let inside = q.max().min(0.0);
            (outside + inside).abs()
        }
        Shape::Cylinder {
            centre,
            axis,
            half_height,
            radius,
        } => {
            let l = p - centre;
            let h = l.dot(axis);
            let r = (l - axis.into_inner() * h).norm();
            let (qr, qh) = (r - radius, h.abs() - half_height);
            let outside = (qr.max(0.0).powi(2) + qh.max(0.0).powi(2)).sqrt();
            (outside + qr.max(qh).min(0.0)).abs()
        }
        Shape::Plane { point, normal } => (p - point).dot(normal).abs(),
        Shape::Disk {
            centre,
            normal,
            radius,
        } => {
            let l = p - centre;
            let h = l.dot(normal);
            let r = (l - normal.into_inner() * h).norm();
            (h * h + (r - radius).max(0.0).powi(2)).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    fn vclose(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        (a - b).norm() < 1e-12
    }

    const T_MIN: f64 = 1e-9;

    #[test]
    fn sphere_outside_inside_miss_and_scaled_direction() {
        let s = Shape::Sphere {
            centre: Vector3::new(1.0, 2.0, 3.0),
            radius: 0.5,
        };
        let o = Vector3::new(1.0, 2.0, 0.0);
        let (t, n) = s
            .intersect(&o, &Vector3::z(), T_MIN, f64::INFINITY)
            .unwrap();
        assert!(close(t, 2.5) && vclose(&n, &-Vector3::z()));
        // A direction of length 2 halves t.
        let (t2, _) = s
            .intersect(&o, &(2.0 * Vector3::z()), T_MIN, f64::INFINITY)
            .unwrap();
        assert!(close(t2, 1.25));
        // From the centre: the far wall, normal outward (along the ray).
        let (t, n) = s
            .intersect(&Vector3::new(1.0, 2.0, 3.0), &Vector3::x(), T_MIN, 10.0)
            .unwrap();
        assert!(close(t, 0.5) && vclose(&n, &Vector3::x()));
        // Miss sideways, miss behind, miss beyond t_max.
        assert!(
            s.intersect(&Vector3::new(2.0, 2.0, 0.0), &Vector3::z(), T_MIN, 10.0)
                .is_none()
        );
        assert!(s.intersect(&o, &-Vector3::z(), T_MIN, 10.0).is_none());
        assert!(s.intersect(&o, &Vector3::z(), T_MIN, 2.0).is_none());
    }

    #[test]
    fn oriented_box_faces_inside_and_miss() {
        // Rotated 90° about z: local x (half 2) lies along world y.
        let b = Shape::Box {
            centre: Vector3::new(0.0, 0.0, 1.0),
            half_extents: Vector3::new(2.0, 0.5, 0.25),
            rotation: UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                std::f64::consts::FRAC_PI_2,
            ),
        };
        let (t, n) = b
            .intersect(
                &Vector3::new(0.0, -5.0, 1.0),
                &Vector3::y(),
                T_MIN,
                f64::INFINITY,
            )
            .unwrap();
        assert!(close(t, 3.0) && vclose(&n, &-Vector3::y()), "{t} {n}");
        let (t, n) = b
            .intersect(
                &Vector3::new(5.0, 1.5, 1.0),
                &Vector3::new(-2.0, 0.0, 0.0),
                T_MIN,
                f64::INFINITY,
            )
            .unwrap();
        assert!(close(t, 2.25) && vclose(&n, &Vector3::x()), "{t} {n}");
        // From inside: the top face from below, outward normal +z.
        let (t, n) = b
            .intersect(&Vector3::new(0.3, 1.0, 1.0), &Vector3::z(), T_MIN, 10.0)
            .unwrap();
        assert!(close(t, 0.25) && vclose(&n, &Vector3::z()));
        // Parallel to a slab outside it, and past the corner.
        assert!(
            b.intersect(&Vector3::new(0.0, -5.0, 2.0), &Vector3::y(), T_MIN, 10.0)
                .is_none()
        );
        assert!(
            b.intersect(
                &Vector3::new(0.0, -5.0, 1.0),
                &Vector3::new(1.0, 1.0, 0.0),
                T_MIN,
                10.0
            )
            .is_none()
        );
    }

    #[test]
    fn cylinder_side_caps_inside_and_miss() {
        let c = Shape::Cylinder {
            centre: Vector3::new(0.0, 0.0, 0.0),
            axis: Vector3::z_axis(),
            half_height: 1.0,
            radius: 0.5,
        };
        // Side.
        let (t, n) = c
            .intersect(&Vector3::new(-3.0, 0.0, 0.2), &Vector3::x(), T_MIN, 10.0)
            .unwrap();
        assert!(close(t, 2.5) && vclose(&n, &-Vector3::x()));
        // Top cap from above, slanted.
        let d = Vector3::new(0.1, 0.0, -1.0);
        let (t, n) = c
            .intersect(&Vector3::new(0.0, 0.0, 3.0), &d, T_MIN, 10.0)
            .unwrap();
        assert!(close(t, 2.0) && vclose(&n, &Vector3::z()));
        // Passes above the top cap's rim: no hit, though the infinite cylinder would be hit.
        assert!(
            c.intersect(&Vector3::new(-3.0, 0.0, 1.2), &Vector3::x(), T_MIN, 10.0)
                .is_none()
        );
        // From inside, along a tilted axis: bottom cap; and the side.
        let axis = Unit::new_normalize(Vector3::new(1.0, 1.0, 0.0));
        let c = Shape::Cylinder {
            centre: Vector3::new(1.0, 0.0, 0.0),
            axis,
            half_height: 2.0,
            radius: 0.3,
        };
        let (t, n) = c
            .intersect(
                &Vector3::new(1.0, 0.0, 0.0),
                &-axis.into_inner(),
                T_MIN,
                10.0,
            )
            .unwrap();
        assert!(close(t, 2.0) && vclose(&n, &-axis.into_inner()));
        let (t, n) = c
            .intersect(&Vector3::new(1.0, 0.0, 0.0), &Vector3::z(), T_MIN, 10.0)
            .unwrap();
        assert!(close(t, 0.3) && vclose(&n, &Vector3::z()));
    }

    #[test]
    fn plane_and_disk() {
        let n = Unit::new_normalize(Vector3::new(0.0, 0.0, 1.0));
        let plane = Shape::Plane {
            point: Vector3::new(0.0, 0.0, -1.0),
            normal: n,
        };
        let d = Vector3::new(0.3, -0.2, -0.5);
        let (t, nn) = plane.intersect(&Vector3::zeros(), &d, T_MIN, 1e9).unwrap();
        assert!(close(t, 2.0) && vclose(&nn, &Vector3::z()));
        // From below the same plane: hit, outward normal unchanged.
        let (t, _) = plane
            .intersect(&Vector3::new(0.0, 0.0, -3.0), &Vector3::z(), T_MIN, 1e9)
            .unwrap();
        assert!(close(t, 2.0));
        // Parallel and pointing away: miss.
        assert!(
            plane
                .intersect(&Vector3::zeros(), &Vector3::x(), T_MIN, 1e9)
                .is_none()
        );
        assert!(
            plane
                .intersect(&Vector3::zeros(), &Vector3::z(), T_MIN, 1e9)
                .is_none()
        );
        let disk = Shape::Disk {
            centre: Vector3::new(0.0, 0.0, -1.0),
            normal: n,
            radius: 0.5,
        };
        assert!(
            disk.intersect(&Vector3::new(0.4, 0.0, 0.0), &-Vector3::z(), T_MIN, 1e9)
                .is_some()
        );
        assert!(
            disk.intersect(&Vector3::new(0.6, 0.0, 0.0), &-Vector3::z(), T_MIN, 1e9)
                .is_none()
        );
    }

    #[test]
    fn farthest_distance_is_attained_and_bounds_samples() {
        let shapes = [
            Shape::Sphere {
                centre: Vector3::new(0.3, 0.1, -0.2),
                radius: 0.4,
            },
            Shape::Box {
                centre: Vector3::new(0.1, -0.3, 0.2),
                half_extents: Vector3::new(0.3, 0.2, 0.1),
                rotation: UnitQuaternion::from_euler_angles(0.3, -0.5, 1.0),
            },
            Shape::Cylinder {
                centre: Vector3::new(-0.2, 0.4, 0.1),
                axis: Unit::new_normalize(Vector3::new(0.2, 1.0, 0.5)),
                half_height: 0.3,
                radius: 0.25,
            },
            Shape::Disk {
                centre: Vector3::new(0.5, 0.0, 0.3),
                normal: Unit::new_normalize(Vector3::new(1.0, 0.2, 0.3)),
                radius: 0.3,
            },
        ];
        // Cast many rays from far away towards the origin region; every hit lies within the
        // bound, and the largest is close to it.
        for shape in &shapes {
            let bound = shape.farthest_distance(&Vector3::zeros());
            let mut largest: f64 = 0.0;
            for i in 0..4000 {
                let (a, b) = (i as f64 * 2.399_963, (i as f64 * 0.618_034).fract());
                let dir = Vector3::new(
                    a.cos() * (1.0 - b * b).sqrt(),
                    a.sin() * (1.0 - b * b).sqrt(),
                    b,
                );
                let dir = if i % 2 == 0 { dir } else { -dir };
                let o = dir * 5.0;
                let aim = Vector3::new(
                    (i % 7) as f64 * 0.1 - 0.3,
                    (i % 5) as f64 * 0.1 - 0.2,
                    (i % 3) as f64 * 0.1 - 0.1,
                );
                if let Some((t, _)) = shape.intersect(&o, &(aim - o), T_MIN, 10.0) {
                    let p = o + (aim - o) * t;
                    assert!(surface_distance(shape, &p) < 1e-9);
                    largest = largest.max(p.norm());
                }
            }
            assert!(
                largest <= bound + 1e-12 && largest > 0.9 * bound,
                "{largest} {bound}"
            );
        }
        assert_eq!(
            Shape::Plane {
                point: Vector3::zeros(),
                normal: Vector3::z_axis()
            }
            .farthest_distance(&Vector3::zeros()),
            f64::INFINITY
        );
    }

    #[test]
    fn textures_are_in_range_and_patterned() {
        let (a, b) = ([0.1, 0.2, 0.3], [0.9, 0.8, 0.7]);
        let checker = Texture::Checker { a, b, scale: 0.5 };
        // Neighbouring cells differ; the offset moves boundaries off round coordinates.
        let p = Vector3::new(0.1, 0.1, 0.1);
        assert_ne!(
            checker.albedo(&p),
            checker.albedo(&(p + Vector3::new(0.5, 0.0, 0.0)))
        );
        assert_eq!(
            checker.albedo(&p),
            checker.albedo(&(p + Vector3::new(0.5, 0.5, 0.0)))
        );
        let stripes = Texture::Stripes {
            a,
            b,
            period: 1.0,
            direction: Vector3::x_axis(),
        };
        assert_eq!(stripes.albedo(&Vector3::new(0.25, 7.0, -3.0)), a);
        assert_eq!(stripes.albedo(&Vector3::new(-0.25, 7.0, -3.0)), b);
        let noise = Texture::Noise {
            a,
            b,
            scale: 0.3,
            seed: 4,
        };
        let marble = Texture::Marble {
            a,
            b,
            period: 0.4,
            direction: Vector3::z_axis(),
            turbulence: 1.0,
            seed: 9,
        };
        for tex in [&noise, &marble] {
            let vals: Vec<f64> = (0..500)
                .map(|i| {
                    let p =
                        Vector3::new(i as f64 * 0.037, (i as f64 * 0.061).sin(), i as f64 * 0.013);
                    let c = tex.albedo(&p);
                    for k in 0..3 {
                        let (lo, hi) = (a[k].min(b[k]), a[k].max(b[k]));
                        assert!(c[k] >= lo - 1e-12 && c[k] <= hi + 1e-12);
                    }
                    c[0]
                })
                .collect();
            let mean = vals.iter().sum::<f64>() / vals.len() as f64;
            let std =
                (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64).sqrt();
            assert!(std > 0.1, "{tex:?}: std {std}");
        }
        // Value noise is continuous across lattice cells and deterministic.
        let p = Vector3::new(2.0, -1.0, 3.0);
        let e = Vector3::new(1e-7, 1e-7, 1e-7);
        assert!((value_noise(&(p - e), 1) - value_noise(&(p + e), 1)).abs() < 1e-6);
        assert_eq!(value_noise(&p, 1), value_noise(&p, 1));
        assert_ne!(value_noise(&(p * 0.37), 1), value_noise(&(p * 0.37), 2));
    }
}
