//! Plots as PNG files that read without the source: every figure has a title, axis labels with
//! units and one legend that names each line and covers no data.
//!
//! - [`trajectories`]: evo_traj's layout, a top view (x–y, equal aspect) beside x, y, z and
//!   roll, pitch, yaw over time;
//! - [`trajectory_comparison`]: one estimate against the truth and the initial poses, in the
//!   layout of [`trajectories`];
//! - [`errors_over_time`]: e.g. position error per method over time;
//! - [`stacked_line_charts`]: panels with their own y axes above one another, e.g. rotation and
//!   position errors over time;
//! - [`curves_csv`] / [`curves`]: training curves from `curves.csv`, one panel per metric;
//! - [`line_chart`]: the general one-panel chart, which [`errors_over_time`] draws with;
//! - [`image_panels`]: pictures side by side with pixel axes and outlines drawn over them.
//!
//! Figures are drawn with `plotters` into memory, encoded as PNG and written atomically
//! ([`crate::fs::write_atomic`]). Text is DejaVu Sans (the `dejavu` crate; Bitstream Vera
//! licence) rasterised by `ab_glyph`, so no system font is needed.
//!
//! Colours follow [`SeriesStyle`]: ground truth black, initial poses grey and dashed, references
//! light grey, estimates in matplotlib's `tab10` order, so `Estimate(i)` has the same colour in
//! every figure.

use std::collections::HashMap;
use std::f64::consts::TAU;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nalgebra::Isometry3;
use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::prelude::*;
use plotters::style::{FontError, FontStyle, register_font, text_anchor};

use crate::geometry::euler_zyx_from_rotation;

/// Size of a [`trajectories`] figure in pixels (width, height).
pub const TRAJECTORIES_SIZE: (u32, u32) = (1600, 900);
/// Size of a [`line_chart`] or [`errors_over_time`] figure in pixels (width, height).
pub const LINE_CHART_SIZE: (u32, u32) = (1200, 700);
/// Size of one metric's panel in a [`curves`] figure in pixels (width, height); the figure is
/// a grid of these (two columns when there are two or more metrics) plus title and legend.
pub const CURVES_PANEL_SIZE: (u32, u32) = (800, 500);
/// The header `curves.csv` starts with (see [`crate::study`]).
pub const CURVES_HEADER: &str = "condition,method,seed,step,wall_s,metric,value";

/// Font family name the DejaVu faces are registered under (plotters' default family).
const FONT: &str = "sans-serif";
const TITLE_PX: f64 = 30.0;
const AXIS_LABEL_PX: f64 = 19.0;
const TICK_LABEL_PX: f64 = 16.0;
const LEGEND_PX: f64 = 19.0;
const PANEL_TITLE_PX: f64 = 19.0;
const TITLE_HEIGHT: u32 = 56;
/// Height of the title strip above a picture of [`image_panels`].
const IMAGE_TITLE_HEIGHT: u32 = 32;
/// Height of one row of the legend.
const LEGEND_ROW_HEIGHT: u32 = 30;
/// Length of the line sample in front of a legend label.
const LEGEND_SAMPLE: i32 = 40;
/// Space between legend entries.
const LEGEND_GAP: i32 = 36;
const LINE_WIDTH: u32 = 2;
/// Dash and gap length of dashed lines (initial poses).
const DASH: u32 = 8;
/// Space kept around a panel's plotting area.
const PANEL_MARGIN: u32 = 12;
/// Below the plotting area: tick labels and the x axis label.
const X_LABEL_AREA: u32 = 52;
/// Left of the plotting area: tick labels and the rotated y axis label.
const Y_LABEL_AREA: u32 = 72;
/// Fraction of the data's span added on each side of an axis.
const PAD_FRACTION: f64 = 0.05;
/// A y axis is logarithmic (in [`curves`]) when all values are positive and the largest is at
/// least this many times the smallest.
const LOG_SCALE_MIN_RATIO: f64 = 100.0;
/// Decades a logarithmic axis spans at most (below the padding); smaller values, such as the
/// rounding noise of an error that is zero, are drawn on its bottom edge.
const LOG_SCALE_MAX_DECADES: f64 = 6.0;

/// matplotlib's `tab10` without its grey (grey is for initial poses): the colours of
/// [`SeriesStyle::Estimate`] in order, repeating after nine.
const ESTIMATE_COLOURS: [RGBColor; 9] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];
const TRUTH_COLOUR: RGBColor = RGBColor(0, 0, 0);
const INITIAL_COLOUR: RGBColor = RGBColor(140, 140, 140);
const REFERENCE_COLOUR: RGBColor = RGBColor(165, 165, 165);

/// Errors of this module; each names the PNG it was drawing.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// There was nothing to draw, or a series had no points.
    #[error("nothing to plot in {}: {what}", .path.display())]
    Empty {
        /// The figure.
        path: PathBuf,
        /// What was empty ("no series", "series \"spline\" has no points").
        what: String,
    },
    /// A series has different numbers of times (or x values) and poses (or y values).
    #[error("series {label:?} has {xs} {x_name} but {ys} {y_name}, in {}", .path.display())]
    LengthMismatch {
        /// The figure.
        path: PathBuf,
        /// The series' label.
        label: String,
        /// What `xs` counts: "times" or "x values".
        x_name: &'static str,
        /// Number of times or x values.
        xs: usize,
        /// What `ys` counts: "poses" or "y values".
        y_name: &'static str,
        /// Number of poses or y values.
        ys: usize,
    },
    /// A line of `curves.csv` text could not be read.
    #[error("curves CSV line {line}: {message}")]
    Csv {
        /// 1-based line number in the text.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// plotters failed to draw (or the font could not be loaded).
    #[error("drawing {}: {message}", .path.display())]
    Draw {
        /// The figure.
        path: PathBuf,
        /// plotters' message.
        message: String,
    },
    /// The PNG could not be encoded or written.
    #[error("writing {}: {message}", .path.display())]
    Write {
        /// The figure.
        path: PathBuf,
        /// The encoder's or the file system's message.
        message: String,
    },
}

/// How a series is drawn, so the same role looks the same in every figure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeriesStyle {
    /// Ground truth: black, solid, drawn first.
    Truth,
    /// Initial poses (before optimisation): grey, dashed.
    Initial,
    /// A reference the estimates are compared with, such as interpolation of the known poses:
    /// light grey, solid (a dashed line is unreadable when it wiggles fast).
    Reference,
    /// The `i`-th estimate: the `i`-th colour of matplotlib's `tab10` (grey skipped), solid.
    Estimate(usize),
}

impl SeriesStyle {
    fn colour(self) -> RGBColor {
        match self {
            Self::Truth => TRUTH_COLOUR,
            Self::Initial => INITIAL_COLOUR,
            Self::Reference => REFERENCE_COLOUR,
            Self::Estimate(i) => ESTIMATE_COLOURS[i % ESTIMATE_COLOURS.len()],
        }
    }

    fn dashed(self) -> bool {
        self == Self::Initial
    }

    /// Drawing order: truth at the bottom, estimates on top.
    fn layer(self) -> usize {
        match self {
            Self::Truth => 0,
            Self::Initial | Self::Reference => 1,
            Self::Estimate(_) => 2,
        }
    }
}

/// One trajectory of a [`trajectories`] figure.
#[derive(Clone, Debug)]
pub struct TrajectorySeries {
    /// Legend text, e.g. `"ground truth"`, `"PoseNet"`.
    pub label: String,
    /// Time of each pose, seconds since the sequence origin.
    pub times_secs: Vec<f64>,
    /// `world_from_body` at each time.
    pub poses: Vec<Isometry3<f64>>,
    /// Colour and dashing.
    pub style: SeriesStyle,
}

/// One line of a [`line_chart`].
#[derive(Clone, Debug)]
pub struct Line {
    /// Legend text.
    pub label: String,
    /// Abscissae (for [`errors_over_time`]: seconds since the sequence origin).
    pub x: Vec<f64>,
    /// Values, one per abscissa; non-finite values leave a gap.
    pub y: Vec<f64>,
    /// Colour and dashing.
    pub style: SeriesStyle,
}

/// Scale of a y axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum YScale {
    /// Linear, fitted to the data.
    Linear,
    /// Linear from 0 (for errors and other non-negative quantities); as [`YScale::Linear`]
    /// when a value is negative.
    LinearFromZero,
    /// Base-10 logarithmic, over at most six decades below the largest value: values `≤ 0` are
    /// left out, positive values below the axis lie on its bottom edge.
    Log,
}

/// One row of `curves.csv`: a value of `metric` reported at `step` by one study unit.
#[derive(Clone, Debug, PartialEq)]
pub struct CurveRow {
    /// The unit's condition, e.g. `noise-20deg`.
    pub condition: String,
    /// The unit's method, e.g. `posenet`.
    pub method: String,
    /// The unit's seed.
    pub seed: u64,
    /// Optimisation step.
    pub step: u64,
    /// Wall-clock seconds since the unit started.
    pub wall_s: f64,
    /// Name of the metric, e.g. `loss`, `rot_err_deg`.
    pub metric: String,
    /// Its value.
    pub value: f64,
}

/// Draws trajectories as evo_traj does, into a [`TRAJECTORIES_SIZE`] PNG at `path`: on the left
/// the top view (x against y in metres, equal aspect), on the right x, y, z (m) and roll, pitch,
/// yaw (°) against time (s), under `title` and above one legend naming every series.
///
/// Roll, pitch and yaw are the Z-Y-X Euler angles of `world_from_body`
/// (`R = Rz(yaw)·Ry(pitch)·Rx(roll)`, [`euler_zyx_from_rotation`]), unwrapped over time so a
/// turn through ±180° stays continuous; each series is then shifted by whole turns to start
/// within 180° of the ground truth (or, without one, of the first series).
pub fn trajectories(
    path: impl AsRef<Path>,
    title: &str,
    series: &[TrajectorySeries],
) -> Result<(), PlotError> {
    let path = path.as_ref();
    if series.is_empty() {
        return Err(empty(path, "no series"));
    }
    for s in series {
        let counts = [("times", s.times_secs.len()), ("poses", s.poses.len())];
        check_lengths(path, &s.label, counts)?;
    }
    let mut order: Vec<&TrajectorySeries> = series.iter().collect();
    order.sort_by_key(|s| s.style.layer());

    // Components over time: x, y, z in metres, then roll, pitch, yaw in degrees.
    let components: Vec<[Vec<f64>; 6]> = order.iter().map(|s| pose_components(s)).collect();
    let reference_start: Vec<Option<f64>> = (3..6)
        .map(|c| components[0][c].iter().copied().find(|a| a.is_finite()))
        .collect();
    let components: Vec<[Vec<f64>; 6]> = components
        .into_iter()
        .map(|mut parts| {
            for (c, start) in (3..6).zip(&reference_start) {
                if let Some(start) = start {
                    shift_by_turns_towards(&mut parts[c], *start);
                }
            }
            parts
        })
        .collect();

    let legend: Vec<(&str, SeriesStyle)> =
        series.iter().map(|s| (s.label.as_str(), s.style)).collect();
    let legend_rows = legend_layout(path, &legend, TRAJECTORIES_SIZE.0)?;
    render_png(path, TRAJECTORIES_SIZE, |root| {
        let body = draw_frame(root, title, &legend, &legend_rows)?;
        let (body_width, body_height) = body.dim_in_pixel();
        let top_view_width = body_height.min(body_width * 9 / 20);
        let (left, right) = body.split_horizontally(top_view_width);

        let top_view: Vec<Trace> = order
            .iter()
            .zip(&components)
            .map(|(s, parts)| Trace::new(&parts[0], &parts[1], s.style))
            .collect();
        draw_top_view(&left, &top_view)?;

        const NAMES: [&str; 6] = [
            "x (m)",
            "y (m)",
            "z (m)",
            "roll (°)",
            "pitch (°)",
            "yaw (°)",
        ];
        // 3 × 2 grid, filled by columns: positions left, angles right.
        let cells = right.split_evenly((3, 2));
        for (c, name) in NAMES.iter().enumerate() {
            let traces: Vec<Trace> = order
                .iter()
                .zip(&components)
                .map(|(s, parts)| Trace::new(&s.times_secs, &parts[c], s.style))
                .collect();
            let cell = &cells[(c % 3) * 2 + c / 3];
            draw_panel(cell, None, "time (s)", name, YScale::Linear, &traces)?;
        }
        Ok(())
    })
}

/// Draws errors against time, one line per method, into a [`LINE_CHART_SIZE`] PNG at `path`:
/// [`line_chart`] with the x axis "time (s)" and the y axis from 0. `y_label` names the error
/// and its unit, e.g. `"position error (cm)"`; each line's `x` is in seconds since the
/// sequence origin.
pub fn errors_over_time(
    path: impl AsRef<Path>,
    title: &str,
    y_label: &str,
    lines: &[Line],
) -> Result<(), PlotError> {
    line_chart(
        path,
        title,
        "time (s)",
        y_label,
        YScale::LinearFromZero,
        lines,
    )
}

/// Draws `lines` in one panel into a [`LINE_CHART_SIZE`] PNG at `path`, with `title` above,
/// the axis labels `x_label` and `y_label` (which should carry units) and a legend between the
/// title and the panel.
pub fn line_chart(
    path: impl AsRef<Path>,
    title: &str,
    x_label: &str,
    y_label: &str,
    y_scale: YScale,
    lines: &[Line],
) -> Result<(), PlotError> {
    let path = path.as_ref();
    if lines.is_empty() {
        return Err(empty(path, "no series"));
    }
    for line in lines {
        let counts = [("x values", line.x.len()), ("y values", line.y.len())];
        check_lengths(path, &line.label, counts)?;
    }
    let mut order: Vec<&Line> = lines.iter().collect();
    order.sort_by_key(|l| l.style.layer());
    let legend: Vec<(&str, SeriesStyle)> =
        lines.iter().map(|l| (l.label.as_str(), l.style)).collect();
    let legend_rows = legend_layout(path, &legend, LINE_CHART_SIZE.0)?;
    render_png(path, LINE_CHART_SIZE, |root| {
        let body = draw_frame(root, title, &legend, &legend_rows)?;
        let traces: Vec<Trace> = order
            .iter()
            .map(|l| Trace::new(&l.x, &l.y, l.style))
            .collect();
        draw_panel(&body, None, x_label, y_label, y_scale, &traces)
    })
}

/// Draws one trajectory estimate against the ground truth and the initial poses with
/// [`trajectories`] (so in evo_traj's layout, into a [`TRAJECTORIES_SIZE`] PNG at `path`): every
/// series is sampled at `times_secs`, in seconds from any origin (the time axes start at the
/// first time, as evo's do); the truth is black and labelled "ground truth", `initial` grey and
/// dashed, the estimate in the first estimate colour, each of these two under its own label.
/// `None` or an empty slice leaves a series out; a series given must have one pose per time.
///
/// The one call of the tasks that compare a single estimate with the truth:
///
/// ```no_run
/// # use nalgebra::Isometry3;
/// # use cpose_core::plot::trajectory_comparison;
/// # fn f(times: &[f64], truth: &[Isometry3<f64>], aligned: &[Isometry3<f64>]) -> Result<(), cpose_core::plot::PlotError> {
/// trajectory_comparison(
///     "trajectory_posenet.png",
///     "slam room0: PoseNet camera path (SE(3)-aligned to the truth)",
///     times,
///     Some(truth),
///     None,
///     ("PoseNet (aligned)", aligned),
/// )
/// # }
/// ```
pub fn trajectory_comparison(
    path: impl AsRef<Path>,
    title: &str,
    times_secs: &[f64],
    truth: Option<&[Isometry3<f64>]>,
    initial: Option<(&str, &[Isometry3<f64>])>,
    estimate: (&str, &[Isometry3<f64>]),
) -> Result<(), PlotError> {
    let origin = times_secs
        .iter()
        .copied()
        .find(|t| t.is_finite())
        .unwrap_or(0.0);
    let times: Vec<f64> = times_secs.iter().map(|t| t - origin).collect();
    let mut series = Vec::new();
    let mut add = |label: &str, poses: &[Isometry3<f64>], style| {
        series.push(TrajectorySeries {
            label: label.to_owned(),
            times_secs: times.clone(),
            poses: poses.to_vec(),
            style,
        });
    };
    if let Some(truth) = truth.filter(|p| !p.is_empty()) {
        add("ground truth", truth, SeriesStyle::Truth);
    }
    if let Some((label, initial)) = initial.filter(|(_, p)| !p.is_empty()) {
        add(label, initial, SeriesStyle::Initial);
    }
    add(estimate.0, estimate.1, SeriesStyle::Estimate(0));
    trajectories(path, title, &series)
}

/// One panel of a [`stacked_line_charts`] figure: its y axis and its lines.
#[derive(Clone, Debug)]
pub struct Panel {
    /// The y axis label, with the unit, e.g. `"rotation error (°)"`.
    pub y_label: String,
    /// The y axis scale.
    pub y_scale: YScale,
    /// The lines; a label and style shared with another panel's line is one legend entry.
    pub lines: Vec<Line>,
}

/// Size of one panel of a [`stacked_line_charts`] figure in pixels (width, height); the figure
/// is a column of these plus title and legend.
pub const STACKED_PANEL_SIZE: (u32, u32) = (1200, 420);

/// Draws `panels` one above the other into a PNG at `path`, each with its own y axis and all
/// with the x axis `x_label`, under `title` and one legend naming every line (in order of first
/// appearance; lines of the same label and style in several panels share an entry).
pub fn stacked_line_charts(
    path: impl AsRef<Path>,
    title: &str,
    x_label: &str,
    panels: &[Panel],
) -> Result<(), PlotError> {
    let path = path.as_ref();
    if panels.is_empty() {
        return Err(empty(path, "no panels"));
    }
    let mut legend: Vec<(&str, SeriesStyle)> = Vec::new();
    for panel in panels {
        if panel.lines.is_empty() {
            let what = format!("panel {:?} has no lines", panel.y_label);
            return Err(empty(path, what));
        }
        for line in &panel.lines {
            let counts = [("x values", line.x.len()), ("y values", line.y.len())];
            check_lengths(path, &line.label, counts)?;
            let entry = (line.label.as_str(), line.style);
            if !legend.contains(&entry) {
                legend.push(entry);
            }
        }
    }
    let width = STACKED_PANEL_SIZE.0;
    let legend_rows = legend_layout(path, &legend, width)?;
    let height = panels.len() as u32 * STACKED_PANEL_SIZE.1 + frame_height(legend_rows.len());
    render_png(path, (width, height), |root| {
        let body = draw_frame(root, title, &legend, &legend_rows)?;
        let cells = body.split_evenly((panels.len(), 1));
        for (panel, cell) in panels.iter().zip(&cells) {
            let mut order: Vec<&Line> = panel.lines.iter().collect();
            order.sort_by_key(|l| l.style.layer());
            let traces: Vec<Trace> = order
                .iter()
                .map(|l| Trace::new(&l.x, &l.y, l.style))
                .collect();
            draw_panel(cell, None, x_label, &panel.y_label, panel.y_scale, &traces)?;
        }
        Ok(())
    })
}

/// About the long side, in pixels, of a picture in an [`image_panels`] figure: larger pictures
/// are shrunk to it, smaller ones enlarged by the whole factor nearest to reaching it.
pub const IMAGE_PANEL_LONG_SIDE: u32 = 640;

/// One picture of an [`image_panels`] figure and the outlines drawn over it.
#[derive(Clone, Copy, Debug)]
pub struct ImagePanel<'a> {
    /// The text above the picture, e.g. `"neural image"`.
    pub title: &'a str,
    /// Width and height in pixels.
    pub size: (usize, usize),
    /// RGB values in `[0, 1]` (clamped; NaN is black), three per pixel, rows from the top.
    pub rgb: &'a [f32],
    /// Width and height the picture spans on its axes, "x (px)" and "y (px)": `size` for this
    /// picture's pixels, or the original size when the picture is a downscaled copy.
    pub extent: (f64, f64),
    /// Drawn over the picture.
    pub outlines: &'a [Outline],
}

/// Closed polygons drawn over an [`ImagePanel`]: one legend entry. Over pictures, lines have a
/// white border, and [`SeriesStyle::Truth`] is drawn wider than the others so an estimate on top
/// of it leaves it visible.
#[derive(Clone, Debug)]
pub struct Outline {
    /// Legend text, e.g. `"true patch outlines"`.
    pub label: String,
    /// Colour and dashing.
    pub style: SeriesStyle,
    /// Corners of each polygon in the picture's axis units (x right, y down from the top-left
    /// corner of the picture); the last corner joins the first.
    pub polygons: Vec<Vec<(f64, f64)>>,
}

/// Draws pictures side by side into a PNG at `path`, each under its own title, with pixel axes
/// and the outlines over it, under `title` and one legend naming every outline (in order of
/// first appearance; outlines of the same label and style on several pictures share an entry).
/// Each picture is shown about [`IMAGE_PANEL_LONG_SIDE`] pixels long (small ones enlarged by
/// a whole factor, without smoothing).
pub fn image_panels(
    path: impl AsRef<Path>,
    title: &str,
    panels: &[ImagePanel],
) -> Result<(), PlotError> {
    let path = path.as_ref();
    if panels.is_empty() {
        return Err(empty(path, "no pictures"));
    }
    let mut legend: Vec<(&str, SeriesStyle)> = Vec::new();
    for panel in panels {
        let (w, h) = panel.size;
        if w == 0 || h == 0 {
            return Err(empty(
                path,
                format!("picture {:?} has no pixels", panel.title),
            ));
        }
        if panel.rgb.len() != 3 * w * h {
            return Err(PlotError::LengthMismatch {
                path: path.to_path_buf(),
                label: panel.title.to_owned(),
                x_name: "values for its size (3 per pixel)",
                xs: 3 * w * h,
                y_name: "RGB values",
                ys: panel.rgb.len(),
            });
        }
        for outline in panel.outlines {
            let entry = (outline.label.as_str(), outline.style);
            if !legend.contains(&entry) {
                legend.push(entry);
            }
        }
    }
    let shown: Vec<(u32, u32)> = panels.iter().map(|p| shown_size(p.size)).collect();
    let cells: Vec<(u32, u32)> = shown
        .iter()
        .map(|&(w, h)| {
            (
                w + 2 * PANEL_MARGIN + Y_LABEL_AREA,
                IMAGE_TITLE_HEIGHT + h + 2 * PANEL_MARGIN + X_LABEL_AREA,
            )
        })
        .collect();
    let cells_width: u32 = cells.iter().map(|c| c.0).sum();
    register_fonts().map_err(|message| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    })?;
    let title_width = title_font(TITLE_PX).box_size(title).map_or(0, |(w, _)| w);
    let width = cells_width.max(title_width + 2 * LEGEND_GAP as u32);
    let legend_rows = legend_layout(path, &legend, width)?;
    let cells_height = cells.iter().map(|c| c.1).max().unwrap_or(0);
    let height = frame_height(legend_rows.len()) + cells_height;
    render_png(path, (width, height), |root| {
        let body = draw_frame(root, title, &legend, &legend_rows)?;
        let mut x = ((width - cells_width) / 2) as i32;
        for ((panel, &size), &cell) in panels.iter().zip(&shown).zip(&cells) {
            draw_image_panel(&body.clone().shrink((x, 0), cell), panel, size)?;
            x += cell.0 as i32;
        }
        Ok(())
    })
}

/// Reads `curves.csv` text ([`parse_curves_csv`]) and draws it with [`curves`].
pub fn curves_csv(path: impl AsRef<Path>, title: &str, csv_text: &str) -> Result<(), PlotError> {
    curves(path, title, &parse_curves_csv(csv_text)?)
}

/// Draws training curves into a PNG at `path`: one panel per metric (in order of first
/// appearance), x axis "step", one line per (condition, method, seed) with the same colour in
/// every panel, and one legend naming the lines by the fields that differ between them. The
/// seeds of one (condition, method) share a colour and an entry ("posenet (3 seeds)") unless
/// there is only one (condition, method); colours repeat after nine entries.
///
/// A metric's y axis is logarithmic when all its values are positive and span at least a
/// factor of 100 (a loss, typically); a unit suffix of the metric name labels the axis
/// (`rot_err_deg` → "rot_err (°)"; `_cm`, `_mm`, `_m`, `_s`, `_db`, `_px` likewise).
pub fn curves(path: impl AsRef<Path>, title: &str, rows: &[CurveRow]) -> Result<(), PlotError> {
    let path = path.as_ref();
    if rows.is_empty() {
        return Err(empty(path, "no curve rows"));
    }
    let mut metrics: Vec<&str> = Vec::new();
    let mut units: Vec<(&str, &str, u64)> = Vec::new();
    for row in rows {
        if !metrics.contains(&row.metric.as_str()) {
            metrics.push(&row.metric);
        }
        let unit = (row.condition.as_str(), row.method.as_str(), row.seed);
        if !units.contains(&unit) {
            units.push(unit);
        }
    }
    let (labels, colour_of_unit) = unit_legend(&units);
    let legend: Vec<(&str, SeriesStyle)> = labels
        .iter()
        .enumerate()
        .map(|(i, l)| (l.as_str(), SeriesStyle::Estimate(i)))
        .collect();

    let columns = metrics.len().min(2) as u32;
    let panel_rows = metrics.len().div_ceil(2) as u32;
    let width = columns * CURVES_PANEL_SIZE.0;
    let legend_rows = legend_layout(path, &legend, width)?;
    let height = panel_rows * CURVES_PANEL_SIZE.1 + frame_height(legend_rows.len());

    // (metric, unit) → (step, value), sorted by step.
    let mut points: HashMap<(&str, usize), Vec<(f64, f64)>> = HashMap::new();
    for row in rows {
        let unit = units
            .iter()
            .position(|u| *u == (row.condition.as_str(), row.method.as_str(), row.seed))
            .expect("every row's unit was collected above");
        points
            .entry((row.metric.as_str(), unit))
            .or_default()
            .push((row.step as f64, row.value));
    }
    for line in points.values_mut() {
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
    }

    render_png(path, (width, height), |root| {
        let body = draw_frame(root, title, &legend, &legend_rows)?;
        let cells = body.split_evenly((panel_rows as usize, columns as usize));
        for (metric, cell) in metrics.iter().zip(&cells) {
            let unit_points: Vec<(Vec<f64>, Vec<f64>)> = (0..units.len())
                .map(|unit| {
                    points
                        .get(&(*metric, unit))
                        .map(|p| p.iter().copied().unzip())
                        .unwrap_or_default()
                })
                .collect();
            let traces: Vec<Trace> = unit_points
                .iter()
                .enumerate()
                .map(|(unit, (x, y))| Trace::new(x, y, SeriesStyle::Estimate(colour_of_unit[unit])))
                .collect();
            let values = unit_points.iter().flat_map(|(_, y)| y.iter().copied());
            let y_scale = if wants_log_scale(values) {
                YScale::Log
            } else {
                YScale::Linear
            };
            let y_label = metric_axis_label(metric, y_scale);
            draw_panel(cell, Some(metric), "step", &y_label, y_scale, &traces)?;
        }
        Ok(())
    })
}

/// Parses `curves.csv` text: the header [`CURVES_HEADER`], then rows of
/// `condition,method,seed,step,wall_s,metric,value`; blank lines are skipped. An error names
/// the 1-based line and what is wrong with it.
pub fn parse_curves_csv(text: &str) -> Result<Vec<CurveRow>, PlotError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim_end()));
    match lines.next() {
        Some((_, header)) if header == CURVES_HEADER => {}
        Some((line, header)) => {
            return Err(PlotError::Csv {
                line,
                message: format!("expected the header {CURVES_HEADER:?}, got {header:?}"),
            });
        }
        None => {
            return Err(PlotError::Csv {
                line: 1,
                message: "empty text, expected a header".into(),
            });
        }
    }
    let mut rows = Vec::new();
    for (line, text) in lines.filter(|(_, l)| !l.is_empty()) {
        let error = |message: String| PlotError::Csv { line, message };
        let fields: Vec<&str> = text.split(',').collect();
        let [condition, method, seed, step, wall_s, metric, value] = fields[..] else {
            return Err(error(format!(
                "expected 7 comma-separated fields, got {}: {text:?}",
                fields.len()
            )));
        };
        let number = |name: &str, field: &str| {
            field
                .parse::<f64>()
                .map_err(|_| error(format!("{name} {field:?} is not a number")))
        };
        let integer = |name: &str, field: &str| {
            field
                .parse::<u64>()
                .map_err(|_| error(format!("{name} {field:?} is not a non-negative integer")))
        };
        rows.push(CurveRow {
            condition: condition.to_string(),
            method: method.to_string(),
            seed: integer("seed", seed)?,
            step: integer("step", step)?,
            wall_s: number("wall_s", wall_s)?,
            metric: metric.to_string(),
            value: number("value", value)?,
        });
    }
    Ok(rows)
}

// ---------------------------------------------------------------------------------------------
// Data preparation
// ---------------------------------------------------------------------------------------------

/// x, y, z (m) and unwrapped roll, pitch, yaw (°) of each pose.
fn pose_components(series: &TrajectorySeries) -> [Vec<f64>; 6] {
    let mut parts: [Vec<f64>; 6] = Default::default();
    let mut angles: [Vec<f64>; 3] = Default::default();
    for pose in &series.poses {
        let t = &pose.translation.vector;
        for (c, part) in parts.iter_mut().take(3).enumerate() {
            part.push(t[c]);
        }
        let euler = euler_zyx_from_rotation(pose.rotation.to_rotation_matrix().matrix());
        for (angle, value) in angles.iter_mut().zip([euler.roll, euler.pitch, euler.yaw]) {
            angle.push(value);
        }
    }
    for (part, angle) in parts[3..].iter_mut().zip(angles) {
        *part = unwrap_angles(&angle)
            .iter()
            .map(|a| a.to_degrees())
            .collect();
    }
    parts
}

/// Adds whole turns (2π) to each angle (radians) so that consecutive finite angles differ by
/// at most π, as numpy's `unwrap`; the first finite angle is kept and non-finite ones pass
/// through.
fn unwrap_angles(angles: &[f64]) -> Vec<f64> {
    let mut previous: Option<f64> = None;
    let mut offset = 0.0;
    angles
        .iter()
        .map(|&angle| {
            if !angle.is_finite() {
                return angle;
            }
            if let Some(previous) = previous {
                offset -= TAU * ((angle - previous) / TAU).round();
            }
            previous = Some(angle);
            angle + offset
        })
        .collect()
}

/// Shifts unwrapped angles (degrees) by whole turns so the first finite one lies within 180°
/// of `start_deg`.
fn shift_by_turns_towards(angles_deg: &mut [f64], start_deg: f64) {
    let Some(first) = angles_deg.iter().copied().find(|a| a.is_finite()) else {
        return;
    };
    let turns = ((start_deg - first) / 360.0).round();
    for angle in angles_deg.iter_mut() {
        *angle += turns * 360.0;
    }
}

/// Whether a metric's values want a log axis: all finite values positive, spanning at least
/// [`LOG_SCALE_MIN_RATIO`].
fn wants_log_scale(values: impl Iterator<Item = f64>) -> bool {
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        if v <= 0.0 {
            return false;
        }
        min = min.min(v);
        max = max.max(v);
    }
    min.is_finite() && max >= LOG_SCALE_MIN_RATIO * min
}

/// `rot_err_deg` → "rot_err (°)", `loss` on a log axis → "loss (log scale)".
fn metric_axis_label(metric: &str, y_scale: YScale) -> String {
    const SUFFIXES: [(&str, &str); 9] = [
        ("_rad_s", "rad/s"),
        ("_deg", "°"),
        ("_cm", "cm"),
        ("_mm", "mm"),
        ("_m", "m"),
        ("_s", "s"),
        ("_db", "dB"),
        ("_px", "px"),
        ("_su", "scene units"),
    ];
    let (name, unit) = SUFFIXES
        .iter()
        .find_map(|(suffix, unit)| metric.strip_suffix(suffix).map(|name| (name, *unit)))
        .unwrap_or((metric, ""));
    match (unit, y_scale == YScale::Log) {
        ("", false) => name.to_string(),
        ("", true) => format!("{name} (log scale)"),
        (unit, false) => format!("{name} ({unit})"),
        (unit, true) => format!("{name} ({unit}, log scale)"),
    }
}

/// Legend entries of study units `(condition, method, seed)` and each unit's entry. Units of
/// one (condition, method) share an entry and a colour, labelled with the fields that differ
/// between entries and the number of seeds; with a single (condition, method), each seed has
/// its own.
fn unit_legend(units: &[(&str, &str, u64)]) -> (Vec<String>, Vec<usize>) {
    let mut groups: Vec<(&str, &str)> = Vec::new();
    for &(condition, method, _) in units {
        if !groups.contains(&(condition, method)) {
            groups.push((condition, method));
        }
    }
    if groups.len() == 1 {
        let labels = if units.len() == 1 {
            vec![units[0].1.to_string()]
        } else {
            units.iter().map(|u| format!("seed {}", u.2)).collect()
        };
        return (labels, (0..units.len()).collect());
    }
    let entry_of_unit: Vec<usize> = units
        .iter()
        .map(|&(condition, method, _)| {
            groups
                .iter()
                .position(|g| *g == (condition, method))
                .expect("every unit's group was collected above")
        })
        .collect();
    let condition_differs = groups.iter().any(|g| g.0 != groups[0].0);
    let method_differs = groups.iter().any(|g| g.1 != groups[0].1);
    let labels = groups
        .iter()
        .enumerate()
        .map(|(entry, (condition, method))| {
            let mut label = match (condition_differs, method_differs) {
                (true, true) => format!("{condition} / {method}"),
                (true, false) => condition.to_string(),
                _ => method.to_string(),
            };
            let seeds = entry_of_unit.iter().filter(|&&e| e == entry).count();
            if seeds > 1 {
                label += &format!(" ({seeds} seeds)");
            }
            label
        })
        .collect();
    (labels, entry_of_unit)
}

fn empty(path: &Path, what: impl Into<String>) -> PlotError {
    PlotError::Empty {
        path: path.to_path_buf(),
        what: what.into(),
    }
}

/// Checks that a series has as many x as y entries, and some.
fn check_lengths(
    path: &Path,
    label: &str,
    [(x_name, xs), (y_name, ys)]: [(&'static str, usize); 2],
) -> Result<(), PlotError> {
    if xs != ys {
        return Err(PlotError::LengthMismatch {
            path: path.to_path_buf(),
            label: label.to_string(),
            x_name,
            xs,
            y_name,
            ys,
        });
    }
    if xs == 0 {
        return Err(empty(path, format!("series {label:?} has no points")));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Drawing
// ---------------------------------------------------------------------------------------------

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type DrawResult<T = ()> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// One line to draw: its points (non-finite ones break it) and style.
struct Trace {
    points: Vec<(f64, f64)>,
    style: SeriesStyle,
}

impl Trace {
    fn new(x: &[f64], y: &[f64], style: SeriesStyle) -> Self {
        Self {
            points: x.iter().copied().zip(y.iter().copied()).collect(),
            style,
        }
    }

    /// Runs of consecutive points whose coordinates are finite (and, on a log axis, positive).
    fn segments(&self, log_y: bool) -> Vec<Vec<(f64, f64)>> {
        let mut segments = vec![Vec::new()];
        for &(x, y) in &self.points {
            if x.is_finite() && y.is_finite() && (!log_y || y > 0.0) {
                if let Some(last) = segments.last_mut() {
                    last.push((x, y));
                }
            } else if segments.last().is_some_and(|s| !s.is_empty()) {
                segments.push(Vec::new());
            }
        }
        segments.retain(|s| !s.is_empty());
        segments
    }
}

/// Registers DejaVu Sans (regular and bold) with plotters, once per process.
fn register_fonts() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            let failed = |face: &str| format!("cannot load DejaVu Sans {face}");
            register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
                .map_err(|_| failed("regular"))?;
            register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).map_err(|_| failed("bold"))
        })
        .clone()
}

/// Draws with `draw` on a white `size` canvas, encodes it as PNG and writes it to `path`.
fn render_png(
    path: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(&Area) -> DrawResult,
) -> Result<(), PlotError> {
    let draw_error = |message: String| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    };
    register_fonts().map_err(draw_error)?;
    let mut rgb = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        draw(&root)
            .and_then(|()| Ok(root.present()?))
            .map_err(|e| draw_error(e.to_string()))?;
    }
    let write_error = |message: String| PlotError::Write {
        path: path.to_path_buf(),
        message,
    };
    let image = image::RgbImage::from_raw(width, height, rgb)
        .expect("the buffer holds width · height RGB pixels");
    let mut png = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| write_error(e.to_string()))?;
    crate::fs::write_atomic(path, png.into_inner()).map_err(|e| write_error(e.to_string()))
}

fn font(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Normal)
}

fn title_font(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Bold)
}

/// Height taken by the title and a legend of `legend_rows` rows.
fn frame_height(legend_rows: usize) -> u32 {
    TITLE_HEIGHT + legend_rows as u32 * LEGEND_ROW_HEIGHT + PANEL_MARGIN
}

/// Splits legend entries into rows that fit `width` pixels, each row a list of entry indices.
fn legend_layout(
    path: &Path,
    entries: &[(&str, SeriesStyle)],
    width: u32,
) -> Result<Vec<Vec<usize>>, PlotError> {
    let draw_error = |message: String| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    };
    register_fonts().map_err(draw_error)?;
    let legend_font = font(LEGEND_PX);
    let mut rows: Vec<Vec<usize>> = Vec::new();
    let mut row_width = 0;
    let max_width = width as i32 - 2 * LEGEND_GAP;
    for (i, (label, _)) in entries.iter().enumerate() {
        let (text_width, _) = legend_font
            .box_size(label)
            .map_err(|e| draw_error(format!("measuring legend text {label:?}: {e}")))?;
        let entry_width = LEGEND_SAMPLE + 8 + text_width as i32;
        match rows.last_mut() {
            Some(row) if row_width + LEGEND_GAP + entry_width <= max_width => {
                row.push(i);
                row_width += LEGEND_GAP + entry_width;
            }
            _ => {
                rows.push(vec![i]);
                row_width = entry_width;
            }
        }
    }
    Ok(rows)
}

/// Draws the title and the legend rows (centred) at the top of `root` and returns the area
/// left below them.
fn draw_frame<'a>(
    root: &Area<'a>,
    title: &str,
    legend: &[(&str, SeriesStyle)],
    legend_rows: &[Vec<usize>],
) -> DrawResult<Area<'a>> {
    let (width, _) = root.dim_in_pixel();
    // A title too long for the figure is set smaller, down to the legend's size.
    let room = f64::from(width) - 2.0 * f64::from(PANEL_MARGIN);
    let title_width = f64::from(title_font(TITLE_PX).box_size(title)?.0);
    let title_px = if title_width > room {
        (TITLE_PX * room / title_width).max(LEGEND_PX)
    } else {
        TITLE_PX
    };
    let title_style = title_font(title_px)
        .color(&BLACK)
        .pos(text_anchor::Pos::new(
            text_anchor::HPos::Center,
            text_anchor::VPos::Center,
        ));
    root.draw_text(
        title,
        &title_style,
        (width as i32 / 2, TITLE_HEIGHT as i32 / 2),
    )?;
    let legend_font = font(LEGEND_PX);
    let label_style = legend_font.color(&BLACK).pos(text_anchor::Pos::new(
        text_anchor::HPos::Left,
        text_anchor::VPos::Center,
    ));
    for (r, row) in legend_rows.iter().enumerate() {
        let widths: Vec<i32> = row
            .iter()
            .map(|&i| {
                let (w, _) = legend_font.box_size(legend[i].0)?;
                Ok(LEGEND_SAMPLE + 8 + w as i32)
            })
            .collect::<Result<_, FontError>>()?;
        let row_width: i32 = widths.iter().sum::<i32>() + LEGEND_GAP * (row.len() as i32 - 1);
        let y = (TITLE_HEIGHT + r as u32 * LEGEND_ROW_HEIGHT + LEGEND_ROW_HEIGHT / 2) as i32;
        let mut x = (width as i32 - row_width) / 2;
        for (&i, entry_width) in row.iter().zip(&widths) {
            let (label, style) = legend[i];
            let colour = style.colour().stroke_width(LINE_WIDTH + 1);
            if style.dashed() {
                for start in (0..LEGEND_SAMPLE).step_by(2 * DASH as usize) {
                    let end = (start + DASH as i32).min(LEGEND_SAMPLE);
                    root.draw(&PathElement::new(
                        vec![(x + start, y), (x + end, y)],
                        colour,
                    ))?;
                }
            } else {
                root.draw(&PathElement::new(
                    vec![(x, y), (x + LEGEND_SAMPLE, y)],
                    colour,
                ))?;
            }
            root.draw_text(label, &label_style, (x + LEGEND_SAMPLE + 8, y))?;
            x += entry_width + LEGEND_GAP;
        }
    }
    let (_, below) = root.split_vertically(frame_height(legend_rows.len()));
    Ok(below)
}

/// Finite x and y ranges of the traces, padded by [`PAD_FRACTION`] (in log space for a log
/// axis, which spans at most [`LOG_SCALE_MAX_DECADES`]); `None` when no trace has a drawable
/// point.
fn data_ranges(traces: &[Trace], y_scale: YScale) -> Option<(Range<f64>, Range<f64>)> {
    let log_y = y_scale == YScale::Log;
    let points = traces.iter().flat_map(|t| t.segments(log_y)).flatten();
    let (mut x, mut y) = (
        (f64::INFINITY, f64::NEG_INFINITY),
        (f64::INFINITY, f64::NEG_INFINITY),
    );
    for (px, py) in points {
        x = (x.0.min(px), x.1.max(px));
        y = (y.0.min(py), y.1.max(py));
    }
    if !x.0.is_finite() {
        return None;
    }
    let y = if log_y {
        let hi = y.1.log10();
        let (lo, hi) = padded(y.0.log10().max(hi - LOG_SCALE_MAX_DECADES), hi);
        10f64.powf(lo)..10f64.powf(hi)
    } else if y_scale == YScale::LinearFromZero && y.0 >= 0.0 {
        let (_, hi) = padded(0.0, y.1);
        0.0..hi
    } else {
        let (lo, hi) = padded(y.0, y.1);
        lo..hi
    };
    let (x_lo, x_hi) = padded(x.0, x.1);
    Some((x_lo..x_hi, y))
}

/// `[lo, hi]` widened by [`PAD_FRACTION`] of its span on each side; a single value gets a span
/// of its own magnitude (or ±1 at zero).
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let span = hi - lo;
    if span > 1e-12 * lo.abs().max(hi.abs()) && span > 0.0 {
        (lo - PAD_FRACTION * span, hi + PAD_FRACTION * span)
    } else {
        let half = if lo == 0.0 { 1.0 } else { 0.5 * lo.abs() };
        (lo - half, hi + half)
    }
}

/// One chart in `area` with an optional panel title, axis labels and the traces.
fn draw_panel(
    area: &Area,
    panel_title: Option<&str>,
    x_label: &str,
    y_label: &str,
    y_scale: YScale,
    traces: &[Trace],
) -> DrawResult {
    let log_y = y_scale == YScale::Log;
    let Some((x_range, y_range)) = data_ranges(traces, y_scale) else {
        return Err(format!("no finite points to draw against {y_label:?}").into());
    };
    let area = match panel_title {
        Some(text) => area.titled(text, font(PANEL_TITLE_PX).color(&BLACK))?,
        None => area.clone(),
    };
    if log_y {
        // Values below the axis (a zero error's rounding noise) lie on its bottom edge.
        let floor = y_range.start;
        let raised: Vec<Trace> = traces
            .iter()
            .map(|t| Trace {
                points: t
                    .points
                    .iter()
                    .map(|&(x, y)| (x, if y > 0.0 { y.max(floor) } else { y }))
                    .collect(),
                style: t.style,
            })
            .collect();
        draw_chart(
            &area,
            x_range,
            y_range.log_scale(),
            (x_label, y_label),
            &raised,
            true,
        )
    } else {
        draw_chart(&area, x_range, y_range, (x_label, y_label), traces, false)
    }
}

/// The top view: x against y in metres with the same metres per pixel on both axes.
fn draw_top_view(area: &Area, traces: &[Trace]) -> DrawResult {
    let Some((x_range, y_range)) = data_ranges(traces, YScale::Linear) else {
        return Err("no finite points to draw".into());
    };
    let (plot_width, plot_height) = plotting_size(area);
    let (x_range, y_range) = equal_aspect(
        x_range,
        y_range,
        f64::from(plot_width),
        f64::from(plot_height),
    );
    draw_chart(area, x_range, y_range, ("x (m)", "y (m)"), traces, false)
}

/// Pixel size of the plotting area [`draw_chart`] leaves inside `area`.
fn plotting_size(area: &Area) -> (u32, u32) {
    let (width, height) = area.dim_in_pixel();
    (
        width.saturating_sub(2 * PANEL_MARGIN + Y_LABEL_AREA),
        height.saturating_sub(2 * PANEL_MARGIN + X_LABEL_AREA),
    )
}

/// Widens the shorter of two ranges (about its centre) so both have the same units per pixel
/// on a `plot_width` × `plot_height` plotting area.
fn equal_aspect(
    x: Range<f64>,
    y: Range<f64>,
    plot_width: f64,
    plot_height: f64,
) -> (Range<f64>, Range<f64>) {
    let per_pixel = ((x.end - x.start) / plot_width).max((y.end - y.start) / plot_height);
    let centred = |r: Range<f64>, pixels: f64| {
        let mid = 0.5 * (r.start + r.end);
        let half = 0.5 * per_pixel * pixels;
        mid - half..mid + half
    };
    (centred(x, plot_width), centred(y, plot_height))
}

fn draw_chart<Y>(
    area: &Area,
    x_range: Range<f64>,
    y_range: Y,
    (x_label, y_label): (&str, &str),
    traces: &[Trace],
    log_y: bool,
) -> DrawResult
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .margin(PANEL_MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(x_range, y_range)?;
    debug_assert_eq!(chart.plotting_area().dim_in_pixel(), plotting_size(area));
    let span = |r: Range<f64>| (r.end - r.start).abs();
    let (x_span, y_span) = (span(chart.x_range()), span(chart.y_range()));
    let x_tick = |v: &f64| tick_label(&snap_to_zero(*v, x_span));
    // Ticks of a log axis are never near zero on its scale.
    let y_tick = |v: &f64| tick_label(&if log_y { *v } else { snap_to_zero(*v, y_span) });
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_labels(7)
        .y_labels(6)
        .label_style(font(TICK_LABEL_PX).color(&BLACK))
        .axis_desc_style(font(AXIS_LABEL_PX).color(&BLACK))
        .x_label_formatter(&x_tick)
        .y_label_formatter(&y_tick)
        .bold_line_style(BLACK.mix(0.12))
        .max_light_lines(0)
        .axis_style(BLACK.mix(0.6))
        .draw()?;
    for trace in traces {
        let style = trace.style.colour().stroke_width(LINE_WIDTH);
        for segment in trace.segments(log_y) {
            if trace.style.dashed() {
                chart.draw_series(DashedLineSeries::new(segment, DASH, DASH, style))?;
            } else {
                chart.draw_series(LineSeries::new(segment, style))?;
            }
        }
    }
    Ok(())
}

/// Pixel size a picture of `size` pixels is shown at (see [`IMAGE_PANEL_LONG_SIDE`]).
fn shown_size((width, height): (usize, usize)) -> (u32, u32) {
    let long = width.max(height) as f64;
    let target = f64::from(IMAGE_PANEL_LONG_SIDE);
    let zoom = if long >= target {
        target / long
    } else {
        (target / long).round().max(1.0)
    };
    let side = |pixels: usize| ((pixels as f64 * zoom).round() as u32).max(1);
    (side(width), side(height))
}

/// `rgb` (`[0, 1]`, three per pixel, `size` pixels) resampled to `shown` pixels as 8-bit RGB:
/// nearest pixel when enlarging, the mean of the covered pixels when shrinking.
fn resample_rgb(rgb: &[f32], (width, height): (usize, usize), shown: (u32, u32)) -> Vec<u8> {
    let (shown_w, shown_h) = (shown.0 as usize, shown.1 as usize);
    // Source pixels [start, end) covered by shown pixel `i` of `n`, on a side of `pixels`.
    let covered = |i: usize, n: usize, pixels: usize| {
        let start = (i * pixels / n).min(pixels - 1);
        let end = ((i + 1) * pixels).div_ceil(n).clamp(start + 1, pixels);
        start..end
    };
    let byte = |v: f32| {
        if v.is_nan() {
            0
        } else {
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        }
    };
    let mut out = Vec::with_capacity(3 * shown_w * shown_h);
    for y in 0..shown_h {
        let rows = covered(y, shown_h, height);
        for x in 0..shown_w {
            let columns = covered(x, shown_w, width);
            let mut sum = [0.0f32; 3];
            for row in rows.clone() {
                for column in columns.clone() {
                    let i = 3 * (row * width + column);
                    for c in 0..3 {
                        sum[c] += rgb[i + c];
                    }
                }
            }
            let n = (rows.len() * columns.len()) as f32;
            out.extend(sum.map(|s| byte(s / n)));
        }
    }
    out
}

/// Line width of an outline over a picture: the truth wider, so an estimate on it leaves it
/// visible.
fn outline_width(style: SeriesStyle) -> u32 {
    match style {
        SeriesStyle::Truth => 2 * LINE_WIDTH + 1,
        _ => LINE_WIDTH,
    }
}

/// One picture of [`image_panels`] in `cell`: the title, the picture `shown` pixels large with
/// pixel axes around it, and the outlines over it.
fn draw_image_panel(cell: &Area, panel: &ImagePanel, shown: (u32, u32)) -> DrawResult {
    let title_style = font(PANEL_TITLE_PX)
        .color(&BLACK)
        .pos(text_anchor::Pos::new(
            text_anchor::HPos::Center,
            text_anchor::VPos::Center,
        ));
    let centre = (PANEL_MARGIN + Y_LABEL_AREA + shown.0 / 2) as i32;
    cell.draw_text(
        panel.title,
        &title_style,
        (centre, IMAGE_TITLE_HEIGHT as i32 / 2),
    )?;
    let (_, chart_area) = cell.split_vertically(IMAGE_TITLE_HEIGHT);
    // Axis units per shown pixel; a point (u, v) of the picture is drawn at (u, −v), so y grows
    // downwards as in the picture. Plotters maps a range onto the first to the last pixel, hence
    // the ranges end one shown pixel short of the extent.
    let (width, height) = panel.extent;
    let (unit_x, unit_y) = (width / f64::from(shown.0), height / f64::from(shown.1));
    let mut chart = ChartBuilder::on(&chart_area)
        .margin(PANEL_MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(0.0..width - unit_x, -(height - unit_y)..0.0)?;
    debug_assert_eq!(chart.plotting_area().dim_in_pixel(), shown);
    let x_tick = |v: &f64| tick_label(&snap_to_zero(*v, width));
    let flip = |v: &f64| tick_label(&snap_to_zero(-*v, height));
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (px)")
        .y_desc("y (px)")
        .x_labels(7)
        .y_labels(6)
        .label_style(font(TICK_LABEL_PX).color(&BLACK))
        .axis_desc_style(font(AXIS_LABEL_PX).color(&BLACK))
        .x_label_formatter(&x_tick)
        .y_label_formatter(&flip)
        .axis_style(BLACK.mix(0.6))
        .draw()?;
    let pixels = resample_rgb(panel.rgb, panel.size, shown);
    let picture = BitMapElement::with_owned_buffer((0, 0), shown, pixels)
        .ok_or("the resampled picture does not fill its size")?;
    chart.plotting_area().strip_coord_spec().draw(&picture)?;

    let mut order: Vec<&Outline> = panel.outlines.iter().collect();
    order.sort_by_key(|o| o.style.layer());
    let closed = |polygon: &[(f64, f64)]| -> Vec<(f64, f64)> {
        let mut points: Vec<(f64, f64)> = polygon.iter().map(|&(u, v)| (u, -v)).collect();
        if let Some(&first) = points.first() {
            points.push(first);
        }
        points
    };
    // White borders under every line first, then the lines, truth at the bottom.
    for (border, outline) in [true, false]
        .into_iter()
        .flat_map(|b| order.iter().map(move |o| (b, o)))
    {
        let width = outline_width(outline.style);
        let style = if border {
            WHITE.stroke_width(width + 2)
        } else {
            outline.style.colour().stroke_width(width)
        };
        for polygon in &outline.polygons {
            let points = closed(polygon);
            if outline.style.dashed() && !border {
                chart.draw_series(DashedLineSeries::new(points, DASH, DASH, style))?;
            } else {
                // Round joins: a disc at every corner.
                let radius = (style.stroke_width / 2).max(1);
                chart.draw_series(
                    points
                        .iter()
                        .map(|&p| Circle::new(p, radius, style.filled())),
                )?;
                chart.draw_series(std::iter::once(PathElement::new(points, style)))?;
            }
        }
    }
    Ok(())
}

/// 0 for a tick value within rounding error of zero on an axis spanning `span` (a tick at
/// `2.8e−17` of an axis centred on 0 is at 0).
fn snap_to_zero(value: f64, span: f64) -> f64 {
    if value.abs() <= 1e-9 * span {
        0.0
    } else {
        value
    }
}

/// A tick label with no trailing zeros (`0.5`, `10`, `1e-5`) and a true minus sign.
fn tick_label(value: &f64) -> String {
    let v = *value;
    let magnitude = v.abs();
    let text = if v == 0.0 {
        "0".to_string()
    } else if (1e-4..1e6).contains(&magnitude) {
        trim_zeros(&format!("{v:.6}")).to_string()
    } else {
        let scientific = format!("{v:.3e}");
        match scientific.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim_zeros(mantissa)),
            None => scientific,
        }
    };
    text.replace('-', "\u{2212}")
}

/// `"2.500"` → `"2.5"`, `"3.000"` → `"3"`.
fn trim_zeros(decimal: &str) -> &str {
    if decimal.contains('.') {
        decimal.trim_end_matches('0').trim_end_matches('.')
    } else {
        decimal
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::TempDir;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use std::f64::consts::PI;

    /// Decodes the PNG and returns its size and number of distinct colours.
    fn png_size_and_colours(path: &Path) -> ((u32, u32), usize) {
        let image = image::open(path).unwrap().to_rgb8();
        let mut colours: Vec<[u8; 3]> = image.pixels().map(|p| p.0).collect();
        colours.sort_unstable();
        colours.dedup();
        (image.dimensions(), colours.len())
    }

    /// A circle of radius 2 m at 1.5 m height, yaw following the direction of travel (so it
    /// crosses ±180°), 20 s per turn; `noise` (m, rad) perturbs it smoothly.
    fn circle(times: &[f64], noise: f64) -> Vec<Isometry3<f64>> {
        times
            .iter()
            .map(|&t| {
                let phase = TAU * t / 20.0;
                let wobble = noise * ((0.9 * t + 1.0).sin() + 0.3 * (2.3 * t).sin());
                let position = Vector3::new(
                    2.0 * phase.cos() + wobble,
                    2.0 * phase.sin() + noise * (0.7 * t).cos(),
                    1.5 + 0.5 * noise * (0.5 * t).sin(),
                );
                let rotation = UnitQuaternion::from_euler_angles(
                    0.1 * (0.5 * t).sin() + wobble,
                    0.05 * (0.3 * t).cos(),
                    phase + PI / 2.0 + wobble,
                );
                Isometry3::from_parts(Translation3::from(position), rotation)
            })
            .collect()
    }

    fn sample_series() -> Vec<TrajectorySeries> {
        let times: Vec<f64> = (0..=200).map(|i| i as f64 * 0.1).collect();
        vec![
            TrajectorySeries {
                label: "ground truth".into(),
                times_secs: times.clone(),
                poses: circle(&times, 0.0),
                style: SeriesStyle::Truth,
            },
            TrajectorySeries {
                label: "initial (perturbed)".into(),
                times_secs: times.clone(),
                poses: circle(&times, 0.3),
                style: SeriesStyle::Initial,
            },
            TrajectorySeries {
                label: "PoseNet".into(),
                times_secs: times.clone(),
                poses: circle(&times, 0.05),
                style: SeriesStyle::Estimate(0),
            },
            TrajectorySeries {
                label: "B-spline".into(),
                times_secs: times.clone(),
                poses: circle(&times, 0.1),
                style: SeriesStyle::Estimate(1),
            },
        ]
    }

    /// Where sample PNGs go: `CPOSE_PLOT_SAMPLES` if set (to look at them), else `dir`.
    fn sample_path(dir: &Path, name: &str) -> PathBuf {
        match std::env::var_os("CPOSE_PLOT_SAMPLES") {
            Some(folder) => PathBuf::from(folder).join(name),
            None => dir.join(name),
        }
    }

    #[test]
    fn trajectories_writes_a_png_of_the_stated_size_with_several_colours() {
        let dir = TempDir::new("plot-traj");
        let path = sample_path(&dir, "trajectories.png");
        trajectories(
            &path,
            "Circle: PoseNet and B-spline vs ground truth",
            &sample_series(),
        )
        .unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size, TRAJECTORIES_SIZE);
        assert!(colours > 20, "{colours} colours");
    }

    #[test]
    fn errors_over_time_writes_a_png_of_the_stated_size_with_several_colours() {
        let dir = TempDir::new("plot-err");
        let path = sample_path(&dir, "errors.png");
        let t: Vec<f64> = (0..=300).map(|i| i as f64 * 0.1).collect();
        let line = |label: &str, scale: f64, style| Line {
            label: label.into(),
            x: t.clone(),
            y: t.iter().map(|t| scale * (1.2 + (0.7 * t).sin())).collect(),
            style,
        };
        let lines = [
            line("initial", 30.0, SeriesStyle::Initial),
            line("PoseNet", 2.0, SeriesStyle::Estimate(0)),
            line("B-spline", 4.0, SeriesStyle::Estimate(1)),
        ];
        errors_over_time(&path, "Position error", "position error (cm)", &lines).unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size, LINE_CHART_SIZE);
        assert!(colours > 20, "{colours} colours");
    }

    fn sample_curves_csv() -> String {
        let mut csv = format!("{CURVES_HEADER}\n");
        for (condition, noise) in [("noise-10deg", 10.0), ("noise-20deg", 20.0)] {
            for (method, rate) in [("posenet", 3e-3), ("barf", 1.5e-3)] {
                for step in (0..=2000).step_by(50) {
                    let s = step as f64;
                    let loss = 0.005 * noise * (-rate * s).exp() + 2e-4;
                    let rot = noise * (-rate * s).exp() + 0.2;
                    csv += &format!(
                        "{condition},{method},0,{step},{:.3},loss,{loss:e}\n",
                        s / 100.0
                    );
                    csv += &format!(
                        "{condition},{method},0,{step},{:.3},rot_err_deg,{rot:e}\n",
                        s / 100.0
                    );
                }
            }
        }
        csv
    }

    #[test]
    fn curves_csv_writes_one_panel_per_metric_with_several_colours() {
        let dir = TempDir::new("plot-curves");
        let path = sample_path(&dir, "curves.png");
        curves_csv(&path, "Training curves", &sample_curves_csv()).unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size.0, 2 * CURVES_PANEL_SIZE.0);
        assert!(size.1 > CURVES_PANEL_SIZE.1, "{size:?}");
        assert!(colours > 20, "{colours} colours");
    }

    #[test]
    fn many_units_wrap_the_legend_and_odd_metric_counts_leave_a_cell_free() {
        let dir = TempDir::new("plot-curves-many");
        let path = sample_path(&dir, "curves_many.png");
        let mut csv = format!("{CURVES_HEADER}\n");
        for (c, condition) in ["orbit-60deg-20pct", "orbit-30deg"].iter().enumerate() {
            for (m, method) in ["posenet", "barf", "lie_spline"].iter().enumerate() {
                for seed in 0..3 {
                    let steps_per_e = 150.0 * (1 + m + 3 * c) as f64 + 20.0 * seed as f64;
                    for step in (0..=1000).step_by(50) {
                        let decay = (-(step as f64) / steps_per_e).exp();
                        let rows = [
                            ("loss", 0.1 * decay + 1e-4),
                            ("rot_err_deg", 30.0 * decay),
                            ("psnr_db", 30.0 - 10.0 * decay),
                        ];
                        for (metric, value) in rows {
                            csv +=
                                &format!("{condition},{method},{seed},{step},0,{metric},{value}\n");
                        }
                    }
                }
            }
        }
        let rows = parse_curves_csv(&csv).unwrap();
        curves(&path, "Training curves, 18 units", &rows).unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size.0, 2 * CURVES_PANEL_SIZE.0);
        assert!(
            size.1 > 2 * CURVES_PANEL_SIZE.1 + LEGEND_ROW_HEIGHT,
            "{size:?}"
        );
        assert!(colours > 20, "{colours} colours");
    }

    #[test]
    fn a_single_pose_or_a_straight_line_still_draws() {
        let dir = TempDir::new("plot-degenerate");
        let single = TrajectorySeries {
            label: "one pose".into(),
            times_secs: vec![0.0],
            poses: vec![Isometry3::identity()],
            style: SeriesStyle::Estimate(0),
        };
        trajectories(dir.join("single.png"), "One pose", &[single]).unwrap();
        let times: Vec<f64> = (0..50).map(f64::from).collect();
        let line = TrajectorySeries {
            label: "along x".into(),
            poses: times
                .iter()
                .map(|&t| Isometry3::translation(t, 0.0, 0.0))
                .collect(),
            times_secs: times,
            style: SeriesStyle::Truth,
        };
        let path = sample_path(&dir, "straight.png");
        trajectories(&path, "Straight line", &[line]).unwrap();
        assert_eq!(png_size_and_colours(&path).0, TRAJECTORIES_SIZE);
    }

    #[test]
    fn csv_parser_names_the_bad_line() {
        let csv =
            format!("{CURVES_HEADER}\na,posenet,0,10,0.5,loss,1e-2\na,posenet,0,20,1.0,loss\n");
        match parse_curves_csv(&csv) {
            Err(PlotError::Csv { line: 3, message }) => assert!(message.contains("7"), "{message}"),
            other => panic!("expected an error on line 3, got {other:?}"),
        }
        let csv = format!("{CURVES_HEADER}\na,posenet,zero,10,0.5,loss,1e-2\n");
        let error = parse_curves_csv(&csv).unwrap_err().to_string();
        assert!(
            error.contains("line 2") && error.contains("seed"),
            "{error}"
        );
        let error = parse_curves_csv("step,value\n1,2\n")
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("line 1") && error.contains("header"),
            "{error}"
        );
        let rows =
            parse_curves_csv(&format!("{CURVES_HEADER}\nc,m,3,20,1.5,loss,NaN\n\n")).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!((rows[0].seed, rows[0].step, rows[0].wall_s), (3, 20, 1.5));
        assert!(rows[0].value.is_nan());
    }

    #[test]
    fn yaw_crossing_180_degrees_is_unwrapped() {
        let yaw_deg = [170.0, 175.0, 179.0, -178.0, -172.0, -165.0];
        let yaw: Vec<f64> = yaw_deg.iter().map(|d: &f64| d.to_radians()).collect();
        let unwrapped: Vec<f64> = unwrap_angles(&yaw).iter().map(|a| a.to_degrees()).collect();
        let expected = [170.0, 175.0, 179.0, 182.0, 188.0, 195.0];
        for (u, e) in unwrapped.iter().zip(expected) {
            assert!((u - e).abs() < 1e-9, "{unwrapped:?}");
        }
        // Two full turns in the other direction, and a gap.
        let turns: Vec<f64> = (0..=40).map(|i| -(i as f64) * TAU / 20.0).collect();
        let wrapped: Vec<f64> = turns
            .iter()
            .map(|a| (a + PI).rem_euclid(TAU) - PI)
            .chain([f64::NAN])
            .collect();
        let unwrapped = unwrap_angles(&wrapped);
        for (u, t) in unwrapped.iter().zip(&turns) {
            assert!((u - t).abs() < 1e-9, "{u} vs {t}");
        }
        assert!(unwrapped[41].is_nan());

        // Through poses: the trajectory's yaw panel data are continuous.
        let series = &sample_series()[0];
        let yaw = &pose_components(series)[5];
        assert!(yaw.windows(2).all(|w| (w[1] - w[0]).abs() < 10.0));
        assert!(
            (yaw[yaw.len() - 1] - yaw[0] - 360.0).abs() < 1e-6,
            "one turn"
        );
    }

    #[test]
    fn series_start_within_half_a_turn_of_the_first() {
        let mut angles = vec![-179.0 + 720.0, -170.0 + 720.0];
        shift_by_turns_towards(&mut angles, 179.0);
        assert_eq!(angles, vec![181.0, 190.0]);
    }

    #[test]
    fn empty_or_mismatched_series_are_errors_naming_the_file() {
        let dir = TempDir::new("plot-empty");
        let path = dir.join("empty.png");
        let error = trajectories(&path, "t", &[]).unwrap_err().to_string();
        assert!(
            error.contains("no series") && error.contains("empty.png"),
            "{error}"
        );
        let no_points = TrajectorySeries {
            label: "truth".into(),
            times_secs: vec![],
            poses: vec![],
            style: SeriesStyle::Truth,
        };
        let error = trajectories(&path, "t", &[no_points])
            .unwrap_err()
            .to_string();
        assert!(error.contains("\"truth\" has no points"), "{error}");
        let mismatched = Line {
            label: "a".into(),
            x: vec![0.0, 1.0],
            y: vec![0.0],
            style: SeriesStyle::Estimate(0),
        };
        let error = errors_over_time(&path, "t", "e", &[mismatched]).unwrap_err();
        assert!(
            matches!(error, PlotError::LengthMismatch { xs: 2, ys: 1, .. }),
            "{error}"
        );
        assert!(
            error.to_string().contains("2 x values but 1 y values"),
            "{error}"
        );
        assert!(errors_over_time(&path, "t", "e", &[]).is_err());
        let error = curves_csv(&path, "t", &format!("{CURVES_HEADER}\n")).unwrap_err();
        assert!(matches!(error, PlotError::Empty { .. }), "{error}");
        let only_nan = Line {
            label: "nan".into(),
            x: vec![0.0],
            y: vec![f64::NAN],
            style: SeriesStyle::Estimate(0),
        };
        let error = errors_over_time(&path, "t", "e", &[only_nan])
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("empty.png") && error.contains("finite"),
            "{error}"
        );
        assert!(!path.exists());
    }

    #[test]
    fn top_view_has_equal_metres_per_pixel() {
        let (x, y) = equal_aspect(-2.0..2.0, 0.0..1.0, 800.0, 400.0);
        assert_eq!((x.end - x.start) / 800.0, (y.end - y.start) / 400.0);
        assert_eq!((x, y), (-2.0..2.0, -0.5..1.5));
    }

    #[test]
    fn unit_suffixes_and_log_scale_label_the_axis() {
        assert_eq!(
            metric_axis_label("rot_err_deg", YScale::Linear),
            "rot_err (°)"
        );
        assert_eq!(metric_axis_label("loss", YScale::Log), "loss (log scale)");
        assert_eq!(
            metric_axis_label("corner_err_px", YScale::Log),
            "corner_err (px, log scale)"
        );
        assert_eq!(
            metric_axis_label("ang_vel_rmse_rad_s", YScale::Linear),
            "ang_vel_rmse (rad/s)"
        );
        assert_eq!(
            metric_axis_label("trans_err_su", YScale::Linear),
            "trans_err (scene units)"
        );
        assert!(wants_log_scale([1.0, 1e-3].into_iter()));
        assert!(!wants_log_scale([1.0, 0.5].into_iter()));
        assert!(!wants_log_scale([1.0, 0.0, 1e-3].into_iter()));
        let legend = unit_legend(&[("a", "posenet", 0), ("a", "barf", 0)]);
        assert_eq!(legend, (vec!["posenet".into(), "barf".into()], vec![0, 1]));
        let legend = unit_legend(&[("a", "posenet", 0), ("a", "posenet", 1)]);
        assert_eq!(legend, (vec!["seed 0".into(), "seed 1".into()], vec![0, 1]));
        let units = [
            ("a", "posenet", 0),
            ("b", "posenet", 0),
            ("a", "posenet", 1),
        ];
        let legend = unit_legend(&units);
        assert_eq!(
            legend,
            (vec!["a (2 seeds)".into(), "b".into()], vec![0, 1, 0])
        );
    }

    #[test]
    fn trajectory_comparison_draws_truth_initial_and_estimate_from_any_time_origin() {
        let dir = TempDir::new("plot-comparison");
        let path = sample_path(&dir, "comparison.png");
        let times: Vec<f64> = (0..=200).map(|i| 1.3e9 + i as f64 * 0.1).collect();
        let relative: Vec<f64> = times.iter().map(|t| t - times[0]).collect();
        let (truth, initial, estimate) = (
            circle(&relative, 0.0),
            circle(&relative, 0.3),
            circle(&relative, 0.05),
        );
        trajectory_comparison(
            &path,
            "Circle: PoseNet (aligned) vs ground truth",
            &times,
            Some(&truth),
            Some(("initial poses (aligned)", &initial)),
            ("PoseNet (aligned)", &estimate),
        )
        .unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size, TRAJECTORIES_SIZE);
        assert!(colours > 20, "{colours} colours");
        // Without truth and with an empty initial: the estimate alone.
        let alone = dir.join("alone.png");
        trajectory_comparison(
            &alone,
            "t",
            &times,
            None,
            Some(("i", &[])),
            ("e", &estimate),
        )
        .unwrap();
        assert_eq!(png_size_and_colours(&alone).0, TRAJECTORIES_SIZE);
        let error = trajectory_comparison(
            &alone,
            "t",
            &times,
            Some(&truth[1..]),
            None,
            ("e", &estimate),
        )
        .unwrap_err();
        assert!(matches!(error, PlotError::LengthMismatch { .. }), "{error}");
    }

    #[test]
    fn stacked_line_charts_draw_one_panel_per_axis_and_one_legend() {
        let dir = TempDir::new("plot-stacked");
        let path = sample_path(&dir, "stacked.png");
        let t: Vec<f64> = (0..=300).map(|i| i as f64 * 0.1).collect();
        let line = |label: &str, scale: f64, style| Line {
            label: label.into(),
            x: t.clone(),
            y: t.iter().map(|t| scale * (1.2 + (0.7 * t).sin())).collect(),
            style,
        };
        let panels = [
            Panel {
                y_label: "rotation error (°)".into(),
                y_scale: YScale::LinearFromZero,
                lines: vec![
                    line("interpolation", 0.5, SeriesStyle::Initial),
                    line("PoseNet", 0.1, SeriesStyle::Estimate(0)),
                ],
            },
            Panel {
                y_label: "position error (cm)".into(),
                y_scale: YScale::LinearFromZero,
                lines: vec![
                    line("interpolation", 3.0, SeriesStyle::Initial),
                    line("PoseNet", 1.0, SeriesStyle::Estimate(0)),
                ],
            },
        ];
        stacked_line_charts(&path, "Held-out errors", "time (s)", &panels).unwrap();
        let (size, colours) = png_size_and_colours(&path);
        assert_eq!(size.0, STACKED_PANEL_SIZE.0);
        // One legend row for the two shared entries.
        assert_eq!(size.1, 2 * STACKED_PANEL_SIZE.1 + frame_height(1));
        assert!(colours > 20, "{colours} colours");
        let no_lines = Panel {
            y_label: "e".into(),
            y_scale: YScale::Linear,
            lines: vec![],
        };
        let error = stacked_line_charts(&path, "t", "x", &[no_lines]).unwrap_err();
        assert!(error.to_string().contains("has no lines"), "{error}");
    }

    #[test]
    fn image_panels_show_pictures_with_outlines_and_a_legend() {
        let dir = TempDir::new("plot-image");
        let path = sample_path(&dir, "image_panels.png");
        let (w, h) = (120, 90);
        let picture: Vec<f32> = (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
                [x, y, 0.5 * (x + y)]
            })
            .collect();
        let square = |x: f64, y: f64, side: f64| {
            vec![(x, y), (x + side, y), (x + side, y + side), (x, y + side)]
        };
        // Axes in pixels of a twice as large original.
        let outlines = [
            Outline {
                label: "true patch outlines".into(),
                style: SeriesStyle::Truth,
                polygons: vec![square(40.0, 30.0, 80.0), square(60.0, 40.0, 80.0)],
            },
            Outline {
                label: "estimated outlines (PoseNet)".into(),
                style: SeriesStyle::Estimate(0),
                polygons: vec![square(41.0, 31.0, 80.0), square(66.0, 44.0, 80.0)],
            },
        ];
        let panels = [
            ImagePanel {
                title: "image",
                size: (w, h),
                rgb: &picture,
                extent: (2.0 * w as f64, 2.0 * h as f64),
                outlines: &outlines,
            },
            ImagePanel {
                title: "neural image",
                size: (w, h),
                rgb: &picture,
                extent: (2.0 * w as f64, 2.0 * h as f64),
                outlines: &[],
            },
        ];
        image_panels(&path, "Patch alignment: PoseNet", &panels).unwrap();
        let (size, colours) = png_size_and_colours(&path);
        // 120 px wide pictures are shown 5 times enlarged.
        let shown = (5 * w as u32, 5 * h as u32);
        assert_eq!(shown_size((w, h)), shown);
        assert_eq!(size.0, 2 * (shown.0 + 2 * PANEL_MARGIN + Y_LABEL_AREA));
        assert!(colours > 100, "{colours} colours");
        let error = image_panels(
            &path,
            "t",
            &[ImagePanel {
                rgb: &picture[3..],
                ..panels[1]
            }],
        )
        .unwrap_err();
        assert!(matches!(error, PlotError::LengthMismatch { .. }), "{error}");
    }

    #[test]
    fn pictures_are_enlarged_by_whole_factors_and_shrunk_by_averaging() {
        assert_eq!(shown_size((32, 32)), (640, 640));
        assert_eq!(shown_size((240, 180)), (720, 540));
        assert_eq!(shown_size((1280, 640)), (640, 320));
        let rgb = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        // Enlarged: each pixel repeated.
        assert_eq!(
            resample_rgb(&rgb, (2, 1), (4, 1)),
            [0, 0, 0, 0, 0, 0, 255, 255, 255, 255, 255, 255]
        );
        // Shrunk: the mean.
        assert_eq!(resample_rgb(&rgb, (2, 1), (1, 1)), [128, 128, 128]);
    }

    #[test]
    fn ticks_within_rounding_error_of_zero_are_zero() {
        assert_eq!(tick_label(&snap_to_zero(2.776e-17, 0.4)), "0");
        assert_eq!(tick_label(&snap_to_zero(-0.1, 0.4)), "\u{2212}0.1");
        assert_eq!(tick_label(&snap_to_zero(1e-12, 1e-10)), "1e\u{2212}12");
    }

    #[test]
    fn tick_labels_are_short() {
        let labels: Vec<String> = [0.0, 0.5, 10.0, -2.0, 0.1 + 0.2, 1e-5, 2.5e7]
            .iter()
            .map(tick_label)
            .collect();
        assert_eq!(
            labels,
            ["0", "0.5", "10", "\u{2212}2", "0.3", "1e\u{2212}5", "2.5e7"]
        );
    }
}
