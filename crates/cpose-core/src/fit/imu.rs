//! IMU readings in the body frame, and how they supervise a fit.

use crate::Order;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One IMU reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Seconds since the sequence origin.
    pub t_secs: f64,
    /// Angular velocity of the body in the body frame, rad/s (`ω_body`, `Ṙ = R[ω]×`).
    pub gyro: Vector3<f64>,
    /// Specific force in the body frame, m/s²: `f = Rᵀ (p̈ − g_world)` (≈ +9.81 up at rest;
    /// see [`crate::geometry::specific_force_body`]).
    pub accel: Vector3<f64>,
}

/// How IMU readings supervise a pose field, named as in configs and `metrics.json`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum ImuMode {
    /// Poses only.
    None,
    /// Plus the gyroscope integrated between two times (the paper's loose coupling).
    Loose,
    /// Plus the gyroscope through `q̇` (the paper's tight coupling).
    Tight,
    /// Plus the accelerometer through `p̈`.
    Accel,
    /// Plus both.
    Combined,
}

impl ImuMode {
    /// Whether the gyroscope enters through `q̇` (tight, combined).
    pub fn gyro(self) -> bool {
        matches!(self, Self::Tight | Self::Combined)
    }
    /// Whether the accelerometer enters through `p̈` (accel, combined).
    pub fn accel(self) -> bool {
        matches!(self, Self::Accel | Self::Combined)
    }
    /// The derivative order the field must give.
    pub fn order(self) -> Order {
        if self.accel() {
            Order::Acceleration
        } else if self.gyro() {
            Order::Velocity
        } else {
            Order::Pose
        }
    }
    /// The mode's name.
    pub fn key(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Loose => "loose",
            Self::Tight => "tight",
            Self::Accel => "accel",
            Self::Combined => "combined",
        }
    }
}
