//! The campaign's figures: each per-robot metric against each numeric axis, the mean over the
//! seeds of every point with its 95 % confidence interval as an error bar, one line per robot
//! (and per combination of the other axes), PNG and SVG.

use std::path::Path;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use super::plan::{labels_and_robots, toml_cell, Aggregate, Plan};
use fdi_common::field_path::show;
use fdi_report::plot::{FONT, PALETTE};

/// The marker of a line's points: the palette's colours come round again every
/// `PALETTE.len()` lines, each time with the next shape, so that no two lines of a figure look
/// alike up to `PALETTE.len() × 4` lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    Circle,
    Square,
    Triangle,
    Cross,
}

impl Shape {
    /// The marker at `at` (pixels from its anchor), filled with `color` (a cross is drawn).
    fn at<DB: DrawingBackend>(
        self,
        (x, y): (i32, i32),
        color: RGBColor,
    ) -> DynElement<'static, DB, (i32, i32)> {
        let fill = color.filled();
        match self {
            Self::Circle => Circle::new((x, y), 3, fill).into_dyn(),
            Self::Square => Rectangle::new([(x - 3, y - 3), (x + 3, y + 3)], fill).into_dyn(),
            Self::Triangle => TriangleMarker::new((x, y), 4, fill).into_dyn(),
            Self::Cross => Cross::new((x, y), 4, color.stroke_width(2)).into_dyn(),
        }
    }
}

/// Error bars of `points`: each interval, capped at both ends by `cap` either side.
fn error_bars(points: &[Mark], cap: f64) -> Vec<Vec<(f64, f64)>> {
    let mut bars = Vec::new();
    for &(x, _, ci) in points {
        if let Some((lo, hi)) = ci {
            bars.push(vec![(x, lo), (x, hi)]);
            bars.push(vec![(x - cap, lo), (x + cap, lo)]);
            bars.push(vec![(x - cap, hi), (x + cap, hi)]);
        }
    }
    bars
}

/// The colour and marker of line `i` of a figure.
fn style_of(i: usize) -> (RGBColor, Shape) {
    const SHAPES: [Shape; 4] = [Shape::Circle, Shape::Square, Shape::Triangle, Shape::Cross];
    (
        PALETTE[i % PALETTE.len()],
        SHAPES[(i / PALETTE.len()) % SHAPES.len()],
    )
}

/// One point of a line: x, the mean, and its confidence interval when there is one.
type Mark = (f64, f64, Option<(f64, f64)>);

/// One line of a figure.
struct Series {
    label: String,
    points: Vec<Mark>,
}

struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    series: Vec<Series>,
}

/// The unit a name's suffix gives (`_rad_s`, `_rad`, `_s`, `_nm`, `_per_min`), if any.
fn unit_of(name: &str) -> Option<&'static str> {
    [
        ("_rad_s", "rad/s"),
        ("_rad", "rad"),
        ("_per_min", "per min"),
        ("_nm", "N·m"),
        ("_s", "s"),
    ]
    .into_iter()
    .find(|(suffix, _)| name.ends_with(suffix))
    .map(|(_, unit)| unit)
}

/// A per-robot metric as the reports name it, with its unit: `rmse_rad` → `RMSE of the
/// tracking error (rad)`, `detectors.chi2.coverage` → `χ²: coverage (share of the attacked
/// ticks alarmed)`.
fn metric_label(f: &str) -> String {
    let plain = match f {
        "rmse_rad" => Some("RMSE of the tracking error (rad)"),
        "max_abs_error_rad" => Some("largest |tracking error| (rad)"),
        "deadline_misses" => Some("deadline misses (ticks)"),
        _ => None,
    };
    if let Some(p) = plain {
        return p.into();
    }
    if let Some((d, m)) = f.strip_prefix("detectors.").and_then(|r| r.split_once('.')) {
        let what = match m {
            "onsets.mean_time_to_detect_s" => "mean time to detect an onset (s)",
            "false_alarms" => "false alarms (count)",
            "coverage" => "coverage (share of the attacked ticks alarmed)",
            "false_alarms_per_min" => "false alarms per minute",
            other => other,
        };
        return format!("{}: {what}", fdi_common::detect::title(d).unwrap_or(d));
    }
    match unit_of(f) {
        Some(u) => format!("{f} ({u})"),
        None => f.into(),
    }
}

/// A campaign axis (a field path) as the reports name it: `controller.beta` → `β, the
/// controller's gain (controller.beta)`; other paths with the unit of their name.
fn axis_label(path: &str) -> String {
    let named = match path {
        "controller.beta" => Some("β, the controller's gain"),
        "controller.alpha" => Some("α, the controller's gain"),
        "controller.k" => Some("k, the controller's gain"),
        "seed" => Some("seed"),
        _ => None,
    };
    match (named, unit_of(path)) {
        (Some(n), _) if n == path => n.into(),
        (Some(n), _) => format!("{n} ({path})"),
        (None, Some(u)) => format!("{path} ({u})"),
        (None, None) => path.into(),
    }
}

/// Two lines closer than this share of the y-axis at every point are one line to the eye;
/// a confidence interval shorter than it is hidden under its marker.
const UNSEEN: f64 = 0.01;

/// What a reader cannot see on the figure, said under it: lines that lie on one another (at
/// every point within [`UNSEEN`] of the y-axis), and confidence intervals too short to show.
fn notes(series: &[Series]) -> Vec<String> {
    let mut out = Vec::new();
    let (lo, hi) = series
        .iter()
        .flat_map(|s| &s.points)
        .fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            (lo.min(p.1), hi.max(p.1))
        });
    let span = (hi - lo).abs().max(hi.abs() * 1e-3).max(1e-300);
    let same = |a: &Series, b: &Series| {
        a.points.len() == b.points.len()
            && a.points
                .iter()
                .zip(&b.points)
                .all(|(p, q)| p.0 == q.0 && (p.1 - q.1).abs() <= UNSEEN * span)
    };
    for (i, a) in series.iter().enumerate() {
        let twins: Vec<&str> = series[i + 1..]
            .iter()
            .filter(|b| same(a, b))
            .map(|b| b.label.as_str())
            .collect();
        if !twins.is_empty() && !series[..i].iter().any(|b| same(a, b)) {
            out.push(format!(
                "{} and {} lie on one another (within {} % of the y-axis at every point)",
                a.label,
                twins.join(", "),
                UNSEEN * 100.0
            ));
        }
    }
    let widths: Vec<f64> = series
        .iter()
        .flat_map(|s| &s.points)
        .filter_map(|p| p.2.map(|(l, h)| h - l))
        .collect();
    let hidden = widths.iter().filter(|w| **w < UNSEEN * span).count();
    if widths.is_empty() {
        out.push("no confidence interval: one seed per point".into());
    } else if hidden == widths.len() {
        let widest = widths.iter().copied().fold(0.0, f64::max);
        out.push(format!(
            "the 95 % confidence intervals are too short to show (at most {widest:.3e} wide)"
        ));
    } else if hidden > 0 {
        out.push(format!(
            "where a point shows no error bar ({hidden} of {}), its 95 % confidence interval is \
             shorter than the marker",
            widths.len()
        ));
    }
    out
}

/// The notes of `series` ([`notes`]) at the foot of `area`; the area above them.
fn draw_notes<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    series: &[Series],
) -> Result<DrawingArea<DB, plotters::coord::Shift>>
where
    DB::ErrorType: 'static,
{
    let lines: Vec<String> = notes(series)
        .iter()
        .flat_map(|n| wrap(&format!("Note: {n}"), NOTE_CHARS))
        .collect();
    let (_, h) = area.dim_in_pixel();
    for (i, n) in lines.iter().enumerate() {
        let y = h as i32 - 8 - 16 * (lines.len() - i) as i32;
        area.draw(&Text::new(
            n.clone(),
            (14, y),
            (FONT, 13).into_font().color(&RGBColor(90, 90, 90)),
        ))
        .map_err(err)?;
    }
    Ok(area.margin(0, 16 * lines.len() as i32, 0, 0))
}

/// The longest line of a note under a figure (13 px text on 900 px).
const NOTE_CHARS: usize = 120;

/// `text` in lines of at most `width` characters, broken at spaces (a longer word on its own
/// line), the lines after the first indented.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        if !line.trim().is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::replace(&mut line, "    ".into()));
        }
        if !line.is_empty() && !line.ends_with("    ") {
            line.push(' ');
        }
        line.push_str(word);
    }
    lines.push(line);
    lines
}

/// A label without its parenthesised tail: `RMSE of the tracking error (rad)` → `RMSE of the
/// tracking error`.
fn short_label(label: &str) -> &str {
    label.split(" (").next().unwrap_or(label)
}

fn file_stem(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes every figure into `dir`.
pub(super) fn write_all(
    plan: &Plan,
    aggregate: &[Aggregate],
    families: &[String],
    dir: &Path,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let (labels, ids) = labels_and_robots(plan, aggregate);
    let seeds = plan.seeds;
    for (ai, axis) in labels.iter().enumerate() {
        // Only an axis of numbers has an x-axis.
        if aggregate
            .iter()
            .any(|a| toml_cell(&a.point.values[ai].1).num().is_none())
        {
            continue;
        }
        for f in families {
            let mut series: Vec<Series> = Vec::new();
            for id in &ids {
                for a in aggregate {
                    let others: Vec<String> = a
                        .point
                        .values
                        .iter()
                        .enumerate()
                        .filter(|(j, _)| *j != ai)
                        .map(|(_, (l, v))| format!("{l} = {}", show(v)))
                        .collect();
                    let label = if others.is_empty() {
                        format!("robot {id}")
                    } else {
                        format!("robot {id}, {}", others.join(", "))
                    };
                    let Some(x) = toml_cell(&a.point.values[ai].1).num() else {
                        continue;
                    };
                    let Some(s) = a.metrics.get(&format!("robot{id}.{f}")).copied().flatten()
                    else {
                        continue;
                    };
                    let ci = s.ci_low.zip(s.ci_high);
                    match series.iter_mut().find(|l| l.label == label) {
                        Some(l) => l.points.push((x, s.mean, ci)),
                        None => series.push(Series {
                            label,
                            points: vec![(x, s.mean, ci)],
                        }),
                    }
                }
            }
            for s in &mut series {
                s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
            }
            if series.is_empty() {
                continue;
            }
            let chart = Chart {
                title: format!(
                    "{}: {} vs {} (mean, 95 % CI over {seeds} seed{})",
                    plan.name,
                    short_label(&metric_label(f)),
                    short_label(&axis_label(axis)),
                    if seeds == 1 { "" } else { "s" }
                ),
                x_label: axis_label(axis),
                y_label: metric_label(f),
                series,
            };
            save(
                &chart,
                &dir.join(format!("{}-vs-{}", file_stem(f), file_stem(axis))),
            )?;
        }
    }
    Ok(())
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("drawing a campaign figure: {e}")
}

/// The figure as SVG, and as PNG rasterised from it ([`fdi_report::plot::write_figure`]).
fn save(chart: &Chart, stem: &Path) -> Result<()> {
    fdi_report::plot::fonts()?;
    let (w, h) = (900u32, 580u32);
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(&area, chart)?;
        area.present().map_err(err)?;
    }
    fdi_report::plot::write_figure(stem, svg, (w, h)).map(drop)
}

fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>, c: &Chart) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(err)?;
    let area = &draw_notes(area, &c.series)?;
    let pts = c.series.iter().flat_map(|s| &s.points);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, m, ci) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        let (lo, hi) = ci.unwrap_or((m, m));
        y0 = y0.min(lo.min(m));
        y1 = y1.max(hi.max(m));
    }
    let pad = |a: f64, b: f64| {
        let span = (b - a).abs();
        let m = if span > 0.0 {
            span * 0.08
        } else {
            a.abs().max(1e-9) * 0.1
        };
        (a - m, b + m)
    };
    let (x0, x1) = pad(x0, x1);
    let (x0, x1) = fdi_report::plot::drawable(x0, x1);
    let (y0, y1) = pad(y0, y1);
    let (y0, y1) = fdi_report::plot::drawable(y0, y1);
    let mut chart = ChartBuilder::on(area)
        .caption(&c.title, (FONT, 17))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(78)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(&c.x_label)
        .y_desc(&c.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(err)?;
    for (i, s) in c.series.iter().enumerate() {
        let (color, shape) = style_of(i);
        let line: Vec<(f64, f64)> = s.points.iter().map(|&(x, m, _)| (x, m)).collect();
        chart
            .draw_series(LineSeries::new(line.clone(), color.stroke_width(2)))
            .map_err(err)?
            .label(&s.label)
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(0, 0), (18, 0)], color.stroke_width(2))
                    + shape.at((9, 0), color)
            });
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, m)| EmptyElement::at((x, m)) + shape.at((0, 0), color)),
            )
            .map_err(err)?;
        chart
            .draw_series(
                error_bars(&s.points, (x1 - x0) * 0.006)
                    .into_iter()
                    .map(|p| PathElement::new(p, color.stroke_width(1))),
            )
            .map_err(err)?;
    }
    fdi_report::plot::draw_legend(&mut chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(label: &str, points: &[Mark]) -> Series {
        Series {
            label: label.into(),
            points: points.to_vec(),
        }
    }

    #[test]
    fn notes_are_wrapped_at_spaces() {
        assert_eq!(wrap("a bb ccc dd", 6), ["a bb", "    ccc", "    dd"]);
        assert_eq!(wrap("short", 120), ["short"]);
    }

    #[test]
    fn labels_are_the_reports_names_with_units() {
        assert_eq!(metric_label("rmse_rad"), "RMSE of the tracking error (rad)");
        assert_eq!(
            metric_label("detectors.chi2.onsets.mean_time_to_detect_s"),
            "χ²: mean time to detect an onset (s)"
        );
        assert_eq!(
            axis_label("controller.beta"),
            "β, the controller's gain (controller.beta)"
        );
        assert_eq!(
            axis_label("agents[2].delay.offset_s"),
            "agents[2].delay.offset_s (s)"
        );
        assert_eq!(
            short_label(&metric_label("rmse_rad")),
            "RMSE of the tracking error"
        );
    }

    #[test]
    fn lines_on_one_another_and_hidden_intervals_are_said() {
        let a = series(
            "robot 1",
            &[(1.0, 1.0, Some((0.999, 1.001))), (2.0, 2.0, None)],
        );
        let b = series(
            "robot 3",
            &[(1.0, 1.001, Some((1.0, 1.002))), (2.0, 2.0, None)],
        );
        let c = series("robot 2", &[(1.0, 1.5, Some((1.0, 2.0))), (2.0, 1.8, None)]);
        let n = notes(&[a, b, c]);
        assert!(
            n[0].starts_with("robot 1 and robot 3 lie on one another"),
            "{n:?}"
        );
        assert!(n[1].contains("(2 of 3)"), "{n:?}");
        let apart = notes(&[
            series("robot 1", &[(1.0, 1.0, None)]),
            series("robot 2", &[(1.0, 2.0, None)]),
        ]);
        assert_eq!(apart, ["no confidence interval: one seed per point"]);
    }

    #[test]
    fn no_two_of_the_first_twenty_four_lines_look_alike_and_a_figure_of_them_draws() {
        let styles: Vec<(RGBColor, Shape)> = (0..PALETTE.len() * 4).map(style_of).collect();
        for (i, a) in styles.iter().enumerate() {
            for b in &styles[i + 1..] {
                assert!(a != b, "lines {i} and another share {a:?}");
            }
        }
        assert_eq!(style_of(6), (PALETTE[0], Shape::Square));
        // Eight lines (two robots × four values of another axis) into an SVG.
        let chart = Chart {
            title: "eight lines".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: (0..8)
                .map(|k| {
                    let y = f64::from(k);
                    series(
                        &format!("line {k}"),
                        &[(1.0, y, Some((y - 0.1, y + 0.1))), (2.0, y + 0.5, None)],
                    )
                })
                .collect(),
        };
        let svg_of = |c: &Chart| {
            let mut svg = String::new();
            {
                fdi_report::plot::fonts().expect("fonts");
                let area = SVGBackend::with_string(&mut svg, (640, 480)).into_drawing_area();
                draw(&area, c).expect("drawn");
            }
            svg
        };
        // Squares in the first colour: the 7th line's two points and its legend entry, none
        // while the figure has six lines.
        let (r, g, b) = (PALETTE[0].0, PALETTE[0].1, PALETTE[0].2);
        let fill = format!("fill=\"#{r:02X}{g:02X}{b:02X}\"");
        let squares = |svg: &str| {
            svg.lines()
                .filter(|l| l.contains("<rect") && l.contains(&fill))
                .count()
        };
        assert_eq!(squares(&svg_of(&chart)), 3);
        let six = Chart {
            series: chart.series[..6]
                .iter()
                .map(|s| series(&s.label, &s.points))
                .collect(),
            ..chart
        };
        assert_eq!(squares(&svg_of(&six)), 0);
    }
}
