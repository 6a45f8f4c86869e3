//! Figures for the analysis commands: one description, drawn twice, to PNG and to SVG.
//!
//! Everything is pure Rust: plotters draws, `ab_glyph` renders text from the DejaVu Sans font
//! embedded by the `dejavu` crate (no fontconfig or freetype on the machine), and `png` encodes the
//! bitmap. A [`Figure`] is a grid of panels, each a line/marker [`Chart`] or a categorical
//! [`Grid`] (the basin maps). Time series denser than the pixels are drawn as their min/max band
//! per pixel column, which looks like the overdrawn lines and keeps both files small; PNGs are
//! written with a 256-colour palette for the same reason.

use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Distinguishable colours (the "tab10" palette).
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];
pub const GREY: RGBColor = RGBColor(120, 120, 120);
pub const DARK: RGBColor = RGBColor(40, 40, 40);

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Style {
    /// A polyline of the given width.
    Line(u32),
    /// Circles of the given radius.
    Markers { size: u32, filled: bool },
    /// A polyline with filled circles at the points.
    LineMarkers { width: u32, size: u32 },
    /// The points as a closed, filled polygon (e.g. an obstacle's disc).
    Fill,
}

#[derive(Clone, Debug)]
pub struct Series {
    pub label: Option<String>,
    pub color: RGBColor,
    pub style: Style,
    /// Opacity in (0, 1].
    pub alpha: f64,
    pub points: Vec<(f64, f64)>,
    /// Symmetric y error bars, one per point.
    pub yerr: Option<Vec<f64>>,
}

impl Series {
    pub fn new(
        label: Option<String>,
        color: RGBColor,
        style: Style,
        points: Vec<(f64, f64)>,
    ) -> Self {
        Self {
            label,
            color,
            style,
            alpha: 1.0,
            points,
            yerr: None,
        }
    }
    pub fn alpha(mut self, a: f64) -> Self {
        self.alpha = a;
        self
    }
    pub fn yerr(mut self, e: Vec<f64>) -> Self {
        self.yerr = Some(e);
        self
    }
}

/// A shaded x-interval (e.g. the paper's claimed μ-window).
#[derive(Clone, Debug)]
pub struct Band {
    pub from: f64,
    pub to: f64,
    pub color: RGBColor,
    pub label: Option<String>,
}

/// A dashed reference line: horizontal at y = value, or vertical at x = value.
#[derive(Clone, Debug)]
pub struct Rule {
    pub value: f64,
    pub vertical: bool,
    pub color: RGBColor,
    pub label: Option<String>,
}

/// An x-y chart.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub bands: Vec<Band>,
    pub rules: Vec<Rule>,
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Draw a legend (only series, bands and rules with labels appear).
    pub legend: bool,
}

/// A categorical map over a regular (x, y) grid, with its own legend column.
#[derive(Clone, Debug)]
pub struct Grid {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// Category of cell (x index i, y index j) at `cells[j * xs.len() + i]`.
    pub cells: Vec<usize>,
    pub categories: Vec<(String, RGBColor)>,
}

#[derive(Clone, Debug)]
pub enum Panel {
    Chart(Chart),
    Grid(Grid),
}

/// Panels on a grid, row by row, with an optional overall title.
#[derive(Clone, Debug)]
pub struct Figure {
    pub title: Option<String>,
    pub panels: Vec<Panel>,
    pub cols: usize,
    pub panel_size: (u32, u32),
}

const FONT: &str = "sans-serif";

fn fonts() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded DejaVu Sans font could not be loaded"))
    }
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e:?}")
}

/// Makes the directory an output prefix writes into, so that a long run does not end in "No
/// such file or directory" with its results lost: the commands call it before they compute.
pub fn make_room(prefix: &Path) -> Result<()> {
    if let Some(dir) = prefix.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create directory {}", dir.display()))?;
    }
    Ok(())
}

/// `prefix` + `.ext` (appended, so a prefix such as `out/mu0.2_time` keeps its dots).
pub fn with_ext(prefix: &Path, ext: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

impl Figure {
    fn size(&self) -> (u32, u32) {
        let cols = self.cols.max(1);
        let rows = self.panels.len().div_ceil(cols).max(1);
        let title = if self.title.is_some() { 40 } else { 0 };
        (
            self.panel_size.0 * cols as u32,
            self.panel_size.1 * rows as u32 + title,
        )
    }

    /// Writes `prefix.png` and `prefix.svg`; returns their paths.
    pub fn save(&self, prefix: &Path) -> Result<Vec<PathBuf>> {
        fonts()?;
        make_room(prefix)?;
        let (w, h) = self.size();
        let png_path = with_ext(prefix, "png");
        let svg_path = with_ext(prefix, "svg");
        let mut buf = vec![255u8; w as usize * h as usize * 3];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            self.draw(&root)?;
            root.present().map_err(plot_err)?;
        }
        write_png(&png_path, &buf, w, h)?;
        {
            let root = SVGBackend::new(&svg_path, (w, h)).into_drawing_area();
            self.draw(&root)?;
            root.present().map_err(plot_err)?;
        }
        Ok(vec![png_path, svg_path])
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        root.fill(&WHITE).map_err(plot_err)?;
        let body = match &self.title {
            Some(t) => {
                let (top, rest) = root.split_vertically(40);
                top.titled(t, (FONT, 20).into_font().style(FontStyle::Bold))
                    .map_err(plot_err)?;
                rest
            }
            None => root.clone(),
        };
        let cols = self.cols.max(1);
        let rows = self.panels.len().div_ceil(cols).max(1);
        let areas = body.split_evenly((rows, cols));
        for (panel, area) in self.panels.iter().zip(areas.iter()) {
            match panel {
                Panel::Chart(c) => draw_chart(area, c)?,
                Panel::Grid(g) => draw_grid(area, g)?,
            }
        }
        Ok(())
    }
}

fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<()> {
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    let (palette, indices) = quantize(rgb);
    enc.set_color(png::ColorType::Indexed);
    enc.set_palette(palette);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::High);
    let mut writer = enc
        .write_header()
        .with_context(|| format!("cannot write {}", path.display()))?;
    writer
        .write_image_data(&indices)
        .with_context(|| format!("cannot write {}", path.display()))?;
    writer
        .finish()
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// An indexed-colour version of an RGB image: the 256 most frequent colours form the palette and
/// every pixel takes the nearest of them. Plots are a few flat colours plus their antialiasing
/// blends, so this is visually lossless and makes the files several times smaller.
fn quantize(rgb: &[u8]) -> (Vec<u8>, Vec<u8>) {
    use std::collections::HashMap;
    let mut counts: HashMap<[u8; 3], usize> = HashMap::new();
    for p in rgb.chunks_exact(3) {
        *counts.entry([p[0], p[1], p[2]]).or_default() += 1;
    }
    let mut by_count: Vec<([u8; 3], usize)> = counts.into_iter().collect();
    by_count.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let palette: Vec<[u8; 3]> = by_count.iter().take(256).map(|c| c.0).collect();
    let nearest = |c: [u8; 3]| -> u8 {
        let d = |p: &[u8; 3]| {
            (0..3)
                .map(|i| (p[i] as i32 - c[i] as i32).pow(2))
                .sum::<i32>()
        };
        (0..palette.len())
            .min_by_key(|&i| d(&palette[i]))
            .unwrap_or(0) as u8
    };
    let lookup: HashMap<[u8; 3], u8> = by_count.iter().map(|(c, _)| (*c, nearest(*c))).collect();
    let indices = rgb
        .chunks_exact(3)
        .map(|p| lookup.get(&[p[0], p[1], p[2]]).copied().unwrap_or(0))
        .collect();
    (palette.concat(), indices)
}

fn finite_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    (lo <= hi).then_some((lo, hi))
}

fn padded(r: Option<(f64, f64)>, pad: f64) -> (f64, f64) {
    match r {
        Some((a, b)) if b > a => {
            let d = (b - a) * pad;
            (a - d, b + d)
        }
        Some((a, _)) => (a - 1.0, a + 1.0),
        None => (0.0, 1.0),
    }
}

/// The upper and lower edges (max and min per column) of a series whose x never decreases,
/// `bins` columns wide.
type Polyline = Vec<(f64, f64)>;

fn band(points: &[(f64, f64)], bins: usize) -> (Polyline, Polyline) {
    let (x0, x1) = (points[0].0, points[points.len() - 1].0);
    if x1.partial_cmp(&x0) != Some(std::cmp::Ordering::Greater) {
        return (points.to_vec(), points.to_vec());
    }
    let (mut upper, mut lower) = (Vec::with_capacity(bins), Vec::with_capacity(bins));
    let mut i = 0;
    for b in 0..bins {
        let edge = x0 + (x1 - x0) * (b + 1) as f64 / bins as f64;
        let start = i;
        while i < points.len() && (points[i].0 <= edge || b + 1 == bins) {
            i += 1;
        }
        let chunk = &points[start..i];
        if chunk.is_empty() {
            continue;
        }
        let x = 0.5 * (chunk[0].0 + chunk[chunk.len() - 1].0);
        let (lo, hi) = chunk
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.1), hi.max(p.1))
            });
        upper.push((x, hi));
        lower.push((x, lo));
    }
    (upper, lower)
}

fn is_sorted_by_x(points: &[(f64, f64)]) -> bool {
    points.windows(2).all(|w| w[0].0 <= w[1].0)
}

fn draw_chart<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, c: &Chart) -> Result<()> {
    let xr = c.x_range.unwrap_or_else(|| {
        padded(
            finite_range(c.series.iter().flat_map(|s| s.points.iter().map(|p| p.0))),
            0.02,
        )
    });
    let yr = c.y_range.unwrap_or_else(|| {
        padded(
            finite_range(c.series.iter().flat_map(|s| {
                let err = s.yerr.as_deref();
                s.points.iter().enumerate().flat_map(move |(i, p)| {
                    let e = err.and_then(|e| e.get(i)).copied().unwrap_or(0.0);
                    [p.1 - e, p.1 + e]
                })
            })),
            0.05,
        )
    });
    let (pw, _) = area.dim_in_pixel();
    let mut chart = ChartBuilder::on(area)
        .caption(&c.title, (FONT, 17))
        .margin(10)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc(&c.x_label)
        .y_desc(&c.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(plot_err)?;
    for b in c.bands.iter().filter(|b| b.from.max(xr.0) < b.to.min(xr.1)) {
        let color = b.color;
        let r = chart
            .draw_series(std::iter::once(Rectangle::new(
                [(b.from.max(xr.0), yr.0), (b.to.min(xr.1), yr.1)],
                color.mix(0.15).filled(),
            )))
            .map_err(plot_err)?;
        if let Some(l) = &b.label {
            r.label(l.clone()).legend(move |(x, y)| {
                Rectangle::new([(x, y - 6), (x + 16, y + 6)], color.mix(0.3).filled())
            });
        }
    }
    for rule in &c.rules {
        let pts = if rule.vertical {
            vec![(rule.value, yr.0), (rule.value, yr.1)]
        } else {
            vec![(xr.0, rule.value), (xr.1, rule.value)]
        };
        let style = rule.color.stroke_width(1);
        let r = chart
            .draw_series(DashedLineSeries::new(pts, 6, 4, style))
            .map_err(plot_err)?;
        if let Some(l) = &rule.label {
            let color = rule.color;
            r.label(l.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(1))
            });
        }
    }
    for s in &c.series {
        if s.points.is_empty() {
            continue;
        }
        let color = s.color.mix(s.alpha);
        let bins = pw as usize;
        if let Some(err) = &s.yerr {
            chart
                .draw_series(s.points.iter().zip(err).filter(|(_, e)| e.is_finite()).map(
                    |(p, e)| {
                        PathElement::new(
                            vec![(p.0, p.1 - e), (p.0, p.1 + e)],
                            color.stroke_width(1),
                        )
                    },
                ))
                .map_err(plot_err)?;
        }
        let anno = match s.style {
            Style::Line(w) if s.points.len() > 4 * bins && is_sorted_by_x(&s.points) => {
                // Denser than the pixels: fill the min/max band, which is what the lines would
                // cover, and compresses far better than thousands of overdrawn strokes.
                let (upper, lower) = band(&s.points, (bins / 2).max(2));
                let outline: Vec<(f64, f64)> =
                    upper.iter().chain(lower.iter().rev()).copied().collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, color.filled())))
                    .map_err(plot_err)?;
                chart
                    .draw_series(LineSeries::new(upper, color.stroke_width(w)))
                    .map_err(plot_err)?;
                chart
                    .draw_series(LineSeries::new(lower, color.stroke_width(w)))
                    .map_err(plot_err)?
            }
            Style::Line(w) => chart
                .draw_series(LineSeries::new(s.points.clone(), color.stroke_width(w)))
                .map_err(plot_err)?,
            Style::Markers { size, filled } => {
                let style = if filled {
                    color.filled()
                } else {
                    color.stroke_width(1)
                };
                chart
                    .draw_series(s.points.iter().map(|p| Circle::new(*p, size, style)))
                    .map_err(plot_err)?
            }
            Style::Fill => chart
                .draw_series(std::iter::once(Polygon::new(
                    s.points.clone(),
                    color.filled(),
                )))
                .map_err(plot_err)?,
            Style::LineMarkers { width, size } => {
                chart
                    .draw_series(LineSeries::new(s.points.clone(), color.stroke_width(width)))
                    .map_err(plot_err)?;
                chart
                    .draw_series(
                        s.points
                            .iter()
                            .map(|p| Circle::new(*p, size, color.filled())),
                    )
                    .map_err(plot_err)?
            }
        };
        if let Some(l) = &s.label {
            // One element type for every style: a line sample plus a marker, either possibly empty.
            let (line, marker, filled) = match s.style {
                Style::Line(w) => (w.max(2), 0, true),
                Style::Fill => (8, 0, true),
                Style::Markers { size, filled } => (0, size.max(3), filled),
                Style::LineMarkers { width, size } => (width, size.max(3), true),
            };
            let c0 = s.color;
            anno.label(l.clone()).legend(move |(x, y)| {
                let line_style = if line > 0 {
                    c0.stroke_width(line)
                } else {
                    TRANSPARENT.stroke_width(0)
                };
                let marker_style = if filled {
                    c0.filled()
                } else {
                    c0.stroke_width(1)
                };
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(0, 0), (18, 0)], line_style)
                    + Circle::new((9, 0), marker, marker_style)
            });
        }
    }
    if c.legend {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font((FONT, 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_err)?;
    }
    Ok(())
}

fn draw_grid<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, g: &Grid) -> Result<()> {
    let (w, _) = area.dim_in_pixel();
    let legend_w = 210.min(w / 3);
    let (plot_area, legend_area) = area.split_horizontally(w - legend_w);
    let step = |v: &[f64]| {
        if v.len() > 1 {
            (v[v.len() - 1] - v[0]) / (v.len() - 1) as f64
        } else {
            1.0
        }
    };
    let (dx, dy) = (step(&g.xs), step(&g.ys));
    let xr = (g.xs[0] - dx / 2.0, g.xs[g.xs.len() - 1] + dx / 2.0);
    let yr = (g.ys[0] - dy / 2.0, g.ys[g.ys.len() - 1] + dy / 2.0);
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&g.title, (FONT, 17))
        .margin(10)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(&g.x_label)
        .y_desc(&g.y_label)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(plot_err)?;
    let nx = g.xs.len();
    chart
        .draw_series(g.cells.iter().enumerate().map(|(idx, &cat)| {
            let (i, j) = (idx % nx, idx / nx);
            let (x, y) = (g.xs[i], g.ys[j]);
            let color = g.categories.get(cat).map(|c| c.1).unwrap_or(WHITE);
            Rectangle::new(
                [(x - dx / 2.0, y - dy / 2.0), (x + dx / 2.0, y + dy / 2.0)],
                color.filled(),
            )
        }))
        .map_err(plot_err)?;
    // Legend: only the categories that occur, in their order.
    let mut row = 0;
    for (k, (name, color)) in g.categories.iter().enumerate() {
        if !g.cells.contains(&k) {
            continue;
        }
        let y = 60 + 24 * row;
        legend_area
            .draw(&Rectangle::new([(8, y), (26, y + 16)], color.filled()))
            .map_err(plot_err)?;
        legend_area
            .draw(&Rectangle::new(
                [(8, y), (26, y + 16)],
                DARK.stroke_width(1),
            ))
            .map_err(plot_err)?;
        legend_area
            .draw(&Text::new(name.clone(), (34, y + 1), (FONT, 14)))
            .map_err(plot_err)?;
        row += 1;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_keeps_extremes_and_shrinks() {
        let pts: Vec<(f64, f64)> = (0..10_000)
            .map(|i| (i as f64, ((i % 7) as f64) - 3.0))
            .collect();
        let (upper, lower) = band(&pts, 100);
        assert_eq!((upper.len(), lower.len()), (100, 100));
        assert!(upper.iter().all(|p| p.1 == 3.0) && lower.iter().all(|p| p.1 == -3.0));
        assert!(is_sorted_by_x(&upper));
    }

    #[test]
    fn with_ext_appends() {
        assert_eq!(
            with_ext(Path::new("out/mu0.2_time"), "png"),
            PathBuf::from("out/mu0.2_time.png")
        );
    }

    #[test]
    fn figure_writes_png_and_svg() {
        let dir = std::env::temp_dir().join(format!("chaosctl-plot-{}", std::process::id()));
        let fig = Figure {
            title: Some("test μ λ q̇".into()),
            panels: vec![Panel::Chart(Chart {
                title: "sine".into(),
                x_label: "t (s)".into(),
                y_label: "y".into(),
                series: vec![Series::new(
                    Some("sin".into()),
                    PALETTE[0],
                    Style::Line(1),
                    (0..100)
                        .map(|i| (i as f64 / 10.0, (i as f64 / 10.0).sin()))
                        .collect(),
                )],
                legend: true,
                ..Default::default()
            })],
            cols: 1,
            panel_size: (400, 300),
        };
        let files = fig.save(&dir.join("fig")).unwrap();
        let png = std::fs::read(&files[0]).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let svg = std::fs::read_to_string(&files[1]).unwrap();
        assert!(svg.contains("<svg") && svg.contains("sine"));
        std::fs::remove_dir_all(dir).ok();
    }
}
