//! An ESIM-style event simulator for a colour (Bayer) event camera, and the synthetic EventNeRF
//! datasets built with it from `cpose-nerf`'s scene renderer.
//!
//! # Model
//!
//! Each pixel sees one colour channel of an **RGGB** mosaic ([`bayer_channel`]: R at even row and
//! even column, B at odd row and odd column, G elsewhere — EventNeRF's `is_colored` mask) and
//! works on the log intensity `L = ln(I^2.2 + ε)` of that channel's value `I ∈ [0, 1]`
//! ([`log_intensity`]; `2.2` linearises the display value, `ε` is EventNeRF's `tonemap_eps`, so
//! that the simulated events match its loss `log(Ĉ^2.2 + ε)`).
//!
//! Between two renders at times `t_a < t_b` with values `L_a`, `L_b`, `L` is taken to be linear in
//! time. Each pixel keeps the reference `L_ref` of its last event (initially its first value);
//! whenever `L` crosses `L_ref ± C` the pixel fires an event of polarity `±1` at the interpolated
//! time `t = t_a + (L_ref ± C − L_a) / (L_b − L_a) · (t_b − t_a)` and moves `L_ref` by `±C` —
//! several events when several levels are crossed (ESIM, Rebecq et al., CoRL 2018, §3). `C` is
//! the contrast threshold `θ`, per pixel `θ + σ·N(0, 1)` with optional fixed-pattern noise
//! `σ`, at least [`MIN_THRESHOLD_FRACTION`]`·θ`. An event less than the refractory period after
//! the pixel's previous event is dropped (counted), but `L_ref` still moves, as in ESIM.
//!
//! Events are sorted by `(t, y, x)` at the end. The result is deterministic given the seed
//! (which only draws the thresholds); pixels are simulated in parallel rows.
//!
//! Not modelled: sensor noise events, bandwidth limits, the temporal aliasing of render steps
//! that are too coarse (take steps small enough that edges move about a pixel per step).

use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use cpose_core::random::standard_normal;
use cpose_core::{Order, PoseBatch, PoseField, Real, Timestamp};
use cpose_nerf::camera::PinholeCamera;
use cpose_nerf::image::Image;
use cpose_nerf::scene::SyntheticScene;

use crate::error::EventsError;
use crate::eventnerf::{EventNerfScene, HeldOutView, write_eventnerf};
use crate::stream::{Event, EventStream};
use crate::turntable::Turntable;

/// The display gamma undone before taking logs (EventNeRF's `2.2`).
pub const GAMMA: f64 = 2.2;

/// Noisy thresholds are clamped from below at this fraction of the nominal threshold, so that a
/// pixel never fires on rounding noise.
pub const MIN_THRESHOLD_FRACTION: f64 = 0.1;

/// The simulator's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatorConfig {
    /// Contrast threshold `θ` in log intensity (> 0). EventNeRF's synthetic data: 0.25.
    pub threshold: f64,
    /// Standard deviation of the per-pixel threshold around `θ` (≥ 0; 0 disables the noise).
    pub threshold_sigma: f64,
    /// Refractory period, seconds (≥ 0; 0 disables it).
    pub refractory_secs: f64,
    /// `ε` in `ln(I^2.2 + ε)` (> 0). EventNeRF's synthetic data: 0.1.
    pub eps: f64,
    /// Seed of the threshold noise.
    pub seed: u64,
}

impl Default for SimulatorConfig {
    fn default() -> Self {
        Self {
            threshold: 0.25,
            threshold_sigma: 0.0,
            refractory_secs: 0.0,
            eps: 0.1,
            seed: 0,
        }
    }
}

impl SimulatorConfig {
    /// Checks the ranges of the field docs; the error names the parameter.
    pub fn validate(&self) -> Result<(), EventsError> {
        let check = |ok: bool, key, expected, value: f64| {
            if ok {
                Ok(())
            } else {
                Err(EventsError::Invalid {
                    key,
                    expected,
                    found: value.to_string(),
                })
            }
        };
        let t = self.threshold;
        check(
            t > 0.0 && t.is_finite(),
            "simulator.threshold",
            "a finite value > 0",
            t,
        )?;
        let s = self.threshold_sigma;
        check(
            s >= 0.0 && s.is_finite(),
            "simulator.threshold_sigma",
            "a finite value ≥ 0",
            s,
        )?;
        let r = self.refractory_secs;
        check(
            r >= 0.0 && r.is_finite(),
            "simulator.refractory_secs",
            "a finite value ≥ 0",
            r,
        )?;
        check(
            self.eps > 0.0 && self.eps.is_finite(),
            "simulator.eps",
            "a finite value > 0",
            self.eps,
        )
    }
}

/// The colour channel (0 red, 1 green, 2 blue) of pixel column `x`, row `y` in an RGGB mosaic:
/// red at (even row, even column), blue at (odd row, odd column), green elsewhere.
pub fn bayer_channel(x: usize, y: usize) -> usize {
    (y % 2) + (x % 2)
}

/// `ln(max(I, 0)^2.2 + eps)`, the log intensity of a display value `I` (NaN counts as 0).
pub fn log_intensity(value: f64, eps: f64) -> f64 {
    (value.max(0.0).powf(GAMMA) + eps).ln()
}

/// Per pixel (row-major), the log intensity of its Bayer channel ([`bayer_channel`]).
pub fn mosaic_log_intensity(image: &Image, eps: f64) -> Vec<f64> {
    let (w, h) = (image.width(), image.height());
    let data = image.data();
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let v = data[3 * (y * w + x) + bayer_channel(x, y)];
            out.push(log_intensity(f64::from(v), eps));
        }
    }
    out
}

/// One pixel's state.
#[derive(Clone, Copy, Debug)]
struct PixelState {
    /// `L_ref`, the log intensity of the last event (or of the first frame).
    reference: f64,
    /// This pixel's contrast threshold.
    threshold: f64,
    /// Time of the last emitted event, ns (−∞ before the first).
    last_event_ns: f64,
}

/// A running simulation: feed it log-intensity frames in time order ([`EventSimulator::advance`]),
/// then take the sorted events ([`EventSimulator::finish`]). See the [module docs](self).
#[derive(Clone, Debug)]
pub struct EventSimulator {
    width: u16,
    height: u16,
    refractory_ns: f64,
    pixels: Vec<PixelState>,
    last_log: Vec<f64>,
    last_t_ns: i64,
    /// Events per image row, in time order within a pixel.
    rows: Vec<Vec<Event>>,
    dropped_refractory: usize,
}

/// The outcome of a simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedEvents {
    /// The events, sorted by `(t, y, x)`.
    pub events: EventStream,
    /// Events dropped by the refractory period.
    pub dropped_refractory: usize,
}

impl EventSimulator {
    /// A simulator for a `width × height` sensor starting at `t0` with the log-intensity frame
    /// `initial_log` (row-major, `width · height` values) as every pixel's reference.
    pub fn new(
        width: u16,
        height: u16,
        config: &SimulatorConfig,
        t0: Timestamp,
        initial_log: &[f64],
    ) -> Result<Self, EventsError> {
        config.validate()?;
        // Also rejects an empty sensor.
        EventStream::new(width, height)?;
        let n = usize::from(width) * usize::from(height);
        check_frame(initial_log, n)?;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let min_threshold = MIN_THRESHOLD_FRACTION * config.threshold;
        let pixels = initial_log
            .iter()
            .map(|&reference| {
                let noise = if config.threshold_sigma > 0.0 {
                    config.threshold_sigma * standard_normal(&mut rng)
                } else {
                    0.0
                };
                PixelState {
                    reference,
                    threshold: (config.threshold + noise).max(min_threshold),
                    last_event_ns: f64::NEG_INFINITY,
                }
            })
            .collect();
        Ok(Self {
            width,
            height,
            refractory_ns: config.refractory_secs * 1e9,
            pixels,
            last_log: initial_log.to_vec(),
            last_t_ns: t0.as_nanos(),
            rows: vec![Vec::new(); usize::from(height)],
            dropped_refractory: 0,
        })
    }

    /// The per-pixel contrast thresholds (row-major).
    pub fn thresholds(&self) -> Vec<f64> {
        self.pixels.iter().map(|p| p.threshold).collect()
    }

    /// Emits the events between the previous frame and the frame `log` at time `t` (later than
    /// the previous frame's), interpolating `L` linearly in time per pixel.
    pub fn advance(&mut self, t: Timestamp, log: &[f64]) -> Result<(), EventsError> {
        check_frame(log, self.pixels.len())?;
        let (t_a, t_b) = (self.last_t_ns, t.as_nanos());
        if t_b <= t_a {
            return Err(EventsError::Invalid {
                key: "simulator frame time",
                expected: "times increasing from frame to frame",
                found: format!("{t_b} ns after {t_a} ns"),
            });
        }
        let w = usize::from(self.width);
        let dt = (t_b - t_a) as f64;
        let refractory = self.refractory_ns;
        let dropped: usize = self
            .pixels
            .par_chunks_mut(w)
            .zip(self.rows.par_iter_mut())
            .zip(self.last_log.par_chunks(w).zip(log.par_chunks(w)))
            .enumerate()
            .map(|(y, ((states, events), (row_a, row_b)))| {
                let mut dropped = 0;
                for (x, state) in states.iter_mut().enumerate() {
                    let (l_a, l_b) = (row_a[x], row_b[x]);
                    let c = state.threshold;
                    let polarity: i8 = if l_b >= state.reference + c {
                        1
                    } else if l_b <= state.reference - c {
                        -1
                    } else {
                        continue;
                    };
                    let step = c * f64::from(polarity);
                    // Crossing levels L_ref + k·step, k = 1, 2, … while not beyond L_b.
                    while (l_b - (state.reference + step)) * f64::from(polarity) >= 0.0 {
                        state.reference += step;
                        // L_b ≠ L_a here (L_b is a threshold away from L_ref, L_a is within
                        // it); clamp against rounding.
                        let frac = ((state.reference - l_a) / (l_b - l_a)).clamp(0.0, 1.0);
                        let t_ns = t_a as f64 + frac * dt;
                        if t_ns - state.last_event_ns < refractory {
                            dropped += 1;
                            continue;
                        }
                        state.last_event_ns = t_ns;
                        events.push(Event {
                            t: Timestamp::from_nanos(t_ns.round() as i64),
                            x: x as u16,
                            y: y as u16,
                            p: polarity,
                        });
                    }
                }
                dropped
            })
            .sum();
        self.dropped_refractory += dropped;
        self.last_log.copy_from_slice(log);
        self.last_t_ns = t_b;
        Ok(())
    }

    /// The events so far, sorted by `(t, y, x)`.
    pub fn finish(self) -> Result<SimulatedEvents, EventsError> {
        let mut all: Vec<Event> = self.rows.into_iter().flatten().collect();
        all.par_sort_unstable_by_key(|e| (e.t, e.y, e.x));
        let mut events = EventStream::new(self.width, self.height)?;
        for e in all {
            events.push(e)?;
        }
        Ok(SimulatedEvents {
            events,
            dropped_refractory: self.dropped_refractory,
        })
    }
}

fn check_frame(log: &[f64], n: usize) -> Result<(), EventsError> {
    if log.len() != n {
        return Err(EventsError::Invalid {
            key: "simulator frame",
            expected: "one log intensity per pixel",
            found: format!("{} values for {n} pixels", log.len()),
        });
    }
    Ok(())
}

/// `n + 1` times evenly spaced over `[start, end]` seconds, both ends included.
pub fn uniform_times(start_secs: f64, end_secs: f64, n: usize) -> Vec<f64> {
    (0..=n)
        .map(|i| start_secs + (end_secs - start_secs) * i as f64 / n.max(1) as f64)
        .collect()
}

/// The sensor's width and height as event coordinates: 1 to 65535 pixels each.
fn sensor_size(camera: &PinholeCamera) -> Result<(u16, u16), EventsError> {
    let size = |v: usize, key| {
        u16::try_from(v)
            .ok()
            .filter(|&v| v > 0)
            .ok_or(EventsError::Invalid {
                key,
                expected: "1 to 65535 pixels",
                found: v.to_string(),
            })
    };
    Ok((
        size(camera.width, "camera.width")?,
        size(camera.height, "camera.height")?,
    ))
}

/// Renders `scene` with `camera` at the poses of `field` (`world_from_body` taken as
/// `world_from_camera`, OpenCV axes) at `render_times_secs` (increasing, inside the field's
/// range, at least two) with `supersample²` rays per pixel, and simulates the events between
/// consecutive renders. Event times are the field's times (seconds since its origin) in ns.
pub fn simulate_scene_events<S: Real>(
    scene: &SyntheticScene,
    camera: &PinholeCamera,
    field: &dyn PoseField<S>,
    render_times_secs: &[f64],
    supersample: usize,
    config: &SimulatorConfig,
) -> Result<SimulatedEvents, EventsError> {
    let (width, height) = sensor_size(camera)?;
    if render_times_secs.len() < 2 || supersample == 0 {
        return Err(EventsError::Invalid {
            key: "simulator render times",
            expected: "at least 2 render times and supersample ≥ 1",
            found: format!(
                "{} times, supersample {supersample}",
                render_times_secs.len()
            ),
        });
    }
    let mut poses = PoseBatch::default();
    field.evaluate(render_times_secs, Order::Pose, &mut poses)?;
    let frame = |i: usize| {
        let view = scene.render(camera, &poses.world_from_body(i), supersample);
        mosaic_log_intensity(&view.image, config.eps)
    };
    let stamp = |t: f64| Timestamp::from_secs_f64(t);
    let mut sim = EventSimulator::new(
        width,
        height,
        config,
        stamp(render_times_secs[0]),
        &frame(0),
    )?;
    for (i, &t) in render_times_secs.iter().enumerate().skip(1) {
        sim.advance(stamp(t), &frame(i))?;
    }
    sim.finish()
}

/// A synthetic EventNeRF dataset: a turntable revolution around [`SyntheticScene`], its events,
/// `views` training views and `held_out_views` rendered ground-truth views.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticEventsConfig {
    /// The camera path (one revolution over `turntable.duration_secs`).
    pub turntable: Turntable,
    /// The event camera (also the size of the held-out images).
    pub camera: PinholeCamera,
    /// Render steps over the revolution (≥ 1; frames at `i · T / steps`, both ends included).
    pub render_steps: usize,
    /// Rays per pixel side for the event renders (≥ 1).
    pub supersample: usize,
    /// Training views `K ≥ 2`, at `i · T / (K − 1)` (view `K − 1` repeats view 0's pose).
    pub views: usize,
    /// Held-out views, at `(j + ½) · T / n`, rendered with `held_out_supersample`.
    pub held_out_views: usize,
    /// Rays per pixel side for the held-out images (≥ 1).
    pub held_out_supersample: usize,
    /// The event simulator.
    pub simulator: SimulatorConfig,
}

impl SyntheticEventsConfig {
    /// Checks the ranges of the field docs; the error names the parameter.
    pub fn validate(&self) -> Result<(), EventsError> {
        self.turntable.validate()?;
        self.simulator.validate()?;
        sensor_size(&self.camera)?;
        let invalid = |key, expected, found: usize| EventsError::Invalid {
            key,
            expected,
            found: found.to_string(),
        };
        if self.views < 2 {
            return Err(invalid("views", "at least 2", self.views));
        }
        if self.render_steps == 0 {
            return Err(invalid("render_steps", "at least 1", self.render_steps));
        }
        if self.supersample == 0 {
            return Err(invalid("supersample", "at least 1", 0));
        }
        if self.held_out_supersample == 0 {
            return Err(invalid("held_out_supersample", "at least 1", 0));
        }
        Ok(())
    }
}

impl Default for SyntheticEventsConfig {
    /// Half the DAVIS346 resolution, 173 × 130 with a 50° horizontal field of view; the default
    /// [`Turntable`]; 360 render steps (1° each); 100 views; 4 held-out views; EventNeRF's
    /// synthetic threshold 0.25 and `ε = 0.1`.
    fn default() -> Self {
        Self {
            turntable: Turntable::default(),
            camera: PinholeCamera::from_fov_x(173, 130, 50f64.to_radians()),
            render_steps: 360,
            supersample: 1,
            views: 100,
            held_out_views: 4,
            held_out_supersample: 2,
            simulator: SimulatorConfig::default(),
        }
    }
}

/// Simulates the dataset of `config` around `scene` (see [`SyntheticEventsConfig`]): events of
/// one revolution with time origin at view 0, the views' poses and times, and the held-out
/// views with their renders. Also returns how many events the refractory period dropped.
pub fn simulate_eventnerf_scene(
    scene: &SyntheticScene,
    config: &SyntheticEventsConfig,
) -> Result<(EventNerfScene, usize), EventsError> {
    config.validate()?;
    let tt = &config.turntable;
    let duration = tt.duration_secs;
    let times = uniform_times(0.0, duration, config.render_steps);
    let sim = simulate_scene_events::<f64>(
        scene,
        &config.camera,
        tt,
        &times,
        config.supersample,
        &config.simulator,
    )?;
    let k = config.views;
    let view_secs = uniform_times(0.0, duration, k - 1);
    let held_out = (0..config.held_out_views)
        .map(|j| {
            let t = (j as f64 + 0.5) * duration / config.held_out_views as f64;
            let pose = tt.world_from_camera(t);
            HeldOutView {
                name: format!("r_{j:05}"),
                time: Some(Timestamp::from_secs_f64(t)),
                world_from_camera: pose,
                image: scene
                    .render(&config.camera, &pose, config.held_out_supersample)
                    .image,
            }
        })
        .collect();
    let dataset = EventNerfScene {
        events: sim.events,
        view_names: (0..k).map(|i| format!("r_{i:05}")).collect(),
        world_from_camera: view_secs.iter().map(|&t| tt.world_from_camera(t)).collect(),
        view_times: view_secs
            .iter()
            .map(|&t| Timestamp::from_secs_f64(t))
            .collect(),
        camera: config.camera,
        distortion: [0.0; 2],
        held_out,
    };
    Ok((dataset, sim.dropped_refractory))
}

/// [`simulate_eventnerf_scene`], then [`write_eventnerf`] into `scene_dir` (whose `train/` and
/// `validation/` must be new or empty). Returns what was written and the number of events the
/// refractory period dropped.
pub fn write_synthetic_eventnerf(
    scene_dir: &Path,
    scene: &SyntheticScene,
    config: &SyntheticEventsConfig,
) -> Result<(EventNerfScene, usize), EventsError> {
    let out = simulate_eventnerf_scene(scene, config)?;
    write_eventnerf(scene_dir, &out.0)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpose_core::{ParamKind, PoseFieldError, TimeRange};
    use nalgebra::Isometry3;

    use crate::eventnerf::{EventNerfOptions, read_eventnerf};

    fn ts(secs: f64) -> Timestamp {
        Timestamp::from_secs_f64(secs)
    }

    /// A camera that does not move.
    struct Fixed(Isometry3<f64>);

    impl PoseField<f64> for Fixed {
        fn time_range(&self) -> TimeRange {
            TimeRange::new(0.0, 10.0).unwrap()
        }
        fn num_params(&self) -> usize {
            0
        }
        fn params(&self, _: &mut dyn FnMut(ParamKind, &[f64])) {}
        fn params_mut(&mut self, _: &mut dyn FnMut(ParamKind, &mut [f64])) {}
        fn evaluate(
            &self,
            t: &[f64],
            order: Order,
            out: &mut PoseBatch,
        ) -> Result<(), PoseFieldError> {
            out.reset(t.len(), order);
            for i in 0..t.len() {
                out.rotation[i] = *self.0.rotation.quaternion();
                out.translation[i] = self.0.translation.vector;
            }
            Ok(())
        }
        fn backward(
            &mut self,
            _: &[f64],
            _: &PoseBatch,
            _: &mut [f64],
        ) -> Result<(), PoseFieldError> {
            Ok(())
        }
    }

    /// A small sensor: the default camera at a quarter of its resolution (43 × 32).
    fn small_camera() -> PinholeCamera {
        SyntheticEventsConfig::default().camera.scaled(0.25)
    }

    #[test]
    fn a_static_camera_gives_no_events() {
        let scene = SyntheticScene::object_centric();
        let field = Fixed(Turntable::default().world_from_camera(1.0));
        let times = uniform_times(0.0, 10.0, 20);
        let out = simulate_scene_events(
            &scene,
            &small_camera(),
            &field,
            &times,
            1,
            &SimulatorConfig::default(),
        )
        .unwrap();
        assert!(out.events.is_empty());
        assert_eq!(out.dropped_refractory, 0);
    }

    #[test]
    fn a_brightness_ramp_fires_one_event_per_threshold_at_interpolated_times() {
        // One pixel of a 2 × 1 sensor: L rises by 1.0 over [1 s, 2 s], stays, then falls by 0.6
        // over [3 s, 4 s]; the other pixel is constant.
        let config = SimulatorConfig::default(); // θ = 0.25
        let mut sim = EventSimulator::new(2, 1, &config, ts(1.0), &[0.0, 0.0]).unwrap();
        sim.advance(ts(2.0), &[1.0, 0.0]).unwrap();
        sim.advance(ts(3.0), &[1.0, 0.0]).unwrap();
        sim.advance(ts(4.0), &[0.4, 0.0]).unwrap();
        let out = sim.finish().unwrap();
        let times: Vec<i64> = out.events.t_ns().to_vec();
        // Up: levels 0.25, 0.5, 0.75, 1.0 at 1.25, 1.5, 1.75, 2.0 s. Down from the reference
        // 1.0: levels 0.75, 0.5 at 3 + 0.25/0.6 and 3 + 0.5/0.6 s; 0.4 stays above 0.25.
        let expected = [1.25, 1.5, 1.75, 2.0, 3.0 + 0.25 / 0.6, 3.0 + 0.5 / 0.6]
            .map(|s: f64| (s * 1e9).round() as i64);
        assert_eq!(times, expected);
        assert_eq!(out.events.p(), [1, 1, 1, 1, -1, -1]);
        assert!(out.events.x().iter().all(|&x| x == 0));

        // A jump of 2.6 thresholds in one step: two events, spread over the step.
        let mut sim = EventSimulator::new(1, 1, &config, ts(0.0), &[0.0]).unwrap();
        sim.advance(ts(1.0), &[-0.65]).unwrap();
        let out = sim.finish().unwrap();
        let expected = [0.25 / 0.65, 0.5 / 0.65].map(|s: f64| (s * 1e9).round() as i64);
        assert_eq!(out.events.t_ns(), expected);
        assert_eq!(out.events.p(), [-1, -1]);
    }

    #[test]
    fn the_refractory_period_drops_events_but_moves_the_reference() {
        let config = SimulatorConfig {
            refractory_secs: 0.3,
            ..Default::default()
        };
        let mut sim = EventSimulator::new(1, 1, &config, ts(0.0), &[0.0]).unwrap();
        sim.advance(ts(1.0), &[1.0]).unwrap(); // crossings at 0.25, 0.5, 0.75, 1.0 s
        sim.advance(ts(2.0), &[1.0]).unwrap(); // no change: nothing, the reference is at 1.0
        let out = sim.finish().unwrap();
        assert_eq!(out.events.t_ns(), [250_000_000, 750_000_000]);
        assert_eq!(out.dropped_refractory, 2);
    }

    #[test]
    fn bayer_channels_are_rggb() {
        assert_eq!(bayer_channel(0, 0), 0); // R at (even row, even column)
        assert_eq!(bayer_channel(1, 0), 1); // G
        assert_eq!(bayer_channel(0, 1), 1); // G
        assert_eq!(bayer_channel(1, 1), 2); // B at (odd row, odd column)
        assert_eq!(bayer_channel(4, 2), 0);
        assert_eq!(bayer_channel(5, 3), 2);
        // Each pixel of the mosaic takes its channel of the image: R 0.8, G 0.5, B 0.2.
        let image = Image::from_fn(3, 2, |_, _| [0.8, 0.5, 0.2]);
        let log = mosaic_log_intensity(&image, 0.1);
        let l = |v: f64| (v.powf(2.2) + 0.1).ln();
        let expected = [l(0.8), l(0.5), l(0.8), l(0.5), l(0.2), l(0.5)];
        for (a, b) in log.iter().zip(expected) {
            assert!((a - b).abs() < 1e-6, "{log:?}");
        }
        assert_eq!(log_intensity(-1.0, 0.1), 0.1f64.ln());
        assert_eq!(log_intensity(f64::NAN, 0.1), 0.1f64.ln());
    }

    /// Events of a quarter revolution on the small sensor.
    fn quarter_turn(config: &SimulatorConfig) -> SimulatedEvents {
        let scene = SyntheticScene::object_centric();
        let tt = Turntable::default();
        let times = uniform_times(0.0, 0.25 * tt.duration_secs, 45);
        simulate_scene_events::<f64>(&scene, &small_camera(), &tt, &times, 1, config).unwrap()
    }

    #[test]
    fn event_counts_scale_inversely_with_the_threshold() {
        let coarse = quarter_turn(&SimulatorConfig {
            threshold: 0.4,
            ..Default::default()
        });
        let fine = quarter_turn(&SimulatorConfig {
            threshold: 0.2,
            ..Default::default()
        });
        let ratio = fine.events.len() as f64 / coarse.events.len() as f64;
        assert!(coarse.events.len() > 1000, "{}", coarse.events.len());
        // Ideal 2 for large changes. Each change rounds down a fraction of a threshold, which
        // lowers the ratio; changes between θ and 2θ fire at the fine threshold only, which
        // raises it (observed: 2.42 with 45 steps on 43 × 32 pixels).
        assert!((1.7..2.8).contains(&ratio), "ratio {ratio}");
        // Both polarities, every Bayer channel, all inside the quarter turn.
        let s = &fine.events;
        assert!(s.p().contains(&1) && s.p().contains(&-1));
        for c in 0..3 {
            assert!(
                (0..s.len())
                    .any(|i| bayer_channel(usize::from(s.x()[i]), usize::from(s.y()[i])) == c)
            );
        }
        let (first, last) = s.time_span().unwrap();
        assert!(first.as_nanos() > 0 && last.as_nanos() <= 2_500_000_000);
    }

    #[test]
    fn threshold_noise_is_deterministic_given_the_seed() {
        let noisy = |seed| SimulatorConfig {
            threshold_sigma: 0.03,
            seed,
            ..Default::default()
        };
        let a = quarter_turn(&noisy(1));
        assert_eq!(a, quarter_turn(&noisy(1)));
        assert_ne!(a.events, quarter_turn(&noisy(2)).events);
        let sim = EventSimulator::new(100, 100, &noisy(3), ts(0.0), &[0.0; 10_000]).unwrap();
        let th = sim.thresholds();
        let mean = th.iter().sum::<f64>() / th.len() as f64;
        let sd = (th.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / th.len() as f64).sqrt();
        assert!(
            (mean - 0.25).abs() < 0.002 && (sd - 0.03).abs() < 0.002,
            "{mean} {sd}"
        );
        assert!(th.iter().all(|&t| t >= MIN_THRESHOLD_FRACTION * 0.25));
    }

    #[test]
    fn bad_simulator_input_is_an_error() {
        let config = SimulatorConfig::default();
        assert!(EventSimulator::new(2, 2, &config, ts(0.0), &[0.0; 3]).is_err());
        let bad = SimulatorConfig {
            threshold: 0.0,
            ..Default::default()
        };
        let err = EventSimulator::new(1, 1, &bad, ts(0.0), &[0.0]).unwrap_err();
        assert!(
            err.to_string().starts_with("simulator.threshold: expected"),
            "{err}"
        );
        let mut sim = EventSimulator::new(1, 1, &config, ts(1.0), &[0.0]).unwrap();
        assert!(sim.advance(ts(1.0), &[0.0]).is_err());
        assert!(sim.advance(ts(2.0), &[0.0, 1.0]).is_err());
    }

    #[test]
    fn a_synthetic_dataset_is_written_and_read_back() {
        let dir = cpose_core::testing::TempDir::new("sim-dataset");
        let config = SyntheticEventsConfig {
            camera: small_camera(),
            render_steps: 60,
            views: 11,
            held_out_views: 2,
            ..Default::default()
        };
        let scene = SyntheticScene::object_centric();
        let (written, _) = write_synthetic_eventnerf(&dir, &scene, &config).unwrap();
        assert!(written.events.len() > 1000);
        let (read, report) = read_eventnerf(&dir, &EventNerfOptions::default()).unwrap();
        assert_eq!(report.dropped_out_of_bounds, 0);
        assert_eq!(read.events, written.events);
        assert_eq!(read.camera, config.camera);
        assert_eq!(read.view_times, written.view_times);
        assert_eq!(read.view_times[10], Timestamp::from_nanos(10_000_000_000));
        for (a, b) in read
            .world_from_camera
            .iter()
            .zip(&written.world_from_camera)
        {
            assert!((a.to_homogeneous() - b.to_homogeneous()).amax() < 1e-12);
        }
        // View K − 1 closes the revolution.
        let first = read.world_from_camera[0].to_homogeneous();
        assert!((read.world_from_camera[10].to_homogeneous() - first).amax() < 1e-9);
        assert_eq!(read.held_out.len(), 2);
        assert_eq!(
            read.held_out[1].time,
            Some(Timestamp::from_nanos(7_500_000_000))
        );
        let (w, h) = (
            read.held_out[0].image.width(),
            read.held_out[0].image.height(),
        );
        assert_eq!((w, h), (config.camera.width, config.camera.height));
    }
}
