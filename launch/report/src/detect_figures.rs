//! The figures of `detect`: the ROC curves and the detection delay against the false-positive
//! rate, one curve per detector (pooled over the robots), its configured threshold marked by a
//! diamond. Drawn by [`crate::plot`], as every figure of the launcher.

use fdi_common::detect::sweep::{Point, Tally};
use fdi_common::detect::{self, S_HAT_NORM};
use plotters::style::RGBColor;

use crate::plot::{Figure, Line, Panel, PanelKind, PALETTE};

/// One detector's sweep.
#[derive(Debug)]
pub struct Swept {
    pub name: &'static str,
    pub points: Vec<Point>,
}

/// Pixels of `roc.png` (and the SVG's size).
pub const ROC_SIZE: (u32, u32) = (1000, 720);
/// Pixels of `delay.png`.
pub const DELAY_SIZE: (u32, u32) = (1000, 900);

const GREY: RGBColor = RGBColor(150, 150, 150);
const X_LABEL: &str =
    "false-positive rate (share of the attack-free ticks watched with the alarm on)";
/// The x-axis: rates from 0 to 1, with room for the markers at the edges.
const X_RANGE: (f64, f64) = (-0.02, 1.02);

/// The legend name of a detector.
fn label(name: &str) -> String {
    match (name, detect::title(name)) {
        (S_HAT_NORM, _) => "‖Ŝ‖ held (s_hat_norm)".into(),
        (_, Some(title)) => format!("{title} ({name})"),
        (other, None) => other.into(),
    }
}

/// A threshold in a legend: three significant digits.
pub fn short(x: f64) -> String {
    if x != 0.0 && !(1e-2..1e5).contains(&x.abs()) {
        format!("{x:.2e}")
    } else {
        let s = format!("{x:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// A closed diamond around `(x, y)`, half-widths `dx`, `dy` in data units.
fn diamond(x: f64, y: f64, dx: f64, dy: f64) -> Vec<(f64, f64)> {
    vec![
        (x - dx, y),
        (x, y + dy),
        (x + dx, y),
        (x, y - dy),
        (x - dx, y),
    ]
}

/// Per detector: its colour, its curve of `y` against the FPR over the thresholds where both
/// are defined (thresholds descending, so the FPR ascends), and the point of its configured
/// threshold.
#[allow(clippy::type_complexity)]
fn curves(
    swept: &[Swept],
    y: impl Fn(&Tally) -> Option<f64>,
) -> Vec<(&Swept, RGBColor, Vec<(f64, f64)>, Option<(f64, f64, f64)>)> {
    let at = |p: &Point| Some((p.pooled.fpr()?, y(&p.pooled)?));
    swept
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let points: Vec<(f64, f64)> = s.points.iter().rev().filter_map(at).collect();
            if points.is_empty() {
                return None;
            }
            let configured = s
                .points
                .iter()
                .find(|p| p.configured)
                .and_then(|p| at(p).map(|(x, v)| (p.threshold, x, v)));
            Some((s, PALETTE[i % PALETTE.len()], points, configured))
        })
        .collect()
}

/// The lines of one panel: each detector's curve and its configured point, diamonds of
/// half-height `dy`.
fn lines(swept: &[Swept], y: impl Fn(&Tally) -> Option<f64>, dy: f64) -> Vec<Line> {
    let mut out = Vec::new();
    for (s, color, points, configured) in curves(swept, y) {
        out.push(Line {
            label: label(s.name),
            color,
            points,
            keep: true,
            dashed: false,
        });
        if let Some((threshold, x, v)) = configured {
            out.push(Line {
                label: format!("◇ at its threshold {}", short(threshold)),
                color,
                points: diamond(x, v, 0.012, dy),
                keep: true,
                dashed: false,
            });
        }
    }
    out
}

/// `roc`: the true- against the false-positive rate per tick; `None` when no threshold has both.
pub fn roc(swept: &[Swept], title: &str) -> Option<Figure> {
    let curves = lines(swept, Tally::tpr, 0.016);
    if curves.is_empty() {
        return None;
    }
    // The diagonal, dashed and drawn over the curves: a detector whose alarm is on or off
    // whatever the attack does lies on it, and would hide it.
    let mut lines = vec![Line {
        label: "chance: TPR = FPR (dashed)".into(),
        color: GREY,
        points: vec![(0.0, 0.0), (1.0, 1.0)],
        keep: true,
        dashed: true,
    }];
    lines.extend(curves);
    Some(Figure {
        title: format!("ROC per tick: {title}"),
        x_label: X_LABEL.into(),
        x_range: X_RANGE,
        markers: Vec::new(),
        marker_label: String::new(),
        panels: vec![Panel {
            title: "one point per threshold".into(),
            y_label: "true-positive rate (share of in-force ticks alarmed)".into(),
            kind: PanelKind::Lines(lines),
            guides: Vec::new(),
        }],
    })
}

/// `delay`: the mean detection delay over the detected onsets, and the share of onsets
/// detected, against the false-positive rate; `None` when no threshold detected an onset.
pub fn delay(swept: &[Swept], title: &str) -> Option<Figure> {
    let top = swept
        .iter()
        .flat_map(|s| &s.points)
        .filter_map(|p| p.pooled.mean_delay_s())
        .fold(0.0f64, f64::max);
    let delays = lines(swept, Tally::mean_delay_s, 0.02 * top.max(1e-3));
    if delays.is_empty() {
        return None;
    }
    let share = |t: &Tally| (t.onsets > 0).then(|| t.detected as f64 / t.onsets as f64);
    let shares = lines(swept, share, 0.016);
    Some(Figure {
        title: format!("Detection delay against false-positive rate: {title}"),
        x_label: X_LABEL.into(),
        x_range: X_RANGE,
        markers: Vec::new(),
        marker_label: String::new(),
        panels: vec![
            Panel {
                title: "mean delay from an onset to its first alarm (detected onsets only)".into(),
                y_label: "mean detection delay (s)".into(),
                kind: PanelKind::Lines(delays),
                guides: Vec::new(),
            },
            Panel {
                title: "onsets detected while the attack was in force".into(),
                y_label: "share of onsets detected".into(),
                kind: PanelKind::Lines(shares),
                guides: Vec::new(),
            },
        ],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_in_legends_are_short() {
        assert_eq!(short(0.6), "0.6");
        assert_eq!(short(33.376), "33.376");
        assert_eq!(short(15.0), "15");
        assert_eq!(short(0.0), "0");
        assert_eq!(short(1.5e-4), "1.50e-4");
    }
}
