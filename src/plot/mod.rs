//! Charts written as PNG and SVG, shared by `motion show`, the synthesis report and the
//! bench report.
//!
//! Owns the embedded font (DejaVu Sans, so no system font library is needed), the colour
//! palette and a small declarative chart description ([`Chart`]) that every report draws
//! through. It does not decide what to plot: callers build the series.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

/// The embedded font, registered with plotters under the family name "sans-serif".
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

/// Default picture size in pixels (width, height).
pub const DEFAULT_SIZE: (u32, u32) = (1000, 600);

/// Above the data, a chart whose legend sits in the upper right corner reaches this
/// multiple of the data's span (set by the caller in `y_range`), so the legend hides no
/// peak: 1.45.
pub const LEGEND_HEADROOM: f64 = 1.45;

/// Margin below data in a [`legend_room_y_range`], as a fraction of its span: 0.05.
pub const BELOW_DATA_MARGIN: f64 = 0.05;

/// The y range for data from `lo` spanning `span`: [`BELOW_DATA_MARGIN`] below it and
/// [`LEGEND_HEADROOM`] × `span` above `lo`, so the legend in the upper right corner hides
/// no peak.
pub fn legend_room_y_range(lo: f64, span: f64) -> (f64, f64) {
    (lo - BELOW_DATA_MARGIN * span, lo + LEGEND_HEADROOM * span)
}

/// Legend text size, pixels: 14.
pub const LEGEND_FONT_PX: u32 = 14;

/// Spacing of the probes along a drawn line when the legend's corner is chosen, pixels: 3,
/// finer than the 2 px lines are wide apart from their ends.
pub const LEGEND_PROBE_PX: f64 = 3.0;

/// Opacity of a [`Chart::zones`] shading: 0.15, a tint under the data.
pub const ZONE_OPACITY: f64 = 0.15;
/// A y label this close to zero, as a fraction of the y range, is labelled as zero: plotters
/// places key points by adding steps, so the one meant at zero can land 1e-17 off it and be
/// printed "-0.0". 1e-9 of the range is far below any label's own precision.
const ZERO_LABEL_FRACTION: f64 = 1e-9;

/// Opacity of a [`Mark::Band`]: 0.35, pale enough that points of any palette colour
/// drawn on it stand out, dark enough to read as the reference where none are.
pub const BAND_OPACITY: f64 = 0.35;

/// The label of y value `y` on an axis `span` long: plotters' own, except that a key point
/// a rounding error off zero reads "0.0" and not "-0.0" (it did on deviation charts whose
/// range crosses zero).
fn y_label(y: f64, span: f64) -> String {
    let y = if y.abs() <= span * ZERO_LABEL_FRACTION {
        0.0
    } else {
        y
    };
    <RangedCoordf64 as ValueFormatter<f64>>::format(&y)
}

/// Error while drawing or writing a chart.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The plotting backend failed (file not writable, bad range, ...).
    #[error("cannot draw chart {path}: {message}")]
    Draw {
        /// The file being written.
        path: PathBuf,
        /// The backend's message.
        message: String,
    },
    /// There is nothing to draw or the data is not finite.
    #[error("chart {title:?} has no finite data to draw")]
    Empty {
        /// The chart's title.
        title: String,
    },
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mark {
    /// A solid polyline; breaks where a point is not finite.
    Line,
    /// A dashed polyline (targets, references).
    Dashed,
    /// Filled circles of the given radius in pixels.
    Points(u32),
    /// Vertical bars from y = 0, centred on each x, as wide as the closest x spacing
    /// (histograms).
    Bars,
    /// A broad pale polyline of the given width in pixels: a reference that data drawn
    /// after it lies on, both visible (a target under measured points).
    Band(u32),
}

/// One named data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text; empty for no legend entry.
    pub label: String,
    /// (x, y) points in data units.
    pub points: Vec<(f64, f64)>,
    /// How to draw it.
    pub mark: Mark,
    /// Index into the palette ([`color`]).
    pub color: usize,
}

impl Series {
    /// A solid line series.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Line,
            color,
        }
    }

    /// A broad pale line series ([`Mark::Band`]), to draw before the data it underlies.
    pub fn band(
        label: impl Into<String>,
        points: Vec<(f64, f64)>,
        color: usize,
        width: u32,
    ) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Band(width),
            color,
        }
    }

    /// A dashed line series.
    pub fn dashed(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Dashed,
            color,
        }
    }

    /// A scatter series with markers of `radius` pixels.
    pub fn points(
        label: impl Into<String>,
        points: Vec<(f64, f64)>,
        radius: u32,
        color: usize,
    ) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Points(radius),
            color,
        }
    }
}

impl Series {
    /// A bar series (histogram): one bar per point, from 0 to y.
    pub fn bars(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Bars,
            color,
        }
    }
}

/// A 2-D chart: axes, series, optional horizontal reference lines.
#[derive(Debug, Clone)]
pub struct Chart {
    /// Caption above the plot.
    pub title: String,
    /// X axis description (with unit).
    pub x_label: String,
    /// Y axis description (with unit).
    pub y_label: String,
    /// The data.
    pub series: Vec<Series>,
    /// Fixed x range; computed from the data when `None`.
    pub x_range: Option<(f64, f64)>,
    /// Fixed y range; computed from the data when `None`.
    pub y_range: Option<(f64, f64)>,
    /// Horizontal reference lines (y value, legend label).
    pub h_lines: Vec<(f64, String)>,
    /// Shaded horizontal zones drawn under everything: (from y, to y, palette colour,
    /// legend label), e.g. where a figure is good and where it is bad.
    pub zones: Vec<(f64, f64, usize, String)>,
    /// Keep one data unit the same length on both axes (for paths and curves).
    pub equal_aspect: bool,
    /// The x axis counts whole things (cycles): labels at whole numbers only, without
    /// decimals (issue 20: ticks at 0.5 cycles).
    pub whole_x: bool,
    /// Picture size in pixels.
    pub size: (u32, u32),
}

impl Chart {
    /// An empty chart with the given title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            x_range: None,
            y_range: None,
            h_lines: Vec::new(),
            zones: Vec::new(),
            equal_aspect: false,
            whole_x: false,
            size: DEFAULT_SIZE,
        }
    }

    /// Add a series (builder style).
    pub fn with(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// Write `<stem>.png` and `<stem>.svg`; returns both paths.
    pub fn write(&self, stem: &Path) -> Result<[PathBuf; 2], PlotError> {
        register_font();
        let ranges = self.ranges()?;
        let png = stem.with_extension("png");
        let svg = stem.with_extension("svg");
        let draw_err = |path: &Path| {
            let path = path.to_path_buf();
            move |e: String| PlotError::Draw {
                path: path.clone(),
                message: e,
            }
        };
        {
            let root = BitMapBackend::new(&png, self.size).into_drawing_area();
            self.draw(&root, ranges).map_err(draw_err(&png))?;
            root.present()
                .map_err(|e| e.to_string())
                .map_err(draw_err(&png))?;
        }
        {
            let root = SVGBackend::new(&svg, self.size).into_drawing_area();
            self.draw(&root, ranges).map_err(draw_err(&svg))?;
            root.present()
                .map_err(|e| e.to_string())
                .map_err(draw_err(&svg))?;
        }
        Ok([png, svg])
    }

    /// The (x, y) data ranges, padded.
    #[allow(clippy::type_complexity)] // two plain (min, max) pairs; an alias would hide that
    fn ranges(&self) -> Result<((f64, f64), (f64, f64)), PlotError> {
        let finite = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        let mut xr = (f64::INFINITY, f64::NEG_INFINITY);
        let mut yr = (f64::INFINITY, f64::NEG_INFINITY);
        for &(x, y) in finite {
            xr = (xr.0.min(x), xr.1.max(x));
            yr = (yr.0.min(y), yr.1.max(y));
        }
        for (y, _) in &self.h_lines {
            yr = (yr.0.min(*y), yr.1.max(*y));
        }
        if self.series.iter().any(|s| s.mark == Mark::Bars) {
            yr = (yr.0.min(0.0), yr.1.max(0.0));
        }
        let mut xr = self.x_range.unwrap_or(xr);
        let mut yr = self.y_range.unwrap_or(yr);
        if !(xr.0.is_finite() && xr.1.is_finite() && yr.0.is_finite() && yr.1.is_finite()) {
            return Err(PlotError::Empty {
                title: self.title.clone(),
            });
        }
        let pad = |r: (f64, f64), fixed: bool| {
            let span = r.1 - r.0;
            if span <= f64::EPSILON * r.0.abs().max(r.1.abs()).max(1.0) {
                (r.0 - 0.5, r.1 + 0.5)
            } else if fixed {
                r
            } else {
                (r.0 - 0.04 * span, r.1 + 0.04 * span)
            }
        };
        xr = pad(xr, self.x_range.is_some());
        yr = pad(yr, self.y_range.is_some());
        if self.equal_aspect {
            let (w, h) = (
                f64::from(self.size.0.saturating_sub(100)),
                f64::from(self.size.1.saturating_sub(100)),
            );
            let units_per_px = ((xr.1 - xr.0) / w).max((yr.1 - yr.0) / h);
            let (cx, cy) = ((xr.0 + xr.1) / 2.0, (yr.0 + yr.1) / 2.0);
            xr = (cx - units_per_px * w / 2.0, cx + units_per_px * w / 2.0);
            yr = (cy - units_per_px * h / 2.0, cy + units_per_px * h / 2.0);
        }
        Ok((xr, yr))
    }

    /// The legend's entries in the order `draw` adds them: labelled zones, labelled
    /// reference lines, then labelled series that draw something.
    fn legend_labels(&self) -> impl Iterator<Item = &str> {
        let zones = self.zones.iter().map(|z| z.3.as_str());
        let lines = self.h_lines.iter().map(|l| l.1.as_str());
        let series = self
            .series
            .iter()
            .filter(|s| s.points.iter().any(|(x, y)| x.is_finite() && y.is_finite()))
            .map(|s| s.label.as_str());
        zones.chain(lines).chain(series).filter(|l| !l.is_empty())
    }

    /// The corner for a legend box of `legend` pixels (width, height) in a plot area of
    /// `plot` pixels showing `xr` × `yr`: of upper right, upper left, lower right and lower
    /// left, in that order of preference, the one where the box hides the fewest marks
    /// (points, and lines followed every [`LEGEND_PROBE_PX`]). A rising curve's legend
    /// goes to the upper left, where it hides nothing, instead of over the curve's end.
    fn legend_corner(
        &self,
        (xr, yr): ((f64, f64), (f64, f64)),
        plot: (u32, u32),
        legend: (i32, i32),
    ) -> SeriesLabelPosition {
        let (w, h) = (f64::from(plot.0), f64::from(plot.1));
        let to_px = |(x, y): (f64, f64)| {
            (
                (x - xr.0) / (xr.1 - xr.0) * w,
                (yr.1 - y) / (yr.1 - yr.0) * h,
            )
        };
        // Every drawn mark as pixel probes: points as they are, lines and bars followed
        // every LEGEND_PROBE_PX.
        fn follow(a: (f64, f64), b: (f64, f64), probes: &mut Vec<(f64, f64)>) {
            let len = (b.0 - a.0).hypot(b.1 - a.1);
            let steps = (len / LEGEND_PROBE_PX).ceil().clamp(1.0, 1000.0) as usize;
            probes.extend((0..=steps).map(|j| {
                let f = j as f64 / steps as f64;
                (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
            }));
        }
        let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
        let mut probes = Vec::new();
        for s in &self.series {
            match s.mark {
                Mark::Points(_) => probes.extend(s.points.iter().filter(finite).map(|p| to_px(*p))),
                Mark::Bars => {
                    for &(x, y) in s.points.iter().filter(finite) {
                        follow(to_px((x, 0.0)), to_px((x, y)), &mut probes);
                    }
                }
                Mark::Line | Mark::Dashed | Mark::Band(_) => {
                    for pair in s.points.windows(2) {
                        if finite(&&pair[0]) && finite(&&pair[1]) {
                            follow(to_px(pair[0]), to_px(pair[1]), &mut probes);
                        }
                    }
                }
            }
        }
        for (y, _) in &self.h_lines {
            follow(to_px((xr.0, *y)), to_px((xr.1, *y)), &mut probes);
        }
        // The boxes' top left corners as plotters lays them out (5 px in from the
        // corner), in the order of preference; each grown by a marker's radius.
        let (lw, lh) = (f64::from(legend.0), f64::from(legend.1));
        let grow = 3.0;
        let corners = [
            (w - lw - 5.0, 5.0),
            (5.0, 5.0),
            (w - lw - 5.0, h - lh - 5.0),
            (5.0, h - lh - 5.0),
        ];
        let hidden = |&(x0, y0): &(f64, f64)| {
            probes
                .iter()
                .filter(|(px, py)| {
                    *px >= x0 - grow
                        && *px <= x0 + lw + grow
                        && *py >= y0 - grow
                        && *py <= y0 + lh + grow
                })
                .count()
        };
        let best = (0..corners.len())
            .min_by_key(|&i| (hidden(&corners[i]), i))
            .unwrap_or(0);
        match best {
            0 => SeriesLabelPosition::UpperRight,
            1 => SeriesLabelPosition::UpperLeft,
            2 => SeriesLabelPosition::LowerRight,
            _ => SeriesLabelPosition::LowerLeft,
        }
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        (xr, yr): ((f64, f64), (f64, f64)),
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
            .map_err(|e| e.to_string())?;
        let whole = |x: &f64| {
            if (x - x.round()).abs() < 1e-9 {
                format!("{:.0}", x.round())
            } else {
                String::new()
            }
        };
        let span = (yr.1 - yr.0).abs();
        let y_label = |y: &f64| y_label(*y, span);
        let mut mesh = chart.configure_mesh();
        mesh.y_label_formatter(&y_label);
        mesh.x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235));
        if self.whole_x {
            // One label per whole number in the range (plotters then steps by 1).
            let count = ((xr.1 - xr.0).floor() as usize + 1).clamp(2, 20);
            mesh.x_labels(count).x_label_formatter(&whole);
        }
        mesh.draw().map_err(|e| e.to_string())?;
        let mut any_label = false;
        for (y0, y1, c, label) in &self.zones {
            let fill = color(*c).mix(ZONE_OPACITY).filled();
            let series = chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(xr.0, y0.max(yr.0)), (xr.1, y1.min(yr.1))],
                    fill,
                )))
                .map_err(|e| e.to_string())?;
            if !label.is_empty() {
                any_label = true;
                series
                    .label(label.as_str())
                    .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], fill));
            }
        }
        for (y, label) in &self.h_lines {
            let style = ShapeStyle::from(&RGBColor(200, 30, 30)).stroke_width(1);
            let series = chart
                .draw_series(DashedLineSeries::new(
                    vec![(xr.0, *y), (xr.1, *y)],
                    8,
                    5,
                    style,
                ))
                .map_err(|e| e.to_string())?;
            if !label.is_empty() {
                any_label = true;
                series
                    .label(label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            }
        }
        for s in &self.series {
            let colour = color(s.color);
            let style = match s.mark {
                Mark::Band(w) => ShapeStyle::from(&colour.mix(BAND_OPACITY)).stroke_width(w),
                _ => ShapeStyle::from(&colour).stroke_width(2),
            };
            let anno = match s.mark {
                Mark::Line | Mark::Dashed | Mark::Band(_) => {
                    // Split at non-finite points so gaps show as gaps.
                    let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
                    for &(x, y) in &s.points {
                        if x.is_finite() && y.is_finite() {
                            runs.last_mut().expect("runs is never empty").push((x, y));
                        } else if !runs.last().expect("runs is never empty").is_empty() {
                            runs.push(Vec::new());
                        }
                    }
                    let mut last = None;
                    for run in runs.into_iter().filter(|r| !r.is_empty()) {
                        last = Some(if s.mark != Mark::Dashed {
                            chart
                                .draw_series(LineSeries::new(run, style))
                                .map_err(|e| e.to_string())?
                        } else {
                            chart
                                .draw_series(DashedLineSeries::new(run, 10, 6, style))
                                .map_err(|e| e.to_string())?
                        });
                    }
                    last
                }
                Mark::Bars => {
                    let mut xs: Vec<f64> = s
                        .points
                        .iter()
                        .map(|p| p.0)
                        .filter(|x| x.is_finite())
                        .collect();
                    xs.sort_by(f64::total_cmp);
                    let width = xs
                        .windows(2)
                        .map(|w| w[1] - w[0])
                        .filter(|d| *d > 0.0)
                        .fold(f64::INFINITY, f64::min);
                    let half = if width.is_finite() { width / 2.0 } else { 0.5 };
                    let fill = colour.mix(0.75).filled();
                    Some(
                        chart
                            .draw_series(
                                s.points
                                    .iter()
                                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                                    .map(|&(x, y)| {
                                        Rectangle::new([(x - half, 0.0), (x + half, y)], fill)
                                    }),
                            )
                            .map_err(|e| e.to_string())?,
                    )
                }
                // Nothing to mark, nothing to name in the legend (e.g. keyframes of a
                // mechanism's dense target, which has none).
                Mark::Points(_)
                    if !s.points.iter().any(|(x, y)| x.is_finite() && y.is_finite()) =>
                {
                    None
                }
                Mark::Points(r) => Some(
                    chart
                        .draw_series(
                            s.points
                                .iter()
                                .filter(|(x, y)| x.is_finite() && y.is_finite())
                                .map(|&p| Circle::new(p, r, colour.filled())),
                        )
                        .map_err(|e| e.to_string())?,
                ),
            };
            if let (Some(anno), false) = (anno, s.label.is_empty()) {
                any_label = true;
                anno.label(s.label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            }
        }
        if any_label {
            let font = TextStyle::from(("sans-serif", LEGEND_FONT_PX).into_font());
            let area = chart.plotting_area();
            let mut text_w = 0;
            let mut lines = 0;
            for label in self.legend_labels() {
                let (w, _) = area
                    .estimate_text_size(label, &font)
                    .map_err(|e| e.to_string())?;
                text_w = text_w.max(w as i32);
                lines += 1;
            }
            // plotters' box: the text, its 30 px sample area and a 10 px margin all round;
            // lines 1.25 font sizes apart.
            let legend = (
                text_w + 30 + 20,
                (f64::from(lines) * 1.25 * f64::from(LEGEND_FONT_PX)).ceil() as i32 + 20,
            );
            let corner = self.legend_corner((xr, yr), area.dim_in_pixel(), legend);
            chart
                .configure_series_labels()
                .position(corner)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", LEGEND_FONT_PX))
                .draw()
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}

/// The palette: colour-blind friendly (Okabe–Ito), cycled by index.
pub fn color(index: usize) -> RGBColor {
    const PALETTE: [RGBColor; 8] = [
        RGBColor(0, 114, 178),
        RGBColor(213, 94, 0),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
        RGBColor(230, 159, 0),
        RGBColor(86, 180, 233),
        RGBColor(0, 0, 0),
        RGBColor(240, 228, 66),
    ];
    PALETTE[index % PALETTE.len()]
}

/// Register the embedded font with plotters (idempotent).
pub fn register_font() {
    REGISTER.call_once(|| {
        if plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_err() {
            tracing::warn!("embedded plot font could not be registered; text may be missing");
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the y labels: a key point a rounding error below zero reads "0.0" (plotters
    /// printed "-0.0" on a height deviation chart), and other values read as plotters
    /// prints them.
    #[test]
    fn a_y_label_near_zero_reads_zero() {
        assert_eq!(y_label(-1.4e-17, 0.6), "0.0");
        assert_eq!(y_label(0.0, 0.6), "0.0");
        assert_eq!(y_label(-0.1, 0.6), "-0.1");
        assert_eq!(y_label(0.25, 0.6), "0.25");
        assert_eq!(y_label(14.0, 16.0), "14.0");
    }

    /// Guards the embedded font and both backends: a chart with a gap (NaN) and a reference
    /// line writes a PNG and an SVG that contain text.
    #[test]
    fn writes_png_and_svg_with_text() {
        let dir = tempfile::tempdir().unwrap();
        let pts: Vec<(f64, f64)> = (0..50)
            .map(|i| {
                let x = f64::from(i) / 10.0;
                (x, if i == 25 { f64::NAN } else { x.sin() })
            })
            .collect();
        let mut chart = Chart::new("sine", "x [rad]", "y [-]").with(Series::line("sin", pts, 0));
        chart.h_lines.push((-0.5, "limit".into()));
        let [png, svg] = chart.write(&dir.path().join("sine")).unwrap();
        assert!(std::fs::metadata(&png).unwrap().len() > 1000);
        let svg_text = std::fs::read_to_string(svg).unwrap();
        assert!(svg_text.contains("sine") && svg_text.contains("limit"));
    }

    /// Guards the legend: a point series with nothing to mark (a dense target's keyframes)
    /// gets no legend entry, while a drawn one keeps its entry.
    #[test]
    fn empty_point_series_has_no_legend_entry() {
        let dir = tempfile::tempdir().unwrap();
        let line: Vec<(f64, f64)> = (0..10).map(|i| (f64::from(i), f64::from(i))).collect();
        let chart = Chart::new("legend", "x", "y")
            .with(Series::line("target path", line, 0))
            .with(Series::points("keyframes", Vec::new(), 5, 1))
            .with(Series::points("measured", vec![(1.0, 2.0)], 2, 2));
        let [_, svg] = chart.write(&dir.path().join("l")).unwrap();
        let svg_text = std::fs::read_to_string(svg).unwrap();
        assert!(svg_text.contains("target path") && svg_text.contains("measured"));
        assert!(!svg_text.contains("keyframes"));
    }

    /// Guards the legend's placement: it goes to the corner where it hides no data, the
    /// upper right when that one is free (a falling line) and the upper left over a rising
    /// line's end (the follower chart hid its last 30° under the legend); a line through
    /// every corner but the lower left sends it there.
    #[test]
    fn legend_goes_where_it_hides_nothing() {
        let ranges = ((0.0, 10.0), (0.0, 10.0));
        let (plot, legend) = ((900, 500), (200, 80));
        let corner = |pts: Vec<(f64, f64)>| {
            Chart::new("c", "x", "y")
                .with(Series::line("data", pts, 0))
                .legend_corner(ranges, plot, legend)
        };
        let falling = corner(vec![(0.0, 10.0), (10.0, 0.0)]);
        assert!(matches!(falling, SeriesLabelPosition::UpperRight));
        let rising = corner(vec![(0.0, 0.0), (10.0, 10.0)]);
        assert!(matches!(rising, SeriesLabelPosition::UpperLeft));
        let around = corner(vec![(9.5, 0.0), (9.5, 9.5), (0.0, 9.5)]);
        assert!(
            matches!(around, SeriesLabelPosition::LowerLeft),
            "{around:?}"
        );
    }

    /// Guards the error path: a chart without finite data is an error, not a panic.
    #[test]
    fn empty_chart_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let chart =
            Chart::new("empty", "x", "y").with(Series::line("nan", vec![(f64::NAN, 1.0)], 0));
        assert!(matches!(
            chart.write(&dir.path().join("e")),
            Err(PlotError::Empty { .. })
        ));
    }
}
