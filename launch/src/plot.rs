//! Figures as data ([`Figure`], [`BarChart`]) and their rendering to PNG and SVG with plotters.
//!
//! Text is drawn with the DejaVu Sans font embedded in the binary (`src/fonts/`, Bitstream Vera
//! license), so figures render the same on a machine without any system font. PNG files are
//! encoded with the `png` crate from plotters' RGB buffer.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");

/// Colours of successive series (a colour-blind-safe palette).
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(230, 159, 0),
];
const MARKER: RGBColor = RGBColor(150, 150, 150);

fn fonts() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded figure font cannot be read"))
    }
}

/// One curve: points in time order.
#[derive(Debug, Clone)]
pub struct Line {
    pub label: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64)>,
}

/// A row of a timeline panel: the intervals during which something held.
#[derive(Debug, Clone)]
pub struct Band {
    pub label: String,
    pub color: RGBColor,
    pub intervals: Vec<(f64, f64)>,
}

#[derive(Debug, Clone)]
pub enum PanelKind {
    Lines(Vec<Line>),
    Timeline(Vec<Band>),
}

/// One chart of a figure, sharing the figure's time axis.
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub y_label: String,
    pub kind: PanelKind,
}

/// Panels stacked vertically over a common time axis.
#[derive(Debug, Clone)]
pub struct Figure {
    pub title: String,
    pub x_label: String,
    pub x_range: (f64, f64),
    /// Times drawn as thin vertical lines in every panel (attack switches).
    pub markers: Vec<f64>,
    pub panels: Vec<Panel>,
}

/// Grouped bars: one group per category, one bar per series.
#[derive(Debug, Clone)]
pub struct BarChart {
    pub title: String,
    pub y_label: String,
    pub categories: Vec<String>,
    /// (label, colour, one value per category).
    pub series: Vec<(String, RGBColor, Vec<f64>)>,
}

/// Min/max decimation: every `stride` samples become the smallest and the largest of them, in
/// time order, so that short spikes survive the downsampling. Non-finite samples are skipped.
#[derive(Debug, Clone)]
pub struct Envelope {
    stride: usize,
    n: usize,
    lo: (f64, f64),
    hi: (f64, f64),
    points: Vec<(f64, f64)>,
}

impl Envelope {
    pub fn new(stride: usize, expected_samples: u64) -> Self {
        let stride = stride.max(1);
        let cap = usize::try_from(expected_samples / stride as u64 * 2 + 2).unwrap_or(0);
        Self {
            stride,
            n: 0,
            lo: (0.0, f64::INFINITY),
            hi: (0.0, f64::NEG_INFINITY),
            points: Vec::with_capacity(cap.min(1 << 20)),
        }
    }

    pub fn push(&mut self, t: f64, v: f64) {
        if !v.is_finite() {
            return;
        }
        if v < self.lo.1 {
            self.lo = (t, v);
        }
        if v > self.hi.1 {
            self.hi = (t, v);
        }
        self.n += 1;
        if self.n == self.stride {
            self.flush();
        }
    }

    fn flush(&mut self) {
        if self.n == 0 {
            return;
        }
        let (a, b) = if self.lo.0 <= self.hi.0 {
            (self.lo, self.hi)
        } else {
            (self.hi, self.lo)
        };
        self.points.push(a);
        if b != a {
            self.points.push(b);
        }
        self.n = 0;
        self.lo = (0.0, f64::INFINITY);
        self.hi = (0.0, f64::NEG_INFINITY);
    }

    pub fn finish(mut self) -> Vec<(f64, f64)> {
        self.flush();
        self.points
    }
}

/// Intervals during which a flag sampled at successive times held.
#[derive(Debug, Clone, Default)]
pub struct Intervals {
    open: Option<f64>,
    last_t: f64,
    done: Vec<(f64, f64)>,
}

impl Intervals {
    pub fn push(&mut self, t: f64, on: bool) {
        match (self.open, on) {
            (None, true) => self.open = Some(t),
            (Some(a), false) => {
                self.done.push((a, t));
                self.open = None;
            }
            _ => {}
        }
        self.last_t = t;
    }

    /// `end`: the time the last sample holds until.
    pub fn finish(mut self, end: f64) -> Vec<(f64, f64)> {
        if let Some(a) = self.open {
            self.done.push((a, end.max(self.last_t)));
        }
        self.done
    }
}

/// Writes `<stem>.png` and `<stem>.svg`; returns both paths.
pub fn save_figure(fig: &Figure, stem: &Path, size: (u32, u32)) -> Result<[PathBuf; 2]> {
    save(stem, size, |root| draw_figure(root, fig))
}

/// Writes `<stem>.png` and `<stem>.svg` of a bar chart; returns both paths.
pub fn save_bars(chart: &BarChart, stem: &Path, size: (u32, u32)) -> Result<[PathBuf; 2]> {
    save(stem, size, |root| draw_bars(root, chart))
}

/// The two backends this module draws on.
enum DynArea<'a> {
    Bitmap(DrawingArea<BitMapBackend<'a>, Shift>),
    Svg(DrawingArea<SVGBackend<'a>, Shift>),
}

fn save(
    stem: &Path,
    (w, h): (u32, u32),
    draw: impl Fn(&DynArea<'_>) -> Result<()>,
) -> Result<[PathBuf; 2]> {
    fonts()?;
    let png_path = stem.with_extension("png");
    let svg_path = stem.with_extension("svg");
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let area = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(&DynArea::Bitmap(area))?;
    }
    write_png(&png_path, &rgb, (w, h))?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(&DynArea::Svg(area))?;
    }
    std::fs::write(&svg_path, svg).with_context(|| format!("writing {}", svg_path.display()))?;
    Ok([png_path, svg_path])
}

fn write_png(path: &Path, rgb: &[u8], (w, h): (u32, u32)) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Balanced);
    let mut out = enc
        .write_header()
        .with_context(|| format!("writing {}", path.display()))?;
    out.write_image_data(rgb)
        .with_context(|| format!("writing {}", path.display()))?;
    out.finish()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

fn draw_figure(area: &DynArea<'_>, fig: &Figure) -> Result<()> {
    match area {
        DynArea::Bitmap(a) => figure_on(a, fig),
        DynArea::Svg(a) => figure_on(a, fig),
    }
}

fn draw_bars(area: &DynArea<'_>, chart: &BarChart) -> Result<()> {
    match area {
        DynArea::Bitmap(a) => bars_on(a, chart),
        DynArea::Svg(a) => bars_on(a, chart),
    }
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("drawing a figure: {e}")
}

/// The series' legend, upper right, in every figure's style.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(plot_err)
}

/// Value range of the lines of a panel, padded by 5 %.
fn y_range(lines: &[Line]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for l in lines {
        for &(_, v) in &l.points {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
        let pad = (hi.abs() * 0.1).max(1e-3);
        return (lo - pad, hi + pad);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// Tick label: short, and without the float noise of `{}`; `span` is the axis length, below
/// a millionth of which a value is zero.
fn tick(v: f64, span: f64) -> String {
    if v == 0.0 || v.abs() < span.abs() * 1e-6 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.1e}");
    }
    let decimals = (3.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    s.replace('-', "\u{2212}")
}

fn figure_on<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let body = root
        .titled(&fig.title, (FONT, 22).into_font().color(&BLACK))
        .map_err(plot_err)?;
    let n = fig.panels.len().max(1);
    let areas = body.split_evenly((n, 1));
    let (x0, x1) = if fig.x_range.1 > fig.x_range.0 {
        fig.x_range
    } else {
        (fig.x_range.0, fig.x_range.0 + 1.0)
    };
    for (panel, area) in fig.panels.iter().zip(&areas) {
        match &panel.kind {
            PanelKind::Lines(lines) => {
                let (y0, y1) = y_range(lines);
                let (xs, ys) = (x1 - x0, y1 - y0);
                let mut chart = ChartBuilder::on(area)
                    .caption(&panel.title, (FONT, 16))
                    .margin(8)
                    .margin_right(20)
                    .x_label_area_size(36)
                    .y_label_area_size(72)
                    .build_cartesian_2d(x0..x1, y0..y1)
                    .map_err(plot_err)?;
                chart
                    .configure_mesh()
                    .x_desc(&fig.x_label)
                    .y_desc(&panel.y_label)
                    .label_style((FONT, 13))
                    .axis_desc_style((FONT, 14))
                    .light_line_style(RGBColor(238, 238, 238))
                    .bold_line_style(RGBColor(210, 210, 210))
                    .x_label_formatter(&|v| tick(*v, xs))
                    .y_label_formatter(&|v| tick(*v, ys))
                    .draw()
                    .map_err(plot_err)?;
                chart
                    .draw_series(
                        fig.markers
                            .iter()
                            .filter(|m| **m > x0 && **m < x1)
                            .map(|&m| PathElement::new(vec![(m, y0), (m, y1)], MARKER)),
                    )
                    .map_err(plot_err)?;
                for l in lines {
                    let color = l.color;
                    chart
                        .draw_series(LineSeries::new(l.points.iter().copied(), color))
                        .map_err(plot_err)?
                        .label(&l.label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        });
                }
                draw_legend(&mut chart)?;
            }
            PanelKind::Timeline(bands) => {
                let rows = bands.len().max(1) as f64;
                let mut chart = ChartBuilder::on(area)
                    .caption(&panel.title, (FONT, 16))
                    .margin(8)
                    .margin_right(20)
                    .x_label_area_size(36)
                    .y_label_area_size(72)
                    .build_cartesian_2d(x0..x1, 0.0..rows)
                    .map_err(plot_err)?;
                chart
                    .configure_mesh()
                    .x_desc(&fig.x_label)
                    .y_desc(&panel.y_label)
                    .y_labels(0)
                    .disable_y_mesh()
                    .label_style((FONT, 13))
                    .axis_desc_style((FONT, 14))
                    .light_line_style(RGBColor(238, 238, 238))
                    .bold_line_style(RGBColor(210, 210, 210))
                    .x_label_formatter(&|v| tick(*v, x1 - x0))
                    .draw()
                    .map_err(plot_err)?;
                chart
                    .draw_series(
                        fig.markers
                            .iter()
                            .filter(|m| **m > x0 && **m < x1)
                            .map(|&m| PathElement::new(vec![(m, 0.0), (m, rows)], MARKER)),
                    )
                    .map_err(plot_err)?;
                for (i, b) in bands.iter().enumerate() {
                    // The first band on top.
                    let row = rows - 1.0 - i as f64;
                    let color = b.color;
                    chart
                        .draw_series(b.intervals.iter().map(|&(a, e)| {
                            // At least one pixel wide.
                            let e = e.max(a + (x1 - x0) * 1e-3);
                            Rectangle::new([(a, row + 0.2), (e, row + 0.8)], color.filled())
                        }))
                        .map_err(plot_err)?;
                    let label = if b.intervals.is_empty() {
                        format!("{} (never)", b.label)
                    } else {
                        b.label.clone()
                    };
                    chart
                        .draw_series(std::iter::once(Text::new(
                            label,
                            (x0 + (x1 - x0) * 0.005, row + 0.95),
                            (FONT, 13).into_font().color(&BLACK),
                        )))
                        .map_err(plot_err)?;
                }
            }
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

fn bars_on<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &BarChart) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let cats = c.categories.len().max(1);
    let top = c
        .series
        .iter()
        .flat_map(|s| s.2.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0_f64, f64::max);
    let top = if top > 0.0 { top * 1.2 } else { 1.0 };
    let mut chart = ChartBuilder::on(root)
        .caption(&c.title, (FONT, 20))
        .margin(12)
        .margin_right(24)
        .x_label_area_size(40)
        .y_label_area_size(72)
        .build_cartesian_2d(0.0..cats as f64, 0.0..top)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc(&c.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(210, 210, 210))
        .y_label_formatter(&|v| tick(*v, top))
        .draw()
        .map_err(plot_err)?;
    let k = c.series.len().max(1) as f64;
    let width = 0.8 / k;
    for (j, (label, color, values)) in c.series.iter().enumerate() {
        let color = *color;
        chart
            .draw_series(
                values
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| v.is_finite())
                    .map(|(i, &v)| {
                        let x = i as f64 + 0.1 + j as f64 * width;
                        Rectangle::new([(x, 0.0), (x + width * 0.9, v)], color.filled())
                    }),
            )
            .map_err(plot_err)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.filled()));
    }
    draw_legend(&mut chart)?;
    let style = TextStyle::from((FONT, 14).into_font()).color(&BLACK).pos(
        plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Center,
            plotters::style::text_anchor::VPos::Top,
        ),
    );
    for (i, name) in c.categories.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, 0.0));
        root.draw(&Text::new(name.clone(), (px, py + 8), style.clone()))
            .map_err(plot_err)?;
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_spikes_and_time_order() {
        let mut e = Envelope::new(10, 100);
        for k in 0..100 {
            let v = if k == 37 { 5.0 } else { 0.0 };
            e.push(k as f64, v);
        }
        let p = e.finish();
        assert!(p.contains(&(37.0, 5.0)), "{p:?}");
        assert!(p.windows(2).all(|w| w[0].0 <= w[1].0), "{p:?}");
        assert!(p.len() <= 20);
    }

    #[test]
    fn intervals_close_at_the_end() {
        let mut i = Intervals::default();
        for (t, on) in [
            (0.0, false),
            (1.0, true),
            (2.0, true),
            (3.0, false),
            (4.0, true),
        ] {
            i.push(t, on);
        }
        assert_eq!(i.finish(5.0), vec![(1.0, 3.0), (4.0, 5.0)]);
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick(0.0, 1.0), "0");
        assert_eq!(tick(-5.6e-17, 0.6), "0");
        assert_eq!(tick(0.02, 1.0), "0.02");
        assert_eq!(tick(-0.005, 1.0), "\u{2212}0.005");
        assert_eq!(tick(25.0, 40.0), "25");
        assert_eq!(tick(1e-6, 1e-5), "1.0e-6");
    }
}
