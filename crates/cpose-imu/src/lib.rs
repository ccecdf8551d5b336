//! cpose-imu: IMU samples, the EuRoC reader, IMU losses through a pose field's time derivatives;
//! tasks `trajectory` (fit a pose field to poses and IMU) and `slam_imu`.

pub use cpose_slam;
