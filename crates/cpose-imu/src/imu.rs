//! IMU measurements in the body frame.

use nalgebra::Vector3;

/// Standard gravity, m/s², pointing along −z of a z-up world: `g_world = (0, 0, −9.81)`.
pub const GRAVITY_M_S2: f64 = 9.81;

/// `g_world` of a z-up world frame (EuRoC, the synthetic motions).
pub fn gravity_world() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -GRAVITY_M_S2)
}

/// One IMU reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Seconds since the sequence origin.
    pub t_secs: f64,
    /// Angular velocity of the body in the body frame, rad/s (`ω_body`, `Ṙ = R[ω]×`).
    pub gyro: Vector3<f64>,
    /// Specific force in the body frame, m/s²: `f = Rᵀ (p̈ − g_world)` (≈ +9.81 up at rest).
    pub accel: Vector3<f64>,
}
