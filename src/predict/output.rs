//! The files of a prediction: `prediction.json` and its charts.
//!
//! Owns [`write()`] and [`PREDICTION_FORMAT`]: `prediction.json`, the charts and
//! `prediction.md` (the figures and charts for a person). It draws the predicted deviation
//! from the target (forward and reverse) and the play over the driver angle, both with the
//! limits that matter marked, and the predicted laws over the target; for a 1R1T follower
//! also its predicted heights' deviation and the play of its slide and screws. It computes
//! nothing.

use std::path::{Path, PathBuf};

use serde_json::json;

use super::{Prediction, DRIVE_LOST_DEG, DRIVE_LOST_MM};
use crate::plot::{legend_room_y_range, Chart, PlotError, Series};

/// The `format` of `prediction.json`.
pub const PREDICTION_FORMAT: &str = "mpcmech-prediction/1";
/// The charts' x axis.
const X_LABEL: &str = "driver angle within the period [deg]";
/// The prediction's file name in its folder.
pub const PREDICTION_FILE: &str = "prediction.json";

/// Error writing a prediction.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file could not be written.
    #[error("cannot write {path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A chart could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// Write `prediction.json` and the charts into `out` (created if missing); returns the
/// files written.
pub fn write(
    p: &Prediction,
    mechanism: &Path,
    parts: &Path,
    out: &Path,
) -> Result<Vec<PathBuf>, OutputError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| OutputError::Io { path, error }
    };
    std::fs::create_dir_all(out).map_err(io(out))?;
    let mut files = Vec::new();
    let json_path = out.join(PREDICTION_FILE);
    let doc = json!({
        "format": PREDICTION_FORMAT,
        "mechanism": mechanism.display().to_string(),
        "parts": parts.display().to_string(),
        "drive_lost_play_deg": DRIVE_LOST_DEG,
        "free_cap_deg": super::FREE_CAP_DEG,
        "prediction": p,
    });
    let mut doc = doc;
    if p.slide.is_some() {
        doc["drive_lost_play_mm"] = json!(DRIVE_LOST_MM);
        doc["free_cap_mm"] = json!(super::FREE_CAP_MM);
    }
    let text = serde_json::to_string_pretty(&doc).expect("a prediction serializes");
    std::fs::write(&json_path, text + "\n").map_err(io(&json_path))?;
    files.push(json_path);

    let x = |f: &dyn Fn(&super::Sample) -> f64| -> Vec<(f64, f64)> {
        p.samples.iter().map(|s| (s.driver_deg, f(s))).collect()
    };
    let x_label = X_LABEL;
    let mut law = Chart::new(
        "Follower angle: target and predicted (drag load)",
        x_label,
        "follower angle [deg]",
    )
    .with(Series::dashed("target", x(&|s| s.target_deg), 0))
    .with(Series::line("driven forward", x(&|s| s.forward_deg), 1))
    .with(Series::line("driven in reverse", x(&|s| s.reverse_deg), 2));
    law.x_range = Some((0.0, 360.0));
    files.extend(law.write(&out.join("law"))?);

    let dev = deviation_chart(
        format!(
            "Predicted − target: worst {:.3}° at driver {:.1}°",
            p.worst_deviation.deg, p.worst_deviation.driver_deg
        ),
        "deviation [deg]",
        [
            x(&|s| s.forward_deg - s.target_deg),
            x(&|s| s.reverse_deg - s.target_deg),
        ],
        0.1,
    );
    files.extend(dev.write(&out.join("deviation"))?);

    let lost = p.samples.iter().filter(|s| s.drive_lost).count();
    let mut play = Chart::new(
        format!(
            "Play of the follower: worst {:.2}° at driver {:.1}°; drive lost at {lost} of {} angles",
            p.worst_play.deg,
            p.worst_play.driver_deg,
            p.samples.len()
        ),
        x_label,
        "free turn [deg]",
    )
    .with(Series::line("play (both ways)", x(&|s| s.play_deg), 0))
    .with(Series::line("free turn +", x(&|s| s.free_plus_deg), 1))
    .with(Series::line("free turn −", x(&|s| s.free_minus_deg), 2))
    .with(Series::points(
        "file: dist(t) > 0 (design contacts do not close)",
        p.samples
            .iter()
            .filter(|s| s.file_dist > 0.0)
            .map(|s| (s.driver_deg, 0.0))
            .collect(),
        3,
        3,
    ));
    play.x_range = Some((0.0, 360.0));
    // Headroom above the data for the legend (drawn in the upper right corner).
    let top = p.worst_play.deg.max(DRIVE_LOST_DEG);
    play.y_range = Some(legend_room_y_range(0.0, top));
    play.h_lines = vec![(DRIVE_LOST_DEG, "drive lost above".to_string())];
    files.extend(play.write(&out.join("play"))?);

    if let Some(slide) = &p.slide {
        let mm = |f: &dyn Fn(&super::Sample) -> Option<f64>| -> Vec<(f64, f64)> {
            p.samples
                .iter()
                .filter_map(|s| f(s).map(|v| (s.driver_deg, v)))
                .collect()
        };
        let dev_mm = |forward: bool| {
            mm(&move |s: &super::Sample| {
                let h = if forward { s.forward_mm } else { s.reverse_mm };
                Some(h? - s.target_mm?)
            })
        };
        let height = deviation_chart(
            format!(
                "Predicted − target height: worst {:.3} mm at driver {:.1}°",
                slide.worst_height_deviation.mm, slide.worst_height_deviation.driver_deg
            ),
            "height deviation [mm]",
            [dev_mm(true), dev_mm(false)],
            0.01,
        );
        files.extend(height.write(&out.join("height"))?);

        let mut slide_play = Chart::new(
            format!(
                "Free slide and screw: worst slide {:.3} mm (driver {:.1}°), screw {:.3} mm ({:.1}°)",
                slide.worst_slide_play.mm,
                slide.worst_slide_play.driver_deg,
                slide.worst_screw_play.mm,
                slide.worst_screw_play.driver_deg
            ),
            x_label,
            format!("free motion [mm; a turn counts at {} mm]", slide.lever_mm),
        )
        .with(Series::line(
            "slide (both ways)",
            mm(&|s| s.slide_play_mm),
            0,
        ))
        .with(Series::line(
            "screws (the larger)",
            mm(&|s| s.screw_play_mm),
            1,
        ))
        .with(Series::line(
            "turn (both ways)",
            x(&|s| s.play_deg.to_radians() * slide.lever_mm),
            2,
        ));
        slide_play.x_range = Some((0.0, 360.0));
        let top = slide
            .worst_slide_play
            .mm
            .max(slide.worst_screw_play.mm)
            .max(p.worst_play.deg.to_radians() * slide.lever_mm)
            .max(DRIVE_LOST_MM);
        slide_play.y_range = Some(legend_room_y_range(0.0, top));
        slide_play.h_lines = vec![(DRIVE_LOST_MM, "drive lost above".to_string())];
        files.extend(slide_play.write(&out.join("play-slide"))?);
    }

    let md_path = out.join("prediction.md");
    std::fs::write(&md_path, markdown(p, mechanism, parts)).map_err(io(&md_path))?;
    files.push(md_path);
    Ok(files)
}

/// A chart of the predicted deviations from the target over the driver angle, forward and
/// reverse, the target's zero marked, at least `min_span` tall.
fn deviation_chart(
    title: String,
    y_label: &str,
    [forward, reverse]: [Vec<(f64, f64)>; 2],
    min_span: f64,
) -> Chart {
    let (low, high) = forward
        .iter()
        .chain(&reverse)
        .fold((0.0f64, 0.0f64), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    let mut chart = Chart::new(title, X_LABEL, y_label)
        .with(Series::line("driven forward", forward, 1))
        .with(Series::line("driven in reverse", reverse, 2));
    chart.x_range = Some((0.0, 360.0));
    chart.y_range = Some(legend_room_y_range(low, (high - low).max(min_span)));
    chart.h_lines = vec![(0.0, "target".to_string())];
    chart
}

/// `prediction.md`: the figures and charts for a person.
fn markdown(p: &Prediction, mechanism: &Path, parts: &Path) -> String {
    let lost = p.samples.iter().filter(|s| s.drive_lost).count();
    let n = p.samples.len();
    let mut md = format!(
        "# Predicted motion of the built parts\n\n\
         Mechanism `{}`, parts `{}` (clearance {:.2} mm{}), {n} driver angles, {} load \
         (docs/simulate.md).\n\n",
        mechanism.display(),
        parts.display(),
        p.clearance_mm,
        p.without_pair
            .map_or(String::new(), |k| format!(", without curve pair {k}")),
        p.load
    );
    let (held, lost_by) = match &p.slide {
        None => (
            format!("play ≤ {DRIVE_LOST_DEG}°"),
            format!("play > {DRIVE_LOST_DEG}°"),
        ),
        Some(s) => (
            format!(
                "play along every line of the free region ≤ {DRIVE_LOST_MM:.2} mm, a turn \
                 counting at {} mm: {DRIVE_LOST_DEG}°",
                s.lever_mm
            ),
            format!(
                "play along a line of the free region > {DRIVE_LOST_MM:.2} mm, a turn \
                 counting at {} mm: {DRIVE_LOST_DEG}°",
                s.lever_mm
            ),
        ),
    };
    if lost == 0 {
        md += &format!("**The driver holds the follower at every angle** ({held}).\n\n");
    } else {
        md += &format!(
            "**The drive is lost at {lost} of {n} angles** ({lost_by}): driver {}.\n\n",
            p.lost_windows_text()
        );
    }
    md += &format!(
        "| figure | value | at driver |\n|---|---|---|\n\
         | worst play{} | {:.3}° | {:.2}° |\n\
         | worst deviation from the target | {:.3}° | {:.2}° |\n\
         | deepest overlap of the meshes at the design pose, where it would stop the follower | {:.3} mm | {:.2}° |\n\n",
        if p.slide.is_some() {
            " of the turn"
        } else {
            ""
        },
        p.worst_play.deg,
        p.worst_play.driver_deg,
        p.worst_deviation.deg,
        p.worst_deviation.driver_deg,
        p.overlap_mm,
        p.overlap_driver_deg
    );
    if let Some(s) = &p.slide {
        md.truncate(md.len() - 1);
        md += &format!(
            "| worst play of the slide | {:.3} mm | {:.2}° |\n\
             | worst play along a screw (a turn counting at {} mm) | {:.3} mm | {:.2}° |\n\
             | worst height deviation from the target | {:.3} mm | {:.2}° |\n\n",
            s.worst_slide_play.mm,
            s.worst_slide_play.driver_deg,
            s.lever_mm,
            s.worst_screw_play.mm,
            s.worst_screw_play.driver_deg,
            s.worst_height_deviation.mm,
            s.worst_height_deviation.driver_deg
        );
    }
    md += "At the mechanism file's samples, the parts' drive against the paper's closure:\n\n\
           | closure from | lost by both | lost by it only | lost by the parts only | held by both |\n\
           |---|---|---|---|---|\n";
    for (what, c) in [
        ("the file's contacts", &p.closure),
        ("the contacts the build kept", &p.kept_closure),
    ] {
        md += &format!(
            "| {what} | {} | {} | {} | {} |\n",
            c.lost_both, c.lost_by_file_only, c.lost_by_parts_only, c.held_both
        );
    }
    md += "\n![deviation](deviation.svg)\n\n![play](play.svg)\n\n![law](law.svg)\n\n";
    if p.slide.is_some() {
        md += "![height](height.svg)\n\n![play of the slide and screws](play-slide.svg)\n\n";
    }
    md += &format!(
        "{} + {} vertices (driver + follower), {} mesh distance queries, {:.1} s.\n",
        p.vertices[0], p.vertices[1], p.queries, p.seconds
    );
    md
}
