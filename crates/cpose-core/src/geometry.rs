//! Rotations and rigid transforms in `f64`: SO(3) and SE(3) exponential and logarithm, Jacobians,
//! quaternion orders and signs, Euler angles, camera-axis conventions and quaternion kinematics.
//!
//! Conventions (pinned by the tests at the bottom of this file and listed in `CONVENTIONS.md`):
//! - quaternions are Hamilton (`w + xi + yj + zk`, `i ⊗ j = k`); `Quaternion::new(w, x, y, z)`;
//!   a `UnitQuaternion` `q` rotates vectors as `q ⊗ (0, v) ⊗ q*`;
//! - transforms are named `target_from_source` and compose right to left:
//!   `world_from_cam = world_from_body * body_from_cam`;
//! - tangent vectors of SE(3) are **rotation first**, `ξ = (ω, v)` (gtsam, sophus-rs, BARF);
//! - Euler angles are intrinsic Z-Y-X (yaw, pitch, roll): `R = Rz(yaw)·Ry(pitch)·Rx(roll)`;
//! - cameras use OpenCV axes (x right, y down, z forward) inside.
//!
//! Two different "exponentials" map a 6-vector to a pose, and they differ in the translation:
//! [`se3_exp`] is the true group exponential (translation `V(ω)·v`, BARF's `Lie.se3_to_SE3`),
//! [`so3_r3_exp`] is the SO(3)×R³ retraction (translation `v`). Their logarithms are
//! [`se3_log`] and [`so3_r3_log`].

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Quaternion, RealField, Rotation3, Translation3, UnitQuaternion,
    Vector3, Vector6,
};

// ---------------------------------------------------------------------------------------------
// Thresholds of the small-angle branches.
// ---------------------------------------------------------------------------------------------

/// Below this value of `θ²` (θ = rotation angle, rad) [`so3_exp`] uses the Taylor series
/// `cos(θ/2) = 1 − θ²/8 + θ⁴/384`, `sin(θ/2)/θ = 1/2 − θ²/48 + θ⁴/3840` instead of the closed
/// form, which is `0/0` at `θ = 0`. Truncation error `O(θ⁶) < 1e-19` here; the closed form is
/// exact to rounding above it (no cancellation).
pub const SO3_EXP_TAYLOR_MAX_THETA_SQ: f64 = 1e-6;

/// Below this value of `|vec(q)|² = sin²(θ/2)` [`so3_log`] uses the series
/// `2·atan(n/w)/n = (2/w)(1 − n²/(3w²) + n⁴/(5w⁴))` instead of `2·atan2(n, w)/n` (`0/0` at
/// `n = 0`). Truncation error `O(n⁶) < 1e-19` here.
pub const SO3_LOG_TAYLOR_MAX_SIN_HALF_SQ: f64 = 1e-6;

/// Below this value of `θ²` the coefficients of the SO(3) Jacobians,
/// `(1 − cos θ)/θ²`, `(θ − sin θ)/θ³` and `1/θ² − cot(θ/2)/(2θ)`, use their Taylor series up to
/// `θ⁶` instead of the closed forms, which lose `≈ ε/θ²` to cancellation. At `θ² = 1e-2` the
/// truncation error (`θ⁸` term, `< 3e-15`) and the cancellation error of the closed form
/// (`≈ ε/θ² ≈ 1e-14`) are both negligible; the branches agree to a few `1e-14` at the switch.
pub const SO3_JACOBIAN_TAYLOR_MAX_THETA_SQ: f64 = 1e-2;

/// [`euler_zyx_from_rotation`] treats the rotation as gimbal-locked (pitch = ±90°) when
/// `cos²(pitch) = R₀₀² + R₁₀²` is below this value. Roll and yaw from `atan2` of entries of size
/// `cos(pitch)` carry a relative error `ε/cos(pitch)`, while fixing roll = 0 at lock costs
/// `O(cos(pitch))`; `1e-16` (`cos(pitch) < 1e-8`) balances both at `≈ 1e-8`.
pub const EULER_GIMBAL_LOCK_MAX_COS_PITCH_SQ: f64 = 1e-16;

// ---------------------------------------------------------------------------------------------
// hat / vee
// ---------------------------------------------------------------------------------------------

/// `[ω]×`, the skew-symmetric matrix with `[ω]× v = ω × v`:
/// `[[0, −ωz, ωy], [ωz, 0, −ωx], [−ωy, ωx, 0]]`.
pub fn hat<T: RealField + Copy>(omega: &Vector3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(
        z, -omega.z, omega.y, //
        omega.z, z, -omega.x, //
        -omega.y, omega.x, z,
    )
}

/// The inverse of [`hat`], taken on the skew-symmetric part of `m`:
/// `ω = ½ (m₂₁ − m₁₂, m₀₂ − m₂₀, m₁₀ − m₀₁)`.
pub fn vee<T: RealField + Copy>(m: &Matrix3<T>) -> Vector3<T> {
    let half = T::one() / (T::one() + T::one());
    Vector3::new(
        (m[(2, 1)] - m[(1, 2)]) * half,
        (m[(0, 2)] - m[(2, 0)]) * half,
        (m[(1, 0)] - m[(0, 1)]) * half,
    )
}

/// `ξ^ = [[ [ω]×, v ], [0, 0]]` for a rotation-first twist `ξ = (ω, v)`, so that the true
/// exponential is the matrix exponential of `ξ^` ([`se3_exp`]).
pub fn hat_se3(xi: &Vector6<f64>) -> Matrix4<f64> {
    let mut m = Matrix4::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&hat(&xi.fixed_rows::<3>(0).into_owned()));
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&xi.fixed_rows::<3>(3));
    m
}

/// The inverse of [`hat_se3`]: `(vee(top-left 3×3), top-right column)`.
pub fn vee_se3(m: &Matrix4<f64>) -> Vector6<f64> {
    let w = vee(&m.fixed_view::<3, 3>(0, 0).into_owned());
    let v = m.fixed_view::<3, 1>(0, 3);
    Vector6::new(w.x, w.y, w.z, v[0], v[1], v[2])
}

// ---------------------------------------------------------------------------------------------
// SO(3)
// ---------------------------------------------------------------------------------------------

/// `Exp: so(3) → SO(3)`, rotation vector `φ = θ·axis` to unit quaternion
/// `q = (cos(θ/2), sin(θ/2)/θ · φ)` (Solà, "Quaternion kinematics for the error-state Kalman
/// filter", eq. 101). Taylor branch below [`SO3_EXP_TAYLOR_MAX_THETA_SQ`].
pub fn so3_exp(rot_vec: &Vector3<f64>) -> UnitQuaternion<f64> {
    let theta_sq = rot_vec.norm_squared();
    let (w, s) = if theta_sq < SO3_EXP_TAYLOR_MAX_THETA_SQ {
        // cos(θ/2) = 1 − θ²/8 + θ⁴/384; sin(θ/2)/θ = 1/2 − θ²/48 + θ⁴/3840
        (
            1.0 - theta_sq / 8.0 + theta_sq * theta_sq / 384.0,
            0.5 - theta_sq / 48.0 + theta_sq * theta_sq / 3840.0,
        )
    } else {
        let theta = theta_sq.sqrt();
        let half = 0.5 * theta;
        (half.cos(), half.sin() / theta)
    };
    // |q|² = cos² + sin² = 1 up to rounding (or O(θ¹²) in the Taylor branch).
    UnitQuaternion::new_unchecked(Quaternion::new(
        w,
        s * rot_vec.x,
        s * rot_vec.y,
        s * rot_vec.z,
    ))
}

/// `Exp: so(3) → SO(3)` as a rotation matrix (Rodrigues:
/// `R = I + sin θ/θ [φ]× + (1 − cos θ)/θ² [φ]×²`), computed through [`so3_exp`].
pub fn so3_exp_matrix(rot_vec: &Vector3<f64>) -> Matrix3<f64> {
    quat_to_rotation_matrix(&so3_exp(rot_vec))
}

/// `Log: SO(3) → so(3)`, unit quaternion to rotation vector with angle `θ ∈ [0, π]`:
/// `φ = 2·atan2(|v|, w)/|v| · v` after flipping `q` to `w ≥ 0` (Solà eq. 105). Accurate near 0
/// (series below [`SO3_LOG_TAYLOR_MAX_SIN_HALF_SQ`]) and near π (`atan2` stays well conditioned).
pub fn so3_log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let q = canonicalize_quat(q);
    let w = q.w;
    let v = q.imag();
    let n_sq = v.norm_squared();
    let f = if n_sq < SO3_LOG_TAYLOR_MAX_SIN_HALF_SQ {
        // 2·atan(n/w)/n = (2/w)(1 − n²/(3w²) + n⁴/(5w⁴)); here w ≈ 1.
        let r = n_sq / (w * w);
        2.0 / w * (1.0 - r / 3.0 + r * r / 5.0)
    } else {
        let n = n_sq.sqrt();
        2.0 * n.atan2(w) / n
    };
    v * f
}

/// `Log: SO(3) → so(3)` of a rotation matrix (assumed orthonormal), through the quaternion.
pub fn so3_log_matrix(rotation: &Matrix3<f64>) -> Vector3<f64> {
    so3_log(&rotation_matrix_to_quat(rotation))
}

/// The coefficients `(A, B) = ((1 − cos θ)/θ², (θ − sin θ)/θ³)` in closed form.
fn jacobian_coeffs_closed(theta_sq: f64) -> (f64, f64) {
    let theta = theta_sq.sqrt();
    (
        (1.0 - theta.cos()) / theta_sq,
        (theta - theta.sin()) / (theta_sq * theta),
    )
}

/// The coefficients `(A, B)` of [`jacobian_coeffs_closed`] by their Taylor series to `θ⁶`.
fn jacobian_coeffs_taylor(theta_sq: f64) -> (f64, f64) {
    let t2 = theta_sq;
    let t4 = t2 * t2;
    let t6 = t4 * t2;
    (
        // (1 − cos θ)/θ² = 1/2 − θ²/24 + θ⁴/720 − θ⁶/40320
        0.5 - t2 / 24.0 + t4 / 720.0 - t6 / 40320.0,
        // (θ − sin θ)/θ³ = 1/6 − θ²/120 + θ⁴/5040 − θ⁶/362880
        1.0 / 6.0 - t2 / 120.0 + t4 / 5040.0 - t6 / 362_880.0,
    )
}

/// The coefficient `C = 1/θ² − cot(θ/2)/(2θ)` of the inverse left Jacobian, closed form
/// (`cot(θ/2) = (1 + cos θ)/sin θ`, finite at `θ = π`).
fn inv_jacobian_coeff_closed(theta_sq: f64) -> f64 {
    let theta = theta_sq.sqrt();
    let half = 0.5 * theta;
    1.0 / theta_sq - half.cos() / (half.sin() * 2.0 * theta)
}

/// `C` of [`inv_jacobian_coeff_closed`] by its Taylor series,
/// `1/12 + θ²/720 + θ⁴/30240 + θ⁶/1209600` (from `x cot x = 1 − x²/3 − x⁴/45 − 2x⁶/945 − …`).
fn inv_jacobian_coeff_taylor(theta_sq: f64) -> f64 {
    let t2 = theta_sq;
    let t4 = t2 * t2;
    1.0 / 12.0 + t2 / 720.0 + t4 / 30240.0 + t4 * t2 / 1_209_600.0
}

/// The left Jacobian of SO(3),
/// `J_l(φ) = I + (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×²`,
/// defined by `Exp(φ + δ) ≈ Exp(J_l(φ) δ) · Exp(φ)` (Solà, Deray, Atchuthan, "A micro Lie theory",
/// eq. 146). It is also the `V(ω)` of the SE(3) exponential. Shape 3×3.
pub fn so3_left_jacobian(rot_vec: &Vector3<f64>) -> Matrix3<f64> {
    let theta_sq = rot_vec.norm_squared();
    let (a, b) = if theta_sq < SO3_JACOBIAN_TAYLOR_MAX_THETA_SQ {
        jacobian_coeffs_taylor(theta_sq)
    } else {
        jacobian_coeffs_closed(theta_sq)
    };
    let k = hat(rot_vec);
    Matrix3::identity() + k * a + k * k * b
}

/// The inverse of [`so3_left_jacobian`],
/// `J_l⁻¹(φ) = I − ½ [φ]× + (1/θ² − cot(θ/2)/(2θ)) [φ]×²` ("A micro Lie theory", eq. 147,
/// with `(1 + cos θ)/sin θ = cot(θ/2)`), so that `Log(Exp(δ)·Exp(φ)) ≈ φ + J_l⁻¹(φ) δ`.
/// Valid for `θ < 2π` (singular at `θ = 2π`; [`so3_log`] returns `θ ≤ π`). Shape 3×3.
pub fn so3_left_jacobian_inverse(rot_vec: &Vector3<f64>) -> Matrix3<f64> {
    let theta_sq = rot_vec.norm_squared();
    let c = if theta_sq < SO3_JACOBIAN_TAYLOR_MAX_THETA_SQ {
        inv_jacobian_coeff_taylor(theta_sq)
    } else {
        inv_jacobian_coeff_closed(theta_sq)
    };
    let k = hat(rot_vec);
    Matrix3::identity() - k * 0.5 + k * k * c
}

/// The right Jacobian `J_r(φ) = J_l(−φ)`, with `Exp(φ + δ) ≈ Exp(φ) · Exp(J_r(φ) δ)`.
pub fn so3_right_jacobian(rot_vec: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(&-rot_vec)
}

/// The inverse right Jacobian `J_r⁻¹(φ) = J_l⁻¹(−φ)`.
pub fn so3_right_jacobian_inverse(rot_vec: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian_inverse(&-rot_vec)
}

/// The geodesic angle between two rotations, `|Log(a⁻¹ b)| ∈ [0, π]`, computed as
/// `2·atan2(|vec(r)|, |w(r)|)` of `r = a* ⊗ b` (well conditioned near 0 and π, unlike `acos`).
pub fn rotation_angle_between(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let r = a.inverse() * b;
    2.0 * r.imag().norm().atan2(r.w.abs())
}

// ---------------------------------------------------------------------------------------------
// SE(3)
// ---------------------------------------------------------------------------------------------

/// The true SE(3) exponential of a rotation-first twist `ξ = (ω, v)`:
/// `R = Exp(ω)`, `t = V(ω) v` with `V = J_l(ω)` ([`so3_left_jacobian`]); equals the matrix
/// exponential of [`hat_se3`]`(ξ)`. BARF's `camera.Lie.se3_to_SE3` (`w` first, then `u`).
pub fn se3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let omega = xi.fixed_rows::<3>(0).into_owned();
    let v = xi.fixed_rows::<3>(3).into_owned();
    Isometry3::from_parts(
        Translation3::from(so3_left_jacobian(&omega) * v),
        so3_exp(&omega),
    )
}

/// The true SE(3) logarithm, inverse of [`se3_exp`]: `ω = Log(R)` (`θ ∈ [0, π]`),
/// `v = J_l⁻¹(ω) t` ([`so3_left_jacobian_inverse`]). BARF's `camera.Lie.SE3_to_se3`.
pub fn se3_log(pose: &Isometry3<f64>) -> Vector6<f64> {
    let omega = so3_log(&pose.rotation);
    let v = so3_left_jacobian_inverse(&omega) * pose.translation.vector;
    Vector6::new(omega.x, omega.y, omega.z, v.x, v.y, v.z)
}

/// The SO(3)×R³ retraction of a rotation-first 6-vector `ξ = (ω, v)`: `R = Exp(ω)`, `t = v`.
/// Not the group exponential of SE(3) (see [`se3_exp`]): rotation and translation are
/// decoupled, as in splines on SO(3)×R³ and in PoseNet's separate heads.
pub fn so3_r3_exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let omega = xi.fixed_rows::<3>(0).into_owned();
    let v = xi.fixed_rows::<3>(3).into_owned();
    Isometry3::from_parts(Translation3::from(v), so3_exp(&omega))
}

/// Inverse of [`so3_r3_exp`]: `(Log(R), t)`.
pub fn so3_r3_log(pose: &Isometry3<f64>) -> Vector6<f64> {
    let omega = so3_log(&pose.rotation);
    let t = pose.translation.vector;
    Vector6::new(omega.x, omega.y, omega.z, t.x, t.y, t.z)
}

// ---------------------------------------------------------------------------------------------
// Quaternions: matrices, array orders, sign
// ---------------------------------------------------------------------------------------------

/// The rotation matrix of a unit quaternion, `R(q) v = vec(q ⊗ (0, v) ⊗ q*)` (Solà eq. 115).
pub fn quat_to_rotation_matrix(q: &UnitQuaternion<f64>) -> Matrix3<f64> {
    *q.to_rotation_matrix().matrix()
}

/// The unit quaternion of a rotation matrix (assumed orthonormal with determinant +1), with the
/// sign chosen by nalgebra's branch on the trace; use [`canonicalize_quat`] for `w ≥ 0`.
pub fn rotation_matrix_to_quat(rotation: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*rotation))
}

/// Smallest norm accepted by [`quat_from_wxyz`] and [`quat_from_xyzw`] before normalising (a
/// file row with a zero quaternion is an error, not a rotation).
pub const QUAT_MIN_NORM: f64 = 1e-6;

fn quat_normalized(q: Quaternion<f64>) -> Option<UnitQuaternion<f64>> {
    let n = q.norm();
    (n.is_finite() && n > QUAT_MIN_NORM).then(|| UnitQuaternion::new_unchecked(q / n))
}

/// From a real-first array `[w, x, y, z]` (EuRoC `q_w q_x q_y q_z`, PoseNet's output,
/// NICE-SLAM's `camera_tensor[0..4]`), normalised; `None` if the norm is below
/// [`QUAT_MIN_NORM`] or not finite.
pub fn quat_from_wxyz(wxyz: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let [w, x, y, z] = wxyz;
    quat_normalized(Quaternion::new(w, x, y, z))
}

/// From a real-last array `[x, y, z, w]` (TUM `qx qy qz qw`, Sophus `params()`, ROS, Eigen's
/// `coeffs()`), normalised; `None` if the norm is below [`QUAT_MIN_NORM`] or not finite.
pub fn quat_from_xyzw(xyzw: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let [x, y, z, w] = xyzw;
    quat_normalized(Quaternion::new(w, x, y, z))
}

/// To a real-first array `[w, x, y, z]`.
pub fn quat_to_wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// To a real-last array `[x, y, z, w]` (TUM order).
pub fn quat_to_xyzw(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.i, q.j, q.k, q.w]
}

/// The representative of `±q` with `w > 0`; when `w = 0`, the one whose first non-zero
/// imaginary component is positive. `q` and `−q` are the same rotation (PoseNet's `w > 0`
/// hemisphere, docs/methods.md §4.4).
pub fn canonicalize_quat(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    let flip = if q.w != 0.0 {
        q.w < 0.0
    } else {
        [q.i, q.j, q.k]
            .into_iter()
            .find(|c| *c != 0.0)
            .is_some_and(|c| c < 0.0)
    };
    if flip {
        UnitQuaternion::new_unchecked(-q.into_inner())
    } else {
        *q
    }
}

// ---------------------------------------------------------------------------------------------
// Euler angles
// ---------------------------------------------------------------------------------------------

/// Intrinsic Z-Y-X Euler angles (yaw about z, then pitch about the new y, then roll about the
/// newest x), radians: `R = Rz(yaw)·Ry(pitch)·Rx(roll)`. The same matrix is the *extrinsic*
/// X-Y-Z sequence (roll about the fixed x, then pitch about the fixed y, then yaw about the fixed
/// z), and nalgebra's `Rotation3::from_euler_angles(roll, pitch, yaw)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EulerZyx {
    /// Rotation about z, `(−π, π]`.
    pub yaw: f64,
    /// Rotation about y, `[−π/2, π/2]`.
    pub pitch: f64,
    /// Rotation about x, `(−π, π]`.
    pub roll: f64,
}

/// `R = Rz(yaw)·Ry(pitch)·Rx(roll)` ([`EulerZyx`]).
pub fn rotation_from_euler_zyx(angles: &EulerZyx) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), angles.yaw)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), angles.pitch)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), angles.roll)
}

/// The quaternion `q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll)` of [`rotation_from_euler_zyx`].
pub fn quat_from_euler_zyx(angles: &EulerZyx) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angles.yaw)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angles.pitch)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angles.roll)
}

/// The Z-Y-X Euler angles of a rotation matrix (orthonormal):
/// `pitch = atan2(−R₂₀, √(R₀₀² + R₁₀²))`, `roll = atan2(R₂₁, R₂₂)`, `yaw = atan2(R₁₀, R₀₀)`.
/// At gimbal lock (`cos² pitch <` [`EULER_GIMBAL_LOCK_MAX_COS_PITCH_SQ`]) only `yaw ∓ roll` is
/// determined; then `roll = 0` and `yaw = atan2(−R₀₁, R₁₁)`, which reproduces `R`.
pub fn euler_zyx_from_rotation(rotation: &Matrix3<f64>) -> EulerZyx {
    let r = rotation;
    let cos_pitch_sq = r[(0, 0)] * r[(0, 0)] + r[(1, 0)] * r[(1, 0)];
    let pitch = (-r[(2, 0)]).atan2(cos_pitch_sq.sqrt());
    if cos_pitch_sq < EULER_GIMBAL_LOCK_MAX_COS_PITCH_SQ {
        // With roll = 0: R₀₁ = −sin(yaw), R₁₁ = cos(yaw) for both pitch = ±π/2.
        EulerZyx {
            yaw: (-r[(0, 1)]).atan2(r[(1, 1)]),
            pitch,
            roll: 0.0,
        }
    } else {
        EulerZyx {
            yaw: r[(1, 0)].atan2(r[(0, 0)]),
            pitch,
            roll: r[(2, 1)].atan2(r[(2, 2)]),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Camera axes
// ---------------------------------------------------------------------------------------------

/// `cam_gl_from_cam_cv = diag(1, −1, −1)`: OpenCV camera axes (x right, y down, z forward) to
/// OpenGL/Blender/NeRF axes (x right, y up, z back); a rotation by π about x, its own inverse.
pub fn cam_gl_from_cam_cv() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)))
}

/// `world_from_cam_cv = world_from_cam_gl · diag(1, −1, −1)`: a camera-to-world pose with
/// OpenGL/Blender camera axes (Blender `transform_matrix`, LLFF after its axis swap, NICE-SLAM's
/// internal `c2w`) to one with OpenCV axes; same camera centre.
pub fn world_from_cam_cv_from_gl(world_from_cam_gl: &Isometry3<f64>) -> Isometry3<f64> {
    flip_cam_yz(world_from_cam_gl)
}

/// `world_from_cam_gl = world_from_cam_cv · diag(1, −1, −1)`, the inverse of
/// [`world_from_cam_cv_from_gl`] (the same map: the flip is an involution). This is NICE-SLAM's
/// `c2w[:3, 1] *= −1; c2w[:3, 2] *= −1` applied to every loaded OpenCV pose.
pub fn world_from_cam_gl_from_cv(world_from_cam_cv: &Isometry3<f64>) -> Isometry3<f64> {
    flip_cam_yz(world_from_cam_cv)
}

/// Negates the camera's y and z axes (columns 1 and 2 of the rotation), keeping the centre.
fn flip_cam_yz(world_from_cam: &Isometry3<f64>) -> Isometry3<f64> {
    // Right-multiplying by the π rotation about x, quaternion (0, 1, 0, 0).
    let flip = UnitQuaternion::new_unchecked(Quaternion::new(0.0, 1.0, 0.0, 0.0));
    Isometry3::from_parts(world_from_cam.translation, world_from_cam.rotation * flip)
}

// ---------------------------------------------------------------------------------------------
// Gravity and specific force
// ---------------------------------------------------------------------------------------------

/// Standard gravity magnitude used inside cpose, m/s² (docs/methods.md §4.1).
pub const GRAVITY_M_S2: f64 = 9.81;

/// `g_world = (0, 0, −9.81)` m/s²: worlds are z-up (synthetic data, EuRoC); a dataset with
/// another up axis keeps its own world and states its gravity vector.
pub fn gravity_world() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -GRAVITY_M_S2)
}

/// The specific force an accelerometer rigidly attached to the body measures, in the body frame:
/// `f = Rᵀ (p̈ − g_world)` with `R` the rotation of `world_from_body` (docs/methods.md §4.2).
/// At rest and level it is `(0, 0, +9.81)`: the reaction to gravity, pointing up.
pub fn specific_force_body(
    world_from_body_rotation: &UnitQuaternion<f64>,
    lin_acc_world: &Vector3<f64>,
    gravity_world: &Vector3<f64>,
) -> Vector3<f64> {
    world_from_body_rotation.inverse_transform_vector(&(lin_acc_world - gravity_world))
}

// ---------------------------------------------------------------------------------------------
// Quaternion kinematics
// ---------------------------------------------------------------------------------------------

/// `Ω(ω)` with `q ⊗ (0, ω) = Ω(ω) q` (rows and columns ordered `w, x, y, z`), so that
/// `q̇ = ½ Ω(ω_body) q` (docs/methods.md §4.3; Solà eq. 199 with body rates):
/// `[[0, −ωx, −ωy, −ωz], [ωx, 0, ωz, −ωy], [ωy, −ωz, 0, ωx], [ωz, ωy, −ωx, 0]]`.
pub fn omega_matrix<T: RealField + Copy>(ang_vel_body: &Vector3<T>) -> Matrix4<T> {
    let (x, y, z) = (ang_vel_body.x, ang_vel_body.y, ang_vel_body.z);
    let o = T::zero();
    Matrix4::new(
        o, -x, -y, -z, //
        x, o, z, -y, //
        y, -z, o, x, //
        z, y, -x, o,
    )
}

/// `q̇ = ½ q ⊗ (0, ω_body)`, the quaternion rate of `world_from_body` for the body angular
/// velocity defined by `Ṙ = R [ω_body]×` (Solà eq. 199).
pub fn quat_rate_from_ang_vel_body<T: RealField + Copy>(
    q: &Quaternion<T>,
    ang_vel_body: &Vector3<T>,
) -> Quaternion<T> {
    let half = T::one() / (T::one() + T::one());
    (*q * Quaternion::from_imag(*ang_vel_body)) * half
}

/// `ω_body = 2 vec(q* ⊗ q̇)`, the inverse of [`quat_rate_from_ang_vel_body`] for unit `q`.
pub fn ang_vel_body_from_quat_rate<T: RealField + Copy>(
    q: &Quaternion<T>,
    q_rate: &Quaternion<T>,
) -> Vector3<T> {
    let two = T::one() + T::one();
    (q.conjugate() * *q_rate).imag() * two
}

/// `q̈ = ½ q ⊗ (0, α_body) − ¼ |ω_body|² q`, the second derivative of `q` for body angular
/// velocity `ω_body` and acceleration `α_body = ω̇_body` (differentiate `q̇ = ½ q ⊗ (0, ω)` and
/// use `(0, ω) ⊗ (0, ω) = (−|ω|², 0)`).
pub fn quat_acc_from_ang_body<T: RealField + Copy>(
    q: &Quaternion<T>,
    ang_vel_body: &Vector3<T>,
    ang_acc_body: &Vector3<T>,
) -> Quaternion<T> {
    let two = T::one() + T::one();
    let four = two * two;
    *q * Quaternion::from_imag(*ang_acc_body) / two - *q * (ang_vel_body.norm_squared() / four)
}

/// A quaternion-valued function of time and its first two derivatives, `(q, q̇, q̈)`, with the
/// product rule and its adjoint. Pose fields use it to compose rotations exactly:
/// `(a ⊗ b)˙ = ȧ ⊗ b + a ⊗ ḃ`, `(a ⊗ b)¨ = ä ⊗ b + 2 ȧ ⊗ ḃ + a ⊗ b̈`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuatJet {
    /// `q`.
    pub value: Quaternion<f64>,
    /// `q̇`.
    pub rate: Quaternion<f64>,
    /// `q̈`.
    pub acc: Quaternion<f64>,
}

impl QuatJet {
    /// The zero jet.
    pub fn zeros() -> Self {
        let z = Quaternion::new(0.0, 0.0, 0.0, 0.0);
        Self {
            value: z,
            rate: z,
            acc: z,
        }
    }

    /// A jet from its three parts.
    pub fn new(value: Quaternion<f64>, rate: Quaternion<f64>, acc: Quaternion<f64>) -> Self {
        Self { value, rate, acc }
    }

    /// The pure-imaginary jet `((0, v), (0, v̇), (0, v̈))` of a vector and its derivatives.
    pub fn from_vectors(v: &Vector3<f64>, v_rate: &Vector3<f64>, v_acc: &Vector3<f64>) -> Self {
        Self::new(
            Quaternion::from_imag(*v),
            Quaternion::from_imag(*v_rate),
            Quaternion::from_imag(*v_acc),
        )
    }

    /// Componentwise conjugate `(q*, q̇*, q̈*)` (conjugation is linear).
    pub fn conjugate(&self) -> Self {
        Self::new(
            self.value.conjugate(),
            self.rate.conjugate(),
            self.acc.conjugate(),
        )
    }

    /// The product jet of `self ⊗ rhs` by the Leibniz rule.
    pub fn mul(&self, rhs: &QuatJet) -> QuatJet {
        let (a, b) = (self, rhs);
        QuatJet {
            value: a.value * b.value,
            rate: a.rate * b.value + a.value * b.rate,
            acc: a.acc * b.value + (a.rate * b.rate) * 2.0 + a.value * b.acc,
        }
    }

    /// The adjoint of [`QuatJet::mul`]: given the cotangent `g` of `c = self ⊗ rhs` (gradients of
    /// a loss with respect to `c, ċ, c̈`, Euclidean in the four coordinates), returns the
    /// cotangents of `self` and `rhs`. Uses `⟨g, a ⊗ b⟩ = ⟨g ⊗ b*, a⟩ = ⟨a* ⊗ g, b⟩` (true for any
    /// quaternions, the left and right multiplication matrices are transposed by conjugation).
    pub fn mul_backward(&self, rhs: &QuatJet, g: &QuatJet) -> (QuatJet, QuatJet) {
        let (a, b) = (self, rhs);
        let (ac, bc) = (a.conjugate(), b.conjugate());
        let grad_a = QuatJet {
            value: g.value * bc.value + g.rate * bc.rate + g.acc * bc.acc,
            rate: g.rate * bc.value + (g.acc * bc.rate) * 2.0,
            acc: g.acc * bc.value,
        };
        let grad_b = QuatJet {
            value: ac.value * g.value + ac.rate * g.rate + ac.acc * g.acc,
            rate: ac.value * g.rate + (ac.rate * g.acc) * 2.0,
            acc: ac.value * g.acc,
        };
        (grad_a, grad_b)
    }

    /// Adds another jet componentwise.
    pub fn add(&self, rhs: &QuatJet) -> QuatJet {
        QuatJet::new(
            self.value + rhs.value,
            self.rate + rhs.rate,
            self.acc + rhs.acc,
        )
    }
}

/// How far `r` is from a rotation: the larger of `‖RᵀR − I‖_F` and `|det R − 1|` (0 for a
/// rotation, NaN for a non-finite entry). Readers refuse a matrix beyond
/// [`MAX_ROTATION_DEFECT`] rather than guess the rotation it meant.
pub fn rotation_defect(r: &Matrix3<f64>) -> f64 {
    (r.transpose() * r - Matrix3::identity())
        .norm()
        .max((r.determinant() - 1.0).abs())
}

/// The largest [`rotation_defect`] a reader accepts (rounding in files written with 6 or more
/// digits stays far below it).
pub const MAX_ROTATION_DEFECT: f64 = 1e-3;

/// The isometry of a row-major 3×4 or 4×4 matrix `m` (its first 12 entries), its rotation block
/// re-orthonormalised; `Err(defect)` when that block is not within [`MAX_ROTATION_DEFECT`] of a
/// rotation or an entry is not finite (defect NaN).
pub fn isometry_from_rows(m: &[f64]) -> Result<Isometry3<f64>, f64> {
    if m.len() < 12 || m[..12].iter().any(|v| !v.is_finite()) {
        return Err(f64::NAN);
    }
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let defect = rotation_defect(&r);
    if defect.is_nan() || defect > MAX_ROTATION_DEFECT {
        return Err(defect);
    }
    Ok(Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r)),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn random_vec3(rng: &mut ChaCha8Rng, scale: f64) -> Vector3<f64> {
        Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * scale
    }

    /// A rotation vector with a uniformly random angle in `[0, max_angle)` about a random axis.
    fn random_rot_vec(rng: &mut ChaCha8Rng, max_angle: f64) -> Vector3<f64> {
        let axis = loop {
            let v = random_vec3(rng, 1.0);
            let n = v.norm();
            if n > 0.1 && n <= 1.0 {
                break v / n;
            }
        };
        axis * rng.random_range(0.0..max_angle)
    }

    fn random_pose(rng: &mut ChaCha8Rng) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(random_vec3(rng, 5.0)),
            so3_exp(&random_rot_vec(rng, PI)),
        )
    }

    fn assert_pose_eq(a: &Isometry3<f64>, b: &Isometry3<f64>, tol: f64) {
        let d = (a.to_homogeneous() - b.to_homogeneous()).abs().max();
        assert!(d < tol, "poses differ by {d:.3e}:\n{a}\n{b}");
    }

    // ----- conventions -----------------------------------------------------------------------

    #[test]
    fn quaternion_new_is_w_first_and_tum_rows_are_xyzw() {
        let q = Quaternion::new(1.0, 2.0, 3.0, 4.0);
        assert_eq!((q.w, q.i, q.j, q.k), (1.0, 2.0, 3.0, 4.0));
        // nalgebra stores the coordinates real-last; never index `coords` expecting w first.
        assert_eq!(q.coords.as_slice(), &[2.0, 3.0, 4.0, 1.0]);
        // A TUM row `timestamp tx ty tz qx qy qz qw` (freiburg1_xyz ground truth, first line).
        let row = [
            1305031098.6659,
            1.3563,
            0.6305,
            1.6380,
            0.6132,
            0.5962,
            -0.3311,
            -0.3986,
        ];
        let q = quat_from_xyzw([row[4], row[5], row[6], row[7]]).expect("unit-ish");
        let n =
            (0.6132f64.powi(2) + 0.5962f64.powi(2) + 0.3311f64.powi(2) + 0.3986f64.powi(2)).sqrt();
        assert!((q.w - -0.3986 / n).abs() < 1e-15);
        assert!((q.i - 0.6132 / n).abs() < 1e-15);
        assert!((q.k - -0.3311 / n).abs() < 1e-15);
        let back = quat_to_xyzw(&q);
        assert!((back[3] - q.w).abs() == 0.0 && back[0] == q.i);
        // The same rotation written EuRoC-style, w first.
        let e = quat_from_wxyz([row[7], row[4], row[5], row[6]]).expect("unit-ish");
        assert_eq!(e, q);
        assert_eq!(quat_to_wxyz(&e), [q.w, q.i, q.j, q.k]);
        assert!(quat_from_wxyz([0.0; 4]).is_none());
        assert!(quat_from_xyzw([f64::NAN, 0.0, 0.0, 1.0]).is_none());
    }

    #[test]
    fn hamilton_product_i_times_j_is_k() {
        let i = Quaternion::new(0.0, 1.0, 0.0, 0.0);
        let j = Quaternion::new(0.0, 0.0, 1.0, 0.0);
        let k = Quaternion::new(0.0, 0.0, 0.0, 1.0);
        assert_eq!(i * j, k);
        assert_eq!(j * k, i);
        assert_eq!(k * i, j);
        assert_eq!(j * i, -k);
        assert_eq!(i * i, Quaternion::new(-1.0, 0.0, 0.0, 0.0));
    }

    #[test]
    fn plus_90_degree_yaw_rotates_x_to_y() {
        let q = so3_exp(&Vector3::new(0.0, 0.0, FRAC_PI_2));
        let s = 0.5f64.sqrt();
        assert!((quat_to_wxyz(&q)[0] - s).abs() < 1e-15 && (q.k - s).abs() < 1e-15);
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-15);
        // The same rotation acts as q ⊗ (0, v) ⊗ q* and as the matrix R(q).
        let v = Vector3::new(0.3, -1.2, 0.7);
        let sandwich =
            (q.into_inner() * Quaternion::from_imag(v) * q.conjugate().into_inner()).imag();
        assert!((sandwich - quat_to_rotation_matrix(&q) * v).norm() < 1e-15);
        assert!((sandwich - q * v).norm() < 1e-15);
    }

    #[test]
    fn transforms_are_target_from_source_and_compose_right_to_left() {
        let world_from_body = Isometry3::from_parts(
            Translation3::new(1.0, 0.0, 0.0),
            so3_exp(&Vector3::new(0.0, 0.0, FRAC_PI_2)),
        );
        let body_from_cam =
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::identity());
        let world_from_cam = world_from_body * body_from_cam;
        let point_in_cam = Point3::new(1.0, 0.0, 0.0);
        let point_in_body = body_from_cam * point_in_cam;
        assert_eq!(point_in_body, Point3::new(1.0, 0.0, 1.0));
        let point_in_world = world_from_cam * point_in_cam;
        assert!((point_in_world - Point3::new(1.0, 1.0, 1.0)).norm() < 1e-15);
        assert!((world_from_body * point_in_body - point_in_world).norm() < 1e-15);
        // The camera centre in the world is the translation of world_from_cam.
        let centre = world_from_cam * Point3::origin();
        assert!((centre.coords - world_from_cam.translation.vector).norm() == 0.0);
        assert!((centre - Point3::new(1.0, 0.0, 1.0)).norm() < 1e-15);
    }

    #[test]
    fn opengl_camera_looking_down_minus_z_looks_down_plus_z_in_opencv() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let world_from_cam_gl = random_pose(&mut rng);
        let world_from_cam_cv = world_from_cam_cv_from_gl(&world_from_cam_gl);
        // Viewing direction: −z in GL, +z in CV; up: +y in GL, −y in CV; right: +x in both.
        let view_gl = world_from_cam_gl.rotation * -Vector3::z();
        let view_cv = world_from_cam_cv.rotation * Vector3::z();
        assert!((view_gl - view_cv).norm() < 1e-14);
        let up_gl = world_from_cam_gl.rotation * Vector3::y();
        assert!((up_gl - world_from_cam_cv.rotation * -Vector3::y()).norm() < 1e-14);
        let right = world_from_cam_gl.rotation * Vector3::x();
        assert!((right - world_from_cam_cv.rotation * Vector3::x()).norm() < 1e-14);
        assert_eq!(world_from_cam_gl.translation, world_from_cam_cv.translation);
        // world_from_cam_cv = world_from_cam_gl · diag(1, −1, −1), as 4×4 matrices.
        let mut flip = Matrix4::identity();
        flip.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(cam_gl_from_cam_cv().matrix());
        let expected = world_from_cam_gl.to_homogeneous() * flip;
        assert!((world_from_cam_cv.to_homogeneous() - expected).abs().max() < 1e-14);
        // NICE-SLAM: c2w[:3, 1] *= −1; c2w[:3, 2] *= −1 is the same map, and an involution.
        let mut nice = world_from_cam_cv.to_homogeneous();
        for c in 1..3 {
            for r in 0..3 {
                nice[(r, c)] = -nice[(r, c)];
            }
        }
        let gl = world_from_cam_gl_from_cv(&world_from_cam_cv);
        assert!((gl.to_homogeneous() - nice).abs().max() < 1e-14);
        assert_pose_eq(&gl, &world_from_cam_gl, 1e-14);
    }

    #[test]
    fn euler_zyx_known_values() {
        let rot = |yaw, pitch, roll| rotation_from_euler_zyx(&EulerZyx { yaw, pitch, roll });
        // Yaw +90°: x → y. Pitch +90°: x → −z. Roll +90°: y → z.
        assert!((rot(FRAC_PI_2, 0.0, 0.0) * Vector3::x() - Vector3::y()).norm() < 1e-15);
        assert!((rot(0.0, FRAC_PI_2, 0.0) * Vector3::x() + Vector3::z()).norm() < 1e-15);
        assert!((rot(0.0, 0.0, FRAC_PI_2) * Vector3::y() - Vector3::z()).norm() < 1e-15);
        // R = Rz(yaw)·Ry(pitch)·Rx(roll): roll is applied to the vector first (extrinsic X-Y-Z),
        // and it is nalgebra's from_euler_angles(roll, pitch, yaw).
        let (yaw, pitch, roll) = (0.7, -0.4, 1.9);
        let r = rot(yaw, pitch, roll);
        let v = Vector3::new(0.2, -0.5, 0.9);
        let fixed_axes = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
            * (Rotation3::from_axis_angle(&Vector3::y_axis(), pitch)
                * (Rotation3::from_axis_angle(&Vector3::x_axis(), roll) * v));
        assert!((r * v - fixed_axes).norm() < 1e-15);
        let na = Rotation3::from_euler_angles(roll, pitch, yaw);
        assert!((r.matrix() - na.matrix()).abs().max() < 1e-15);
        let q = quat_from_euler_zyx(&EulerZyx { yaw, pitch, roll });
        assert!((quat_to_rotation_matrix(&q) - r.matrix()).abs().max() < 1e-15);
    }

    #[test]
    fn euler_zyx_round_trips_and_gimbal_lock() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..500 {
            let e = EulerZyx {
                yaw: rng.random_range(-PI..PI),
                pitch: rng.random_range(-FRAC_PI_2 + 1e-3..FRAC_PI_2 - 1e-3),
                roll: rng.random_range(-PI..PI),
            };
            let back = euler_zyx_from_rotation(rotation_from_euler_zyx(&e).matrix());
            assert!((back.yaw - e.yaw).abs() < 1e-11, "{e:?} vs {back:?}");
            assert!((back.pitch - e.pitch).abs() < 1e-11, "{e:?} vs {back:?}");
            assert!((back.roll - e.roll).abs() < 1e-11, "{e:?} vs {back:?}");
        }
        for pitch in [FRAC_PI_2, -FRAC_PI_2] {
            for (yaw, roll) in [(0.3, 0.0), (-1.0, 0.5), (2.5, -2.0)] {
                let r = rotation_from_euler_zyx(&EulerZyx { yaw, pitch, roll });
                let e = euler_zyx_from_rotation(r.matrix());
                assert!(e.yaw.is_finite() && e.roll == 0.0);
                assert!((e.pitch - pitch).abs() < 1e-7);
                let again = rotation_from_euler_zyx(&e);
                assert!((again.matrix() - r.matrix()).abs().max() < 1e-12);
            }
        }
    }

    #[test]
    fn specific_force_at_rest_points_up() {
        let level = UnitQuaternion::identity();
        let f = specific_force_body(&level, &Vector3::zeros(), &gravity_world());
        assert_eq!(f, Vector3::new(0.0, 0.0, 9.81));
        // Rolled +90° about x: R = Rx(90°) maps body +y to world +z, so up is body +y.
        let rolled = so3_exp(&Vector3::new(FRAC_PI_2, 0.0, 0.0));
        let f = specific_force_body(&rolled, &Vector3::zeros(), &gravity_world());
        assert!((f - Vector3::new(0.0, 9.81, 0.0)).norm() < 1e-14, "{f}");
        // Free fall measures nothing.
        let f = specific_force_body(&rolled, &gravity_world(), &gravity_world());
        assert!(f.norm() < 1e-15);
    }

    #[test]
    fn se3_tangent_is_rotation_first() {
        let rot_only = se3_exp(&Vector6::new(0.0, 0.0, FRAC_PI_2, 0.0, 0.0, 0.0));
        assert_eq!(rot_only.translation.vector, Vector3::zeros());
        assert!((rot_only.rotation * Vector3::x() - Vector3::y()).norm() < 1e-15);
        let trans_only = se3_exp(&Vector6::new(0.0, 0.0, 0.0, 1.0, 2.0, 3.0));
        assert_eq!(trans_only.rotation, UnitQuaternion::identity());
        assert_eq!(trans_only.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    }

    // ----- SO(3) -----------------------------------------------------------------------------

    #[test]
    fn so3_exp_log_round_trip_including_near_zero_and_near_pi() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..500 {
            let phi = random_rot_vec(&mut rng, PI);
            let back = so3_log(&so3_exp(&phi));
            assert!(
                (back - phi).norm() < 1e-12 * (1.0 + phi.norm()),
                "{phi} {back}"
            );
            let m = so3_exp_matrix(&phi);
            assert!((so3_log_matrix(&m) - phi).norm() < 1e-12);
            // Rodrigues' formula as an independent reference.
            let th = phi.norm();
            let k = hat(&phi);
            let rodrigues =
                Matrix3::identity() + k * (th.sin() / th) + k * k * ((1.0 - th.cos()) / (th * th));
            assert!((m - rodrigues).abs().max() < 1e-14);
        }
        let axis = Vector3::new(0.48, -0.6, 0.64);
        for theta in [
            0.0,
            1e-12,
            1e-9,
            1e-6,
            1e-3,
            0.1,
            PI - 1e-3,
            PI - 1e-6,
            PI - 1e-9,
        ] {
            let phi = axis * theta;
            let q = so3_exp(&phi);
            assert!((q.into_inner().norm() - 1.0).abs() < 1e-15);
            let back = so3_log(&q);
            // Relative accuracy near 0, absolute near π (the axis error there is ~ε/sin(θ/2)).
            assert!(
                (back - phi).norm() <= 1e-15 * theta + 1e-15,
                "θ = {theta}: {back}"
            );
        }
        // Exactly π: the log has angle π about ±axis, and exp of it is the same rotation.
        let q = so3_exp(&(axis * PI));
        let back = so3_log(&q);
        assert!((back.norm() - PI).abs() < 1e-14);
        assert!(rotation_angle_between(&so3_exp(&back), &q) < 1e-14);
        // Beyond π the log wraps to the shorter rotation, 2π − θ about −axis.
        let back = so3_log(&so3_exp(&(axis * (PI + 0.5))));
        assert!((back + axis * (PI - 0.5)).norm() < 1e-14);
    }

    #[test]
    fn taylor_branches_agree_with_closed_forms_at_their_thresholds() {
        // so3_exp: just below the threshold (Taylor) vs the closed form at the same angle.
        let axis = Vector3::new(0.0, 0.6, 0.8);
        let theta = (SO3_EXP_TAYLOR_MAX_THETA_SQ * (1.0 - 1e-9)).sqrt();
        let q = so3_exp(&(axis * theta));
        let closed = Quaternion::from_parts((0.5 * theta).cos(), axis * (0.5 * theta).sin());
        let d = (q.into_inner() - closed).norm();
        assert!(d < 3e-16, "exp branches differ by {d:.3e}");
        // so3_log: series vs atan2 at |v|² = threshold.
        let n = SO3_LOG_TAYLOR_MAX_SIN_HALF_SQ.sqrt();
        let w = (1.0 - n * n).sqrt();
        let q = UnitQuaternion::new_unchecked(Quaternion::from_parts(w, axis * n));
        let below =
            UnitQuaternion::new_unchecked(Quaternion::from_parts(w, axis * (n * (1.0 - 1e-12))));
        let closed = |q: &UnitQuaternion<f64>| {
            let v = q.imag();
            v * (2.0 * v.norm().atan2(q.w) / v.norm())
        };
        let (d1, d2) = (
            (so3_log(&q) - closed(&q)).norm(),
            (so3_log(&below) - closed(&below)).norm(),
        );
        assert!(
            d1 < 1e-18 && d2 < 1e-18,
            "log branches differ by {d1:.3e}, {d2:.3e}"
        );
        // Jacobian coefficients at θ² = threshold: truncation O(θ⁸) vs cancellation ε/θ².
        let t2 = SO3_JACOBIAN_TAYLOR_MAX_THETA_SQ;
        let (a_t, b_t) = jacobian_coeffs_taylor(t2);
        let (a_c, b_c) = jacobian_coeffs_closed(t2);
        assert!((a_t - a_c).abs() < 2e-14, "{a_t} vs {a_c}");
        assert!((b_t - b_c).abs() < 2e-14, "{b_t} vs {b_c}");
        let (c_t, c_c) = (inv_jacobian_coeff_taylor(t2), inv_jacobian_coeff_closed(t2));
        // 1/θ² − cot(θ/2)/(2θ) cancels two terms of size 1/θ² = 100: rounding ≈ 100·ε.
        assert!((c_t - c_c).abs() < 5e-14, "{c_t} vs {c_c}");
        // And at θ = 0 the series give the limits.
        assert_eq!(jacobian_coeffs_taylor(0.0), (0.5, 1.0 / 6.0));
        assert_eq!(inv_jacobian_coeff_taylor(0.0), 1.0 / 12.0);
        assert_eq!(so3_left_jacobian(&Vector3::zeros()), Matrix3::identity());
    }

    /// Central difference of a vector function of a 3-vector, column by column. `h = 1e-5`:
    /// truncation `O(h²) ≈ 1e-10`, rounding `≈ ε/h ≈ 1e-11`.
    fn fd_jacobian(f: impl Fn(&Vector3<f64>) -> Vector3<f64>, h: f64) -> Matrix3<f64> {
        let mut j = Matrix3::zeros();
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = h;
            j.set_column(k, &((f(&e) - f(&-e)) / (2.0 * h)));
        }
        j
    }

    #[test]
    fn so3_jacobians_match_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut cases: Vec<Vector3<f64>> = (0..50).map(|_| random_rot_vec(&mut rng, 3.0)).collect();
        cases.push(Vector3::zeros());
        cases.push(Vector3::new(1e-4, -2e-4, 5e-5)); // inside the Taylor branch
        cases.push(Vector3::new(0.06, -0.05, 0.04)); // at the switch
        cases.push(Vector3::new(0.0, 3.1, 0.0)); // near π
        let h = 1e-5;
        for phi in &cases {
            let r = so3_exp(phi);
            // Exp(φ + δ) ≈ Exp(J_l δ)·Exp(φ)
            let jl = fd_jacobian(|d| so3_log(&(so3_exp(&(phi + d)) * r.inverse())), h);
            assert!(
                (jl - so3_left_jacobian(phi)).abs().max() < 1e-8,
                "J_l at {phi}"
            );
            // Exp(φ + δ) ≈ Exp(φ)·Exp(J_r δ)
            let jr = fd_jacobian(|d| so3_log(&(r.inverse() * so3_exp(&(phi + d)))), h);
            assert!(
                (jr - so3_right_jacobian(phi)).abs().max() < 1e-8,
                "J_r at {phi}"
            );
            // Log(Exp(δ)·Exp(φ)) ≈ φ + J_l⁻¹ δ
            let jli = fd_jacobian(|d| so3_log(&(so3_exp(d) * r)), h);
            let tol = 1e-8 * (1.0 + jli.abs().max());
            assert!(
                (jli - so3_left_jacobian_inverse(phi)).abs().max() < tol,
                "J_l⁻¹ at {phi}"
            );
            let jri = fd_jacobian(|d| so3_log(&(r * so3_exp(d))), h);
            assert!((jri - so3_right_jacobian_inverse(phi)).abs().max() < tol);
            let prod = so3_left_jacobian(phi) * so3_left_jacobian_inverse(phi);
            assert!((prod - Matrix3::identity()).abs().max() < 1e-12);
        }
    }

    #[test]
    fn geodesic_angle_between_rotations() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..100 {
            let a = so3_exp(&random_rot_vec(&mut rng, PI));
            let d = random_rot_vec(&mut rng, PI);
            let b = a * so3_exp(&d);
            assert!((rotation_angle_between(&a, &b) - d.norm()).abs() < 1e-12);
            // −q is the same rotation.
            let b_neg = UnitQuaternion::new_unchecked(-b.into_inner());
            assert!((rotation_angle_between(&a, &b_neg) - d.norm()).abs() < 1e-12);
        }
        let a = UnitQuaternion::identity();
        let tiny = so3_exp(&Vector3::new(1e-10, 0.0, 0.0));
        assert!((rotation_angle_between(&a, &tiny) - 1e-10).abs() < 1e-24);
    }

    #[test]
    fn canonical_quaternion_has_non_negative_w() {
        let q = UnitQuaternion::new_unchecked(Quaternion::new(-0.6, 0.0, 0.8, 0.0));
        let c = canonicalize_quat(&q);
        assert_eq!(quat_to_wxyz(&c), [0.6, -0.0, -0.8, -0.0]);
        assert_eq!(canonicalize_quat(&c), c);
        let half_turn = UnitQuaternion::new_unchecked(Quaternion::new(0.0, 0.0, -1.0, 0.0));
        assert_eq!(quat_to_wxyz(&canonicalize_quat(&half_turn))[2], 1.0);
    }

    #[test]
    fn hat_vee_and_cross_product() {
        let a = Vector3::new(0.3, -1.0, 2.0);
        let b = Vector3::new(-0.7, 0.4, 1.1);
        assert!((hat(&a) * b - a.cross(&b)).norm() < 1e-15);
        assert_eq!(vee(&hat(&a)), a);
        assert_eq!(hat(&a).transpose(), -hat(&a));
        let xi = Vector6::new(0.1, 0.2, 0.3, 4.0, 5.0, 6.0);
        assert_eq!(vee_se3(&hat_se3(&xi)), xi);
    }

    // ----- SE(3) -----------------------------------------------------------------------------

    #[test]
    fn se3_exp_is_the_matrix_exponential_and_differs_from_the_so3_r3_retraction() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..100 {
            let omega = random_rot_vec(&mut rng, 3.0);
            let v = random_vec3(&mut rng, 2.0);
            let xi = Vector6::new(omega.x, omega.y, omega.z, v.x, v.y, v.z);
            let t = se3_exp(&xi);
            let m = hat_se3(&xi).exp();
            assert!((t.to_homogeneous() - m).abs().max() < 1e-10);
            // BARF's se3_to_SE3: translation V(ω)·v.
            let expected_t = so3_left_jacobian(&omega) * v;
            assert!((t.translation.vector - expected_t).norm() < 1e-14);
            // The retraction keeps v as the translation; the two share the rotation.
            let r = so3_r3_exp(&xi);
            assert_eq!(r.translation.vector, v);
            assert_eq!(r.rotation, t.rotation);
            assert!((r.translation.vector - t.translation.vector).norm() > 1e-3);
            // Round trips.
            assert!((se3_log(&t) - xi).norm() < 1e-11 * (1.0 + xi.norm()));
            assert!((so3_r3_log(&r) - xi).norm() < 1e-12 * (1.0 + xi.norm()));
        }
        // A pure translation is the same in both conventions.
        let xi = Vector6::new(0.0, 0.0, 0.0, 1.0, -2.0, 3.0);
        assert_pose_eq(&se3_exp(&xi), &so3_r3_exp(&xi), 0.0 + 1e-300);
    }

    #[test]
    fn se3_group_laws_on_seeded_random_poses() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let identity = Isometry3::identity();
        for _ in 0..200 {
            let a = random_pose(&mut rng);
            let b = random_pose(&mut rng);
            let c = random_pose(&mut rng);
            assert_pose_eq(&(a * identity), &a, 1e-15);
            assert_pose_eq(&(identity * a), &a, 1e-15);
            assert_pose_eq(&(a * a.inverse()), &identity, 1e-13);
            assert_pose_eq(&(a.inverse() * a), &identity, 1e-13);
            assert_pose_eq(&((a * b) * c), &(a * (b * c)), 1e-12);
            assert_pose_eq(&(a * b).inverse(), &(b.inverse() * a.inverse()), 1e-12);
            assert_pose_eq(&se3_exp(&se3_log(&a)), &a, 1e-12);
            assert_pose_eq(&so3_r3_exp(&so3_r3_log(&a)), &a, 1e-13);
            // Exp(−ξ) = Exp(ξ)⁻¹.
            let xi = se3_log(&a);
            assert_pose_eq(&se3_exp(&-xi), &a.inverse(), 1e-12);
            assert_eq!(se3_log(&identity), Vector6::zeros());
        }
    }

    // ----- quaternion kinematics -------------------------------------------------------------

    #[test]
    fn omega_matrix_is_right_multiplication_by_the_pure_quaternion() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let q = so3_exp(&random_rot_vec(&mut rng, PI)).into_inner();
        let w = random_vec3(&mut rng, 2.0);
        let lhs = omega_matrix(&w) * nalgebra::Vector4::new(q.w, q.i, q.j, q.k);
        let rhs = q * Quaternion::from_imag(w);
        let rhs = nalgebra::Vector4::new(rhs.w, rhs.i, rhs.j, rhs.k);
        assert!((lhs - rhs).norm() < 1e-15);
    }

    #[test]
    fn quaternion_rate_and_acceleration_match_finite_differences() {
        // R(t) = R0·Exp(ω0 t + ½ α t²) about a fixed axis has body rate ω0 + α t (same axis);
        // a general curve: q(t) = q0 ⊗ Exp(a t) ⊗ Exp(b t²) — compare with central differences.
        let q0 = so3_exp(&Vector3::new(0.4, -0.3, 1.2));
        let a = Vector3::new(0.5, 0.1, -0.7);
        let b = Vector3::new(-0.2, 0.9, 0.3);
        let q = |t: f64| (q0 * so3_exp(&(a * t)) * so3_exp(&(b * (t * t)))).into_inner();
        let t = 0.6;
        let h = 1e-4; // truncation O(h²) ≈ 1e-8 on q̇, rounding ε/h² ≈ 1e-8 on q̈
        let q_rate = (q(t + h) - q(t - h)) / (2.0 * h);
        let q_acc = (q(t + h) - q(t) * 2.0 + q(t - h)) / (h * h);
        let w_body = ang_vel_body_from_quat_rate(&q(t), &q_rate);
        assert!((quat_rate_from_ang_vel_body(&q(t), &w_body) - q_rate).norm() < 1e-8);
        let w_body_of = |s: f64| {
            let r = (q(s + h) - q(s - h)) / (2.0 * h);
            ang_vel_body_from_quat_rate(&q(s), &r)
        };
        let alpha_body = (w_body_of(t + h) - w_body_of(t - h)) / (2.0 * h);
        let acc = quat_acc_from_ang_body(&q(t), &w_body, &alpha_body);
        assert!((acc - q_acc).norm() < 1e-5, "{acc} vs {q_acc}");
        // Ṙ = R [ω_body]×.
        let r_of = |s: f64| quat_to_rotation_matrix(&UnitQuaternion::new_normalize(q(s)));
        let r_rate = (r_of(t + h) - r_of(t - h)) / (2.0 * h);
        assert!((r_rate - r_of(t) * hat(&w_body)).abs().max() < 1e-7);
    }

    #[test]
    fn quat_jet_product_rule_and_adjoint() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let rq = |rng: &mut ChaCha8Rng| {
            Quaternion::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let jet = |rng: &mut ChaCha8Rng| QuatJet::new(rq(rng), rq(rng), rq(rng));
        // Product rule against a curve: a(t) = a0 + a1 t + a2 t²/2 (jets of polynomials).
        let (a, b, g) = (jet(&mut rng), jet(&mut rng), jet(&mut rng));
        let at = |j: &QuatJet, t: f64| j.value + j.rate * t + j.acc * (0.5 * t * t);
        let c = a.mul(&b);
        let h = 1e-3; // products of quadratics are quartic: central differences exact to O(h²)
        let f = |t: f64| at(&a, t) * at(&b, t);
        assert!((c.value - f(0.0)).norm() < 1e-15);
        assert!((c.rate - (f(h) - f(-h)) / (2.0 * h)).norm() < 1e-5);
        assert!((c.acc - (f(h) - f(0.0) * 2.0 + f(-h)) / (h * h)).norm() < 1e-5);
        // Adjoint: ⟨g, a ⊗ b⟩ summed over the three parts is bilinear; check by directions.
        let dot = |x: &QuatJet, y: &QuatJet| {
            x.value.coords.dot(&y.value.coords)
                + x.rate.coords.dot(&y.rate.coords)
                + x.acc.coords.dot(&y.acc.coords)
        };
        let (ga, gb) = a.mul_backward(&b, &g);
        let (da, db) = (jet(&mut rng), jet(&mut rng));
        // d/ds ⟨g, (a + s da) ⊗ b⟩ = ⟨g, da ⊗ b⟩ = ⟨ga, da⟩, exactly (linear in a).
        assert!((dot(&g, &da.mul(&b)) - dot(&ga, &da)).abs() < 1e-14);
        assert!((dot(&g, &a.mul(&db)) - dot(&gb, &db)).abs() < 1e-14);
    }

    #[test]
    fn isometry_from_rows_refuses_what_is_not_a_rotation() {
        let pose = Isometry3::from_parts(
            Translation3::new(1.0, -2.0, 3.0),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
        );
        let m = pose.to_homogeneous();
        let rows: Vec<f64> = (0..4)
            .flat_map(|r| (0..4).map(move |c| m[(r, c)]))
            .collect();
        let back = isometry_from_rows(&rows).unwrap();
        assert!((back.to_homogeneous() - m).amax() < 1e-12);
        // Scaled, reflected, sheared or non-finite: refused with the defect.
        let mut scaled = rows.clone();
        scaled[0] *= 1.01;
        assert!(isometry_from_rows(&scaled).unwrap_err() > MAX_ROTATION_DEFECT);
        let mut reflected = rows.clone();
        for v in &mut reflected[..3] {
            *v = -*v;
        }
        assert!((isometry_from_rows(&reflected).unwrap_err() - 2.0).abs() < 1e-9);
        let mut nan = rows.clone();
        nan[5] = f64::NAN;
        assert!(isometry_from_rows(&nan).unwrap_err().is_nan());
        assert!(isometry_from_rows(&rows[..11]).is_err());
        // Rounding to 6 digits stays well inside the tolerance.
        let rounded: Vec<f64> = rows.iter().map(|v| (v * 1e6).round() / 1e6).collect();
        assert!(isometry_from_rows(&rounded).is_ok());
    }
}
