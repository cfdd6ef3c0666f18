//! The campaign's figures: each per-robot metric against each numeric axis, the mean over the
//! seeds of every point with its 95 % confidence interval as an error bar, one line per robot
//! (and per combination of the other axes), PNG and SVG.

use std::path::Path;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use super::plan::{labels_and_robots, toml_cell, Aggregate, Plan};
use fdi_common::field_path::show;
use fdi_report::plot::{FONT, PALETTE};

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
                    "{}: {f} vs {axis} (mean, 95 % CI over {seeds} seed{})",
                    plan.name,
                    if seeds == 1 { "" } else { "s" }
                ),
                x_label: axis.to_string(),
                y_label: f.clone(),
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

fn save(chart: &Chart, stem: &Path) -> Result<()> {
    fdi_report::plot::fonts()?;
    let (w, h) = (900u32, 560u32);
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let area = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(&area, chart)?;
        area.present().map_err(err)?;
    }
    fdi_report::plot::write_png(&stem.with_extension("png"), &rgb, (w, h))?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(&area, chart)?;
        area.present().map_err(err)?;
    }
    let p = stem.with_extension("svg");
    std::fs::write(&p, svg).with_context(|| format!("writing {}", p.display()))
}

fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, plotters::coord::Shift>, c: &Chart) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(err)?;
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
        let color = PALETTE[i % PALETTE.len()];
        let line: Vec<(f64, f64)> = s.points.iter().map(|&(x, m, _)| (x, m)).collect();
        chart
            .draw_series(LineSeries::new(line.clone(), color.stroke_width(2)))
            .map_err(err)?
            .label(&s.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        chart
            .draw_series(
                line.iter()
                    .map(|&(x, m)| Circle::new((x, m), 3, color.filled())),
            )
            .map_err(err)?;
        // Error bars: the interval, capped at both ends (caps a fixed share of the x-axis).
        let cap = (x1 - x0) * 0.006;
        let mut bars = Vec::new();
        for &(x, _, ci) in &s.points {
            if let Some((lo, hi)) = ci {
                bars.push(vec![(x, lo), (x, hi)]);
                bars.push(vec![(x - cap, lo), (x + cap, lo)]);
                bars.push(vec![(x - cap, hi), (x + cap, hi)]);
            }
        }
        chart
            .draw_series(
                bars.into_iter()
                    .map(|p| PathElement::new(p, color.stroke_width(1))),
            )
            .map_err(err)?;
    }
    fdi_report::plot::draw_legend(&mut chart)
}
