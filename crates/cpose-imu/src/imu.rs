//! IMU measurements in the body frame.

use nalgebra::Vector3;

/// One IMU reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Seconds since the sequence origin.
    pub t_secs: f64,
    /// Angular velocity of the body in the body frame, rad/s (`ω_body`, `Ṙ = R[ω]×`).
    pub gyro: Vector3<f64>,
    /// Specific force in the body frame, m/s²: `f = Rᵀ (p̈ − g_world)` (≈ +9.81 up at rest;
    /// see `cpose_core::geometry::specific_force_body`).
    pub accel: Vector3<f64>,
}
