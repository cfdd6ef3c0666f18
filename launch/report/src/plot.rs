//! Figures as data ([`Figure`], [`BarChart`]) and their rendering to PNG and SVG with plotters.
//!
//! Text is drawn with the DejaVu Sans font embedded in the binary (`src/fonts/`, Bitstream Vera
//! license), so figures render the same on a machine without any system font. plotters draws
//! each figure once, as SVG; the PNG is that SVG rasterised by resvg, whose text is shaped with
//! the same embedded font (plotters' own bitmap text placed glyphs unevenly: "pap er", a decimal
//! point drawn as "·"), and encoded with the `png` crate.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{anyhow, Context, Result};
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{register_font, FontStyle};

pub const FONT: &str = "sans-serif";
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

pub fn fonts() -> Result<()> {
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
    /// The y-axis always holds the whole curve: it is never clipped (the true attack S, the
    /// delay τ). Other curves may be clipped by the robust range ([`robust_y_range`]).
    pub keep: bool,
    /// Drawn dashed and over the other curves (a reference such as the ROC's chance diagonal,
    /// which a curve lying on it would otherwise hide).
    pub dashed: bool,
}

/// A horizontal reference band `lo ≤ y ≤ hi` drawn behind the curves (a bound the paper states).
#[derive(Debug, Clone)]
pub struct Guide {
    pub label: String,
    pub lo: f64,
    pub hi: f64,
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
    /// Reference bands of a line panel (always inside its y-range).
    pub guides: Vec<Guide>,
}

/// Panels stacked vertically over a common time axis.
#[derive(Debug, Clone)]
pub struct Figure {
    pub title: String,
    pub x_label: String,
    pub x_range: (f64, f64),
    /// Times drawn as thin vertical lines in every panel (attack switches).
    pub markers: Vec<f64>,
    /// The legend entry of the markers (empty: none).
    pub marker_label: String,
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
    /// A logarithmic value axis (for shares spanning decades: latency histograms). Bars of
    /// value zero are then not drawn.
    pub log_y: bool,
}

/// Quantiles of a line panel's (clippable) points that set its robust y-range.
pub const ROBUST_QUANTILES: (f64, f64) = (0.005, 0.995);
/// Margin added on each side of the robust range, as a share of its span.
pub const ROBUST_MARGIN: f64 = 0.15;
/// The robust range is used only when the full range is more than this many times larger;
/// otherwise nothing is clipped.
pub const CLIP_RATIO: f64 = 1.5;

/// The y-range of a line panel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YRange {
    pub lo: f64,
    pub hi: f64,
    /// Some values lie outside `[lo, hi]`: they are drawn at the edge and marked.
    pub clips: bool,
}

/// `(lo, hi)` padded by `share` of the span on each side; a (near) zero span gets a pad of its own.
fn padded(lo: f64, hi: f64, share: f64) -> (f64, f64) {
    let span = hi - lo;
    if span <= f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
        let pad = (hi.abs() * 0.1).max(1e-3);
        return (lo - pad, hi + pad);
    }
    (lo - share * span, hi + share * span)
}

/// The y-range of a panel whose clippable values are `values` and whose `must_show` values (kept
/// curves, reference bands) must all be inside. The full range (all values, padded by 5 %) is
/// used unless it is more than [`CLIP_RATIO`] times the robust range: the
/// [`ROBUST_QUANTILES`] of `values`, widened to hold `must_show`, padded by [`ROBUST_MARGIN`].
/// A few spikes (attack switches) then no longer squash the steady state into a few pixels.
/// Non-finite values are ignored. Deterministic: depends on the values only, not their order.
pub fn robust_y_range(values: &[f64], must_show: &[f64]) -> YRange {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let must = must_show.iter().copied().filter(|x| x.is_finite());
    let (mut mlo, mut mhi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in must {
        mlo = mlo.min(x);
        mhi = mhi.max(x);
    }
    let (Some(&vmin), Some(&vmax)) = (v.first(), v.last()) else {
        if mlo.is_finite() {
            let (lo, hi) = padded(mlo, mhi, 0.05);
            return YRange {
                lo,
                hi,
                clips: false,
            };
        }
        return YRange {
            lo: -1.0,
            hi: 1.0,
            clips: false,
        };
    };
    let (flo, fhi) = padded(vmin.min(mlo), vmax.max(mhi), 0.05);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    let (a, b) = (
        q(ROBUST_QUANTILES.0).min(mlo),
        q(ROBUST_QUANTILES.1).max(mhi),
    );
    let (rlo, rhi) = padded(a, b, ROBUST_MARGIN);
    if fhi - flo <= CLIP_RATIO * (rhi - rlo) || (vmin >= rlo && vmax <= rhi) {
        return YRange {
            lo: flo,
            hi: fhi,
            clips: false,
        };
    }
    YRange {
        lo: rlo,
        hi: rhi,
        clips: true,
    }
}

/// A run of consecutive points of one curve beyond one edge of the y-range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excursion {
    /// Time and value of the point farthest beyond the edge.
    pub t: f64,
    pub v: f64,
    /// Above the top edge (else below the bottom one).
    pub above: bool,
    /// Points in the run.
    pub points: usize,
}

/// The runs of `points` outside `[lo, hi]`, in time order.
pub fn excursions(points: &[(f64, f64)], lo: f64, hi: f64) -> Vec<Excursion> {
    let mut out: Vec<Excursion> = Vec::new();
    let mut open: Option<Excursion> = None;
    for &(t, v) in points {
        let side = if v > hi {
            Some(true)
        } else if v < lo {
            Some(false)
        } else {
            None
        };
        match (open.as_mut(), side) {
            (Some(e), Some(above)) if e.above == above => {
                e.points += 1;
                if (above && v > e.v) || (!above && v < e.v) {
                    e.t = t;
                    e.v = v;
                }
            }
            (_, side) => {
                out.extend(open.take());
                open = side.map(|above| Excursion {
                    t,
                    v,
                    above,
                    points: 1,
                });
            }
        }
    }
    out.extend(open);
    out
}

/// `beyond` (excursions of the curves of one panel, with their colours) with those on the same
/// side less than `gap` apart in time merged into one: the farthest, with the points of all.
/// One marker then stands for an oscillating spike however many times it crosses the edge.
pub fn merge_excursions<C: Copy>(mut beyond: Vec<(C, Excursion)>, gap: f64) -> Vec<(C, Excursion)> {
    // A stable sort: ties keep the curves' order.
    beyond.sort_by(|a, b| a.1.t.total_cmp(&b.1.t));
    let mut out: Vec<(C, Excursion)> = Vec::new();
    for (c, e) in beyond {
        let near = out
            .iter_mut()
            .rev()
            .take_while(|(_, o)| e.t - o.t < gap)
            .find(|(_, o)| o.above == e.above);
        match near {
            Some((oc, o)) => {
                let farther = if e.above { e.v > o.v } else { e.v < o.v };
                let points = o.points + e.points;
                if farther {
                    *oc = c;
                    *o = e;
                }
                o.points = points;
            }
            None => out.push((c, e)),
        }
    }
    out
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

/// The area this module draws on: SVG (the PNG is rasterised from it).
type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

fn save(
    stem: &Path,
    (w, h): (u32, u32),
    draw: impl Fn(&Area<'_>) -> Result<()>,
) -> Result<[PathBuf; 2]> {
    fonts()?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(&area)?;
    }
    write_figure(stem, svg, (w, h))
}

/// Writes the figure `svg` of `w` × `h` pixels as `<stem>.svg` and, rasterised from it, as
/// `<stem>.png` ([`rasterise`]); the two paths.
pub fn write_figure(stem: &Path, svg: String, (w, h): (u32, u32)) -> Result<[PathBuf; 2]> {
    let png_path = stem.with_extension("png");
    let svg_path = stem.with_extension("svg");
    let svg = xml_text(svg);
    let rgb = rasterise(&svg, (w, h)).with_context(|| format!("drawing {}", png_path.display()))?;
    write_png(&png_path, &rgb, (w, h))?;
    std::fs::write(&svg_path, svg).with_context(|| format!("writing {}", svg_path.display()))?;
    Ok([png_path, svg_path])
}

/// `svg` with every character XML 1.0 does not allow (the control characters but tab, line
/// feed and carriage return) shown as U+FFFD: a title or label made from a name read from a
/// file is drawn, never the reason the figure cannot be read.
fn xml_text(svg: String) -> String {
    let forbidden = |c: char| c.is_control() && !matches!(c, '\t' | '\n' | '\r');
    if !svg.contains(forbidden) {
        return svg;
    }
    svg.replace(forbidden, "\u{fffd}")
}

/// The SVG `svg` of `w` × `h` pixels as RGB bytes on white, its text in the embedded font.
pub fn rasterise(svg: &str, (w, h): (u32, u32)) -> Result<Vec<u8>> {
    use resvg::{tiny_skia, usvg};
    static OPTIONS: OnceLock<usvg::Options<'static>> = OnceLock::new();
    let options = OPTIONS.get_or_init(|| {
        let mut o = usvg::Options::default();
        let db = o.fontdb_mut();
        db.load_font_data(FONT_BYTES.to_vec());
        db.set_sans_serif_family("DejaVu Sans");
        o.font_family = "DejaVu Sans".into();
        o
    });
    let tree = usvg::Tree::from_str(svg, options).context("reading the figure's SVG")?;
    let mut pixmap =
        tiny_skia::Pixmap::new(w, h).ok_or_else(|| anyhow!("a figure of {w} × {h} pixels"))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(&tree, tiny_skia::Transform::default(), &mut pixmap.as_mut());
    // Opaque on white: the premultiplied RGBA is the RGB.
    Ok(pixmap
        .data()
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect())
}

pub fn write_png(path: &Path, rgb: &[u8], (w, h): (u32, u32)) -> Result<()> {
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

fn draw_figure(area: &Area<'_>, fig: &Figure) -> Result<()> {
    figure_on(area, fig)
}

fn draw_bars(area: &Area<'_>, chart: &BarChart) -> Result<()> {
    bars_on(area, chart)
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("drawing a figure: {e}")
}

/// The series' legend, upper right, in every figure's style.
pub fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
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

/// Width of the legend column right of every panel, px.
const LEGEND_W: u32 = 270;
/// Colour of the reference bands (the paper's bounds).
const GUIDE: RGBColor = RGBColor(0, 158, 115);
/// Excursions beyond the y-range of a panel that get their value written beside their marker;
/// with more, only the farthest above and the farthest below do.
pub const LABELLED_EXCURSIONS: usize = 6;
/// Excursions on the same side closer than this share of the time axis get one marker.
pub const MERGE_SHARE: f64 = 0.015;

fn key_style() -> TextStyle<'static> {
    TextStyle::from((FONT, 13).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center))
}

/// One entry of the legend column beside a panel.
enum Key {
    Line(RGBColor, String),
    Guide(String),
    Marker(String),
    Clipped(String),
    /// A swatch of a timeline row.
    Row(RGBColor, String),
    /// A further line of text under the previous entry.
    Text(String),
}

/// A triangle pointing out of the plot, apex at (0, 0) (backend pixels relative to its anchor).
fn triangle(above: bool) -> Vec<(i32, i32)> {
    let d = if above { 9 } else { -9 };
    vec![(0, 0), (-5, d), (5, d)]
}

/// Draws `keys` top down in `area` (pixels relative to it), the first centred at `top`.
fn draw_keys<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    keys: &[Key],
    top: i32,
) -> Result<()> {
    let (x, tx) = (8, 40);
    for (i, k) in keys.iter().enumerate() {
        let y = top + 19 * i as i32;
        let label = match k {
            Key::Line(c, l) => {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 24, y)],
                    c.stroke_width(2),
                ))
                .map_err(plot_err)?;
                l
            }
            Key::Guide(l) => {
                area.draw(&Rectangle::new(
                    [(x, y - 6), (x + 24, y + 6)],
                    GUIDE.mix(0.18).filled(),
                ))
                .map_err(plot_err)?;
                area.draw(&Rectangle::new(
                    [(x, y - 6), (x + 24, y + 6)],
                    GUIDE.mix(0.8),
                ))
                .map_err(plot_err)?;
                l
            }
            Key::Marker(l) => {
                area.draw(&PathElement::new(
                    vec![(x + 12, y - 8), (x + 12, y + 8)],
                    MARKER,
                ))
                .map_err(plot_err)?;
                l
            }
            Key::Clipped(l) => {
                area.draw(&Polygon::new(
                    triangle(true)
                        .into_iter()
                        .map(|(a, b)| (x + 6 + a, y - 5 + b))
                        .collect::<Vec<_>>(),
                    BLACK.filled(),
                ))
                .map_err(plot_err)?;
                area.draw(&Polygon::new(
                    triangle(false)
                        .into_iter()
                        .map(|(a, b)| (x + 18 + a, y + 5 + b))
                        .collect::<Vec<_>>(),
                    BLACK.filled(),
                ))
                .map_err(plot_err)?;
                l
            }
            Key::Row(c, l) => {
                area.draw(&Rectangle::new([(x, y - 6), (x + 24, y + 6)], c.filled()))
                    .map_err(plot_err)?;
                l
            }
            Key::Text(l) => l,
        };
        area.draw(&Text::new(label.clone(), (tx, y), key_style()))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// The legend entry of the figure's markers, if one of them is drawn in `(x0, x1)`.
fn marker_key(fig: &Figure, x0: f64, x1: f64) -> Option<Key> {
    let shown = fig.markers.iter().any(|m| *m > x0 && *m < x1);
    (shown && !fig.marker_label.is_empty()).then(|| Key::Marker(fig.marker_label.clone()))
}

/// A value beside its clip marker: three significant digits.
fn peak(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return tick(v, 1.0);
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.2e}").replace('-', "\u{2212}");
    }
    let decimals = (2.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
    format!("{v:.decimals$}").replace('-', "\u{2212}")
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
        let (plot_area, key_area) =
            area.split_horizontally(area.dim_in_pixel().0.saturating_sub(LEGEND_W));
        match &panel.kind {
            PanelKind::Lines(lines) => {
                lines_panel(fig, panel, lines, &plot_area, &key_area, (x0, x1))?
            }
            PanelKind::Timeline(bands) => {
                timeline_panel(fig, panel, bands, &plot_area, &key_area, (x0, x1))?;
            }
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

/// The largest magnitude an axis reaches: data beyond it (a diverged run, 1e300) is clipped
/// at the axis, never handed to the tick computation.
pub(crate) const AXIS_LIMIT: f64 = 1e15;

/// An axis range that can be drawn in bounded time: finite, within ±[`AXIS_LIMIT`], ordered,
/// and wide enough against its magnitude that tick steps stay above the rounding of its values
/// (a range of non-finite, huge or collapsed values made the tick computation loop for ever).
pub fn drawable(lo: f64, hi: f64) -> (f64, f64) {
    let clamp = |v: f64, fallback: f64| {
        if v.is_nan() {
            fallback
        } else {
            v.clamp(-AXIS_LIMIT, AXIS_LIMIT)
        }
    };
    let (a, b) = (clamp(lo, -1.0), clamp(hi, 1.0));
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    let mid = a / 2.0 + b / 2.0;
    let least = (mid.abs() * 1e-9).max(1e-12);
    if b - a >= 2.0 * least {
        (a, b)
    } else {
        let mid = mid.clamp(-AXIS_LIMIT + least, AXIS_LIMIT - least);
        (mid - least, mid + least)
    }
}

/// The chart of one panel: time on x, values (or timeline rows) on y.
type PanelChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A panel's chart on `plot_area` with its caption, grid and axes over `x` by `y`; `y_ticks`
/// false (a timeline): no y-axis ticks and no horizontal grid lines.
fn panel_axes<'a, DB: DrawingBackend + 'a>(
    plot_area: &'a DrawingArea<DB, Shift>,
    fig: &Figure,
    panel: &Panel,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    y_ticks: bool,
) -> Result<PanelChart<'a, DB>> {
    let (x0, x1) = drawable(x0, x1);
    let (y0, y1) = drawable(y0, y1);
    let mut chart = ChartBuilder::on(plot_area)
        .caption(&panel.title, (FONT, 16))
        .margin(8)
        .margin_right(12)
        .x_label_area_size(36)
        .y_label_area_size(72)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    let (xs, ys) = (x1 - x0, y1 - y0);
    let x_tick = |v: &f64| tick(*v, xs);
    let y_tick = |v: &f64| tick(*v, ys);
    {
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(&fig.x_label)
            .y_desc(&panel.y_label)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .light_line_style(RGBColor(238, 238, 238))
            .bold_line_style(RGBColor(210, 210, 210))
            .x_label_formatter(&x_tick);
        if y_ticks {
            mesh.y_label_formatter(&y_tick);
        } else {
            mesh.y_labels(0).disable_y_mesh();
        }
        mesh.draw().map_err(plot_err)?;
    }
    Ok(chart)
}

/// The figure's markers (attack switches) inside `(x0, x1)`, as vertical lines from `y0` to `y1`.
fn draw_markers<'a, DB: DrawingBackend + 'a>(
    chart: &mut PanelChart<'a, DB>,
    fig: &Figure,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<()> {
    chart
        .draw_series(
            fig.markers
                .iter()
                .filter(|m| **m > x0 && **m < x1)
                .map(|&m| PathElement::new(vec![(m, y0), (m, y1)], MARKER)),
        )
        .map_err(plot_err)?;
    Ok(())
}

fn lines_panel<DB: DrawingBackend>(
    fig: &Figure,
    panel: &Panel,
    lines: &[Line],
    plot_area: &DrawingArea<DB, Shift>,
    key_area: &DrawingArea<DB, Shift>,
    (x0, x1): (f64, f64),
) -> Result<()> {
    let clippable: Vec<f64> = lines
        .iter()
        .filter(|l| !l.keep)
        .flat_map(|l| l.points.iter().map(|p| p.1))
        .collect();
    let YRange {
        lo: y0,
        hi: y1,
        clips,
    } = robust_y_range(&clippable, &must_show(panel, lines));
    let mut chart = panel_axes(plot_area, fig, panel, (x0, x1), (y0, y1), true)?;
    let mut keys = draw_guides(&mut chart, &panel.guides, (x0, x1))?;
    draw_markers(&mut chart, fig, (x0, x1), (y0, y1))?;
    let clipped = draw_curves(&mut chart, lines, (y0, y1), clips, &mut keys)?;
    keys.extend(marker_key(fig, x0, x1));
    if clipped.points > 0 {
        keys.extend(clipped.keys(&clippable, y1 - y0, &panel.y_label));
        let beyond = merge_excursions(clipped.beyond, MERGE_SHARE * (x1 - x0));
        draw_excursions(&mut chart, &beyond, (y0, y1))?;
    }
    let top = chart.plotting_area().get_base_pixel().1 - key_area.get_base_pixel().1 + 10;
    draw_keys(key_area, &keys, top)
}

/// The values a line panel's y-range must hold: its kept curves' and its reference bands'.
fn must_show(panel: &Panel, lines: &[Line]) -> Vec<f64> {
    let mut must: Vec<f64> = lines
        .iter()
        .filter(|l| l.keep)
        .flat_map(|l| l.points.iter().map(|p| p.1))
        .collect();
    for g in &panel.guides {
        must.extend([g.lo, g.hi]);
    }
    must
}

/// The reference bands across `(x0, x1)`, filled and edged; returns their legend entries.
fn draw_guides<'a, DB: DrawingBackend + 'a>(
    chart: &mut PanelChart<'a, DB>,
    guides: &[Guide],
    (x0, x1): (f64, f64),
) -> Result<Vec<Key>> {
    let mut keys = Vec::new();
    for g in guides {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x0, g.lo), (x1, g.hi)],
                GUIDE.mix(0.12).filled(),
            )))
            .map_err(plot_err)?;
        chart
            .draw_series(
                [g.lo, g.hi].map(|y| PathElement::new(vec![(x0, y), (x1, y)], GUIDE.mix(0.7))),
            )
            .map_err(plot_err)?;
        keys.push(Key::Guide(g.label.clone()));
    }
    Ok(keys)
}

/// What a line panel's y-range clipped of its curves.
struct Clipped {
    /// The runs of points beyond the range, with their curve's colour.
    beyond: Vec<(RGBColor, Excursion)>,
    /// Points clipped, of `total` clippable points.
    points: usize,
    total: usize,
}

impl Clipped {
    /// The legend entries of the clipping: how many points, and the range of all `values`.
    fn keys(&self, values: &[f64], ys: f64, y_label: &str) -> [Key; 2] {
        let (vmin, vmax) = values
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        [
            Key::Clipped(format!("clipped: {} of {} points", self.points, self.total)),
            Key::Text(format!(
                "all values: {} … {} {}",
                tick(vmin, ys),
                tick(vmax, ys),
                y_label
            )),
        ]
    }
}

/// The curves, clamped to `[y0, y1]`, each with its legend entry in `keys`; returns what was
/// clipped (with `clips`, of the curves that may be clipped).
fn draw_curves<'a, DB: DrawingBackend + 'a>(
    chart: &mut PanelChart<'a, DB>,
    lines: &[Line],
    (y0, y1): (f64, f64),
    clips: bool,
    keys: &mut Vec<Key>,
) -> Result<Clipped> {
    let mut clipped = Clipped {
        beyond: Vec::new(),
        points: 0,
        total: 0,
    };
    // The dashed references last, over the curves.
    let order = lines
        .iter()
        .filter(|l| !l.dashed)
        .chain(lines.iter().filter(|l| l.dashed));
    for l in order {
        let color = l.color;
        let points = l.points.iter().map(|&(t, v)| (t, v.clamp(y0, y1)));
        if l.dashed {
            chart
                .draw_series(DashedLineSeries::new(points, 6, 5, color.stroke_width(2)))
                .map_err(plot_err)?;
        } else {
            chart
                .draw_series(LineSeries::new(points, color))
                .map_err(plot_err)?;
        }
        // A curve without a label has no legend entry (the team figure's many robots share one).
        if !l.label.is_empty() {
            keys.push(Key::Line(color, l.label.clone()));
        }
        if clips && !l.keep {
            clipped.total += l.points.len();
            for e in excursions(&l.points, y0, y1) {
                clipped.points += e.points;
                clipped.beyond.push((color, e));
            }
        }
    }
    Ok(clipped)
}

/// The index in `beyond` of the farthest excursion above the range (or below it).
fn farthest(beyond: &[(RGBColor, Excursion)], above: bool) -> Option<usize> {
    beyond
        .iter()
        .enumerate()
        .filter(|(_, (_, e))| e.above == above)
        .max_by(|(_, (_, a)), (_, (_, b))| {
            if above {
                a.v.total_cmp(&b.v)
            } else {
                b.v.total_cmp(&a.v)
            }
        })
        .map(|(i, _)| i)
}

/// A ▲ or ▼ at the edge for every excursion, with its value beside it when there are at most
/// [`LABELLED_EXCURSIONS`] (else beside the farthest on each side only).
fn draw_excursions<'a, DB: DrawingBackend + 'a>(
    chart: &mut PanelChart<'a, DB>,
    beyond: &[(RGBColor, Excursion)],
    (y0, y1): (f64, f64),
) -> Result<()> {
    let (far_up, far_down) = (farthest(beyond, true), farthest(beyond, false));
    let style = (FONT, 12).into_font().color(&BLACK);
    for (i, (color, e)) in beyond.iter().enumerate() {
        let edge = if e.above { y1 } else { y0 };
        let label = beyond.len() <= LABELLED_EXCURSIONS || Some(i) == far_up || Some(i) == far_down;
        let text = if label { peak(e.v) } else { String::new() };
        let dy = if e.above { 2 } else { -14 };
        chart
            .draw_series(std::iter::once(
                EmptyElement::at((e.t, edge))
                    + Polygon::new(triangle(e.above), color.filled())
                    + Text::new(text, (7, dy), style.clone()),
            ))
            .map_err(plot_err)?;
    }
    Ok(())
}

fn timeline_panel<DB: DrawingBackend>(
    fig: &Figure,
    panel: &Panel,
    bands: &[Band],
    plot_area: &DrawingArea<DB, Shift>,
    key_area: &DrawingArea<DB, Shift>,
    (x0, x1): (f64, f64),
) -> Result<()> {
    let rows = bands.len().max(1) as f64;
    let mut chart = panel_axes(plot_area, fig, panel, (x0, x1), (0.0, rows), false)?;
    draw_markers(&mut chart, fig, (x0, x1), (0.0, rows))?;
    // Every interval is at least two pixels wide, so that short pulses stay visible.
    let px = f64::from(chart.plotting_area().dim_in_pixel().0.max(1));
    let min_w = 2.0 * (x1 - x0) / px;
    let base = key_area.get_base_pixel().1;
    for (i, b) in bands.iter().enumerate() {
        // The first band on top.
        let row = rows - 1.0 - i as f64;
        let color = b.color;
        chart
            .draw_series(b.intervals.iter().map(|&(a, e)| {
                let e = e.max(a + min_w);
                Rectangle::new([(a, row + 0.2), (e, row + 0.8)], color.filled())
            }))
            .map_err(plot_err)?;
        let y = chart.backend_coord(&(x0, row + 0.5)).1 - base;
        draw_keys(
            key_area,
            &[
                Key::Row(color, b.label.clone()),
                Key::Text(band_detail(b, (x0, x1))),
            ],
            y - 9,
        )?;
    }
    Ok(())
}

/// How often and how long a timeline row held within `(x0, x1)`, for its legend.
fn band_detail(b: &Band, (x0, x1): (f64, f64)) -> String {
    let held: f64 = b
        .intervals
        .iter()
        .map(|&(a, e)| (e.min(x1) - a.max(x0)).max(0.0))
        .sum();
    match b.intervals.len() {
        0 => "never".to_string(),
        1 => format!("1 interval, {:.1} % of the time", 100.0 * held / (x1 - x0)),
        n => format!(
            "{n} intervals, {:.1} % of the time",
            100.0 * held / (x1 - x0)
        ),
    }
}

/// Decades `[lo, hi]` that hold the positive `values` (for a logarithmic axis), with one decade
/// below the smallest, so that the smallest bar is a bar and not a sliver.
fn decades(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .map(|v| v.clamp(1.0 / AXIS_LIMIT, AXIS_LIMIT))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.1, 100.0);
    }
    let lo = 10f64.powf(lo.log10().floor() - 1.0);
    let hi = 10f64.powf(hi.log10().ceil()).max(lo * 10.0);
    (lo, hi)
}

fn bars_on<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, c: &BarChart) -> Result<()> {
    root.fill(&WHITE).map_err(plot_err)?;
    let cats = c.categories.len().max(1) as f64;
    let values = || c.series.iter().flat_map(|s| s.2.iter().copied());
    let builder = |root| {
        let mut b = ChartBuilder::on(root);
        b.caption(&c.title, (FONT, 20))
            .margin(12)
            .margin_right(24)
            .x_label_area_size(12 + 15 * category_lines(&c.categories) as u32)
            .y_label_area_size(72);
        b
    };
    if c.log_y {
        let (lo, hi) = decades(values());
        let chart = builder(root)
            .build_cartesian_2d(0.0..cats, (lo..hi).log_scale())
            .map_err(plot_err)?;
        bars_body(root, chart, c, lo, hi)
    } else {
        let top = values().filter(|v| v.is_finite()).fold(0.0_f64, f64::max);
        let top = if top > 0.0 { top * 1.2 } else { 1.0 };
        let (_, top) = drawable(0.0, top);
        let chart = builder(root)
            .build_cartesian_2d(0.0..cats, 0.0..top)
            .map_err(plot_err)?;
        bars_body(root, chart, c, 0.0, top)
    }
}

/// Marks each value of series `j` (bars `width` wide, `color`) that is not finite (a robot
/// that diverged) where its bar would be: an outline from `base` to `top`, "diverged" written
/// up it.
fn mark_diverged<'a, DB, Y>(
    root: &DrawingArea<DB, Shift>,
    chart: &ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    (j, width, color, values): (usize, f64, RGBColor, &[f64]),
    (base, top): (f64, f64),
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64>,
{
    let (lo_px, hi_px) = (
        chart.backend_coord(&(0.0, base)).1,
        chart.backend_coord(&(0.0, top)).1,
    );
    for (i, _) in values.iter().enumerate().filter(|(_, v)| !v.is_finite()) {
        let x = i as f64 + 0.1 + j as f64 * width;
        let (left, _) = chart.backend_coord(&(x, base));
        let (right, _) = chart.backend_coord(&(x + width * 0.9, base));
        root.draw(&Rectangle::new(
            [(left, hi_px), (right, lo_px)],
            color.stroke_width(2),
        ))
        .map_err(plot_err)?;
        let up = TextStyle::from((FONT, 12).into_font())
            .color(&color)
            .transform(FontTransform::Rotate270)
            .pos(Pos::new(HPos::Left, VPos::Center));
        root.draw(&Text::new("diverged", ((left + right) / 2, lo_px - 6), up))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// Longest line of a category label before it is broken at a hyphen.
const CATEGORY_LINE: usize = 10;

/// A category's label in lines that fit under its bars: a line per word, a long word broken
/// after a hyphen (`measurement-delay r1` → `measurement-`, `delay`, `r1`).
fn category_label(name: &str) -> Vec<String> {
    let mut lines = Vec::new();
    for word in name.split_whitespace() {
        let mut line = String::new();
        for part in word.split_inclusive('-') {
            if !line.is_empty() && line.chars().count() + part.chars().count() > CATEGORY_LINE {
                lines.push(std::mem::take(&mut line));
            }
            line.push_str(part);
        }
        lines.push(line);
    }
    lines
}

/// The most lines a category label of `categories` takes.
fn category_lines(categories: &[String]) -> usize {
    categories
        .iter()
        .map(|c| category_label(c).len())
        .max()
        .unwrap_or(1)
}

/// The bars of `c` from `base` up, on a chart whose value axis is `Y` (linear or logarithmic).
fn bars_body<'a, DB, Y>(
    root: &DrawingArea<DB, Shift>,
    mut chart: ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    c: &BarChart,
    base: f64,
    top: f64,
) -> Result<()>
where
    DB: DrawingBackend + 'a,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let y_desc = if c.log_y {
        format!("{}, log scale", c.y_label)
    } else {
        c.y_label.clone()
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc(y_desc)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(210, 210, 210))
        .y_label_formatter(&|v| tick(*v, if c.log_y { *v } else { top }))
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
                    .filter(|(_, v)| v.is_finite() && **v > base)
                    .map(|(i, &v)| {
                        let x = i as f64 + 0.1 + j as f64 * width;
                        Rectangle::new([(x, base), (x + width * 0.9, v)], color.filled())
                    }),
            )
            .map_err(plot_err)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.filled()));
        mark_diverged(root, &chart, (j, width, color, values), (base, top))?;
    }
    draw_legend(&mut chart)?;
    let style = TextStyle::from((FONT, 13).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    for (i, name) in c.categories.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, base));
        for (n, line) in category_label(name).iter().enumerate() {
            root.draw(&Text::new(
                line.clone(),
                (px, py + 6 + 15 * n as i32),
                style.clone(),
            ))
            .map_err(plot_err)?;
        }
    }
    root.present().map_err(plot_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (issue 51): a name holding NUL or ESC, drawn in a title, made an SVG that
    /// no reader takes ("reading the figure's SVG"), after every run of a campaign.
    #[test]
    fn a_title_with_control_characters_is_drawn_and_its_svg_read_back() {
        let dir = tempfile::tempdir().expect("dir");
        let stem = dir.path().join("f");
        let [png, svg] = save(&stem, (200, 100), |area| {
            area.titled("a\u{0}b\u{1b}[31mc\td", (FONT, 12))
                .map(drop)
                .map_err(|e| anyhow!("{e}"))
        })
        .expect("drawn");
        let text = std::fs::read_to_string(&svg).expect("svg");
        assert!(text.contains("a\u{fffd}b\u{fffd}[31mc"), "{text}");
        assert!(png.is_file());
        rasterise(&text, (200, 100)).expect("read back");
        assert_eq!(xml_text("x\ty\n".into()), "x\ty\n");
    }

    #[test]
    fn category_labels_break_at_spaces_and_after_hyphens_of_long_words() {
        assert_eq!(
            category_label("measurement-delay r1"),
            ["measurement-", "delay", "r1"]
        );
        assert_eq!(category_label("paper r2"), ["paper", "r2"]);
        assert_eq!(category_label("dos-drop r1"), ["dos-drop", "r1"]);
        assert_eq!(
            category_label("replay-example r1"),
            ["replay-", "example", "r1"]
        );
        assert_eq!(category_lines(&["a b c".into(), "d".into()]), 3);
    }

    #[test]
    fn drawable_ranges_are_finite_bounded_and_wide_enough_whatever_the_data() {
        for (lo, hi) in [
            (f64::NAN, f64::NAN),
            (f64::NEG_INFINITY, f64::INFINITY),
            (-1e300, 1e300),
            (1e300, 1e300 * (1.0 + f64::EPSILON)),
            (0.0, 0.0),
            (5.0, 5.0),
            (3.0, -2.0),
            (1e-300, 2e-300),
        ] {
            let (a, b) = drawable(lo, hi);
            assert!(
                a.is_finite() && b.is_finite() && a < b,
                "{lo}, {hi}: {a}, {b}"
            );
            assert!(a >= -AXIS_LIMIT && b <= AXIS_LIMIT, "{lo}, {hi}: {a}, {b}");
            let mid = a / 2.0 + b / 2.0;
            assert!(b - a >= mid.abs() * 1e-9, "{lo}, {hi}: {a}, {b}");
        }
        assert_eq!(
            drawable(-0.02, 0.03),
            (-0.02, 0.03),
            "ordinary data is kept"
        );
    }

    #[test]
    fn a_figure_of_diverged_data_is_drawn_in_bounded_time() {
        // Values of a diverged run (gain_k = 21000): 1e300, non-finite, collapsed. Drawing them
        // made the axis ticks loop for ever; the figure must now simply be written.
        let dir = tempfile::tempdir().expect("a scratch folder");
        let line = |label: &str, points: Vec<(f64, f64)>| Line {
            label: label.into(),
            color: PALETTE[0],
            points,
            keep: false,
            dashed: false,
        };
        let fig = Figure {
            title: "diverged".into(),
            x_label: "t (s)".into(),
            x_range: (0.0, 0.2),
            markers: vec![0.1],
            marker_label: "switch".into(),
            panels: vec![
                Panel {
                    title: "huge".into(),
                    y_label: "rad".into(),
                    kind: PanelKind::Lines(vec![line(
                        "e",
                        (0..200)
                            .map(|k| (k as f64 * 1e-3, 1e300 * k as f64))
                            .collect(),
                    )]),
                    guides: vec![],
                },
                Panel {
                    title: "non-finite".into(),
                    y_label: "rad".into(),
                    kind: PanelKind::Lines(vec![line(
                        "e",
                        vec![
                            (0.0, f64::NAN),
                            (0.1, f64::INFINITY),
                            (0.2, f64::NEG_INFINITY),
                        ],
                    )]),
                    guides: vec![],
                },
                Panel {
                    title: "collapsed".into(),
                    y_label: "rad".into(),
                    kind: PanelKind::Lines(vec![line("e", vec![(0.0, 1e300), (0.2, 1e300)])]),
                    guides: vec![],
                },
            ],
        };
        let written = save_figure(&fig, &dir.path().join("diverged"), (600, 600)).expect("drawn");
        for p in written {
            assert!(
                std::fs::metadata(&p).is_ok_and(|m| m.len() > 0),
                "{}",
                p.display()
            );
        }
        let bars = BarChart {
            title: "huge bars".into(),
            y_label: "RMSE".into(),
            categories: vec!["a".into(), "b".into()],
            series: vec![("s".into(), PALETTE[0], vec![1e300, f64::NAN])],
            log_y: false,
        };
        save_bars(&bars, &dir.path().join("bars"), (400, 300)).expect("drawn");
        let log_bars = BarChart {
            log_y: true,
            ..bars
        };
        save_bars(&log_bars, &dir.path().join("log-bars"), (400, 300)).expect("drawn");
    }

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

    /// A slow oscillation of ±0.01 with three short spikes of 0.43 (attack switches).
    fn spiky() -> Vec<f64> {
        (0..4000)
            .map(|k| {
                let t = f64::from(k) * 0.01;
                match k {
                    1000 | 1001 => -0.43,
                    2000 | 3000 => 0.3,
                    _ => 0.01 * (1.5 * t).sin(),
                }
            })
            .collect()
    }

    #[test]
    fn robust_range_clips_spikes_and_keeps_the_steady_state() {
        let r = robust_y_range(&spiky(), &[]);
        assert!(r.clips, "{r:?}");
        // The steady state fills the axis: ±0.01 plus the margin, not ±0.43.
        assert!(r.lo < -0.0099 && r.lo > -0.02, "{r:?}");
        assert!(r.hi > 0.0099 && r.hi < 0.02, "{r:?}");
        // The full range without the spikes: nothing is clipped.
        let calm: Vec<f64> = spiky().into_iter().filter(|v| v.abs() < 0.1).collect();
        let r = robust_y_range(&calm, &[]);
        assert!(!r.clips && r.lo < -0.0099 && r.hi > 0.0099, "{r:?}");
        assert!(r.hi - r.lo < 0.03, "{r:?}");
    }

    #[test]
    fn robust_range_holds_what_must_be_shown_and_ignores_order_and_nan() {
        // A band wider than the data: inside, with the data.
        let r = robust_y_range(&spiky(), &[-0.02, 0.02]);
        assert!(
            r.clips && r.lo <= -0.02 && r.hi >= 0.02 && r.hi < 0.1,
            "{r:?}"
        );
        // A kept curve that reaches 5: inside too, so the spikes are not clipped any more.
        let r = robust_y_range(&spiky(), &[0.0, 5.0]);
        assert!(!r.clips && r.lo <= -0.43 && r.hi >= 5.0, "{r:?}");
        let mut v = spiky();
        v.reverse();
        v.push(f64::NAN);
        v.push(f64::INFINITY);
        assert_eq!(robust_y_range(&v, &[]), robust_y_range(&spiky(), &[]));
        let empty = robust_y_range(&[], &[]);
        assert!(empty.lo < empty.hi && !empty.clips);
        let flat = robust_y_range(&[2.0; 10], &[]);
        assert!(flat.lo < 2.0 && flat.hi > 2.0 && !flat.clips, "{flat:?}");
    }

    #[test]
    fn excursions_are_runs_beyond_each_edge_with_their_farthest_point() {
        let pts: Vec<(f64, f64)> = [0.0, 2.0, 3.0, 1.5, 0.0, -2.0, -1.0, 0.5, 4.0]
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64, *v))
            .collect();
        let e = excursions(&pts, -1.5, 1.0);
        let got: Vec<(f64, f64, bool, usize)> =
            e.iter().map(|e| (e.t, e.v, e.above, e.points)).collect();
        assert_eq!(
            got,
            vec![
                (2.0, 3.0, true, 3),
                (5.0, -2.0, false, 1),
                (8.0, 4.0, true, 1)
            ]
        );
    }

    #[test]
    fn nearby_excursions_on_one_side_share_a_marker() {
        let ex = |t: f64, v: f64| Excursion {
            t,
            v,
            above: v > 0.0,
            points: 1,
        };
        let merged = merge_excursions(
            vec![
                ('a', ex(5.0, 0.2)),
                ('b', ex(5.1, 0.4)),
                ('a', ex(5.05, -0.3)),
                ('a', ex(9.0, 0.3)),
            ],
            0.5,
        );
        let got: Vec<(char, f64, f64, usize)> = merged
            .iter()
            .map(|(c, e)| (*c, e.t, e.v, e.points))
            .collect();
        assert_eq!(
            got,
            vec![('b', 5.1, 0.4, 2), ('a', 5.05, -0.3, 1), ('a', 9.0, 0.3, 1)]
        );
    }

    #[test]
    fn log_axis_spans_whole_decades_of_the_positive_values() {
        assert_eq!(
            decades([0.0, 0.004, 37.0, 99.0].into_iter()),
            (0.0001, 100.0)
        );
        assert_eq!(decades([0.0].into_iter()), (0.1, 100.0));
        let (lo, hi) = decades([5.0].into_iter());
        assert!(lo < 5.0 && hi > 5.0);
    }

    #[test]
    fn peak_labels_have_three_digits() {
        assert_eq!(peak(-0.4297), "\u{2212}0.430");
        assert_eq!(peak(0.03934), "0.0393");
        assert_eq!(peak(12.0), "12.0");
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
