//! Latency distribution plots in the HdrHistogram style, written as PNG and SVG.
//!
//! The x axis is the percentile on a log scale of 1/(1 − p): 0 %, 90 %, 99 %, 99.9 %, … are
//! equally spaced, so the tail, which is what a real-time loop cares about, gets as much room as
//! the median. The y axis (latency) is logarithmic too, because the series compared side by side
//! differ by orders of magnitude (a shared-memory flag next to a socket).
//!
//! Everything is pure Rust, as in `chaosctl`'s plots: plotters draws, text is rendered with
//! ab_glyph from the DejaVu Sans font compiled into the binary (no fontconfig or freetype on the
//! machine), and the bitmap is encoded with the `png` crate.

use crate::stats::Dist;
use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const FONT: &str = "sans-serif";
const PANEL: (u32, u32) = (900, 620);

/// The "tab10" palette: distinguishable, and the same colour order in every figure.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// One chart: several distributions of one quantity.
#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    /// What the values are, e.g. "round trip"; the axis says "… (µs)".
    pub quantity: String,
    pub series: Vec<Dist>,
}

fn fonts() -> Result<()> {
    static OK: OnceLock<bool> = OnceLock::new();
    let ok = *OK.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded DejaVu Sans font could not be loaded"))
    }
}

fn draw_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e:?}")
}

/// The x coordinate of quantile `q` in a series of `count` values: 1/(1 − q). The maximum
/// (q = 1) is drawn where a sample of that size resolves it, at 1 − 1/count.
pub fn x_of(q: f64, count: u64) -> f64 {
    let cap = (count.max(1)) as f64;
    if q >= 1.0 {
        cap
    } else {
        (1.0 / (1.0 - q)).min(cap).max(1.0)
    }
}

/// The percentile label of x = 1/(1 − p): 1 → "0%", 10 → "90%", 1000 → "99.9%", 2 → "50%".
pub fn percentile_label(x: f64) -> String {
    let p = 100.0 * (1.0 - 1.0 / x);
    let decimals = (x.log10().ceil() as i32 - 2).max(0) as usize;
    format!("{p:.decimals$}%")
}

/// A tick label for a latency in µs.
fn us_label(v: f64) -> String {
    if v >= 1.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Ticks covering [lo, hi]: 1-2-5 per decade over up to three decades, else decades only.
fn ticks_125(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    let steps: &[f64] = if hi / lo > 1e3 {
        &[1.0]
    } else {
        &[1.0, 2.0, 5.0]
    };
    while decade <= hi * 1.0001 {
        for &m in steps {
            let v = decade * m;
            if v >= lo * 0.9999 && v <= hi * 1.0001 {
                out.push(v);
            }
        }
        decade *= 10.0;
    }
    out
}

/// A series in plot coordinates: (1/(1 − p), µs), with its palette index.
struct Curve<'a> {
    color: usize,
    dist: &'a Dist,
    points: Vec<(f64, f64)>,
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel) -> Result<()> {
    let curves: Vec<Curve> = p
        .series
        .iter()
        .enumerate()
        .filter(|(_, d)| !d.points.is_empty())
        .map(|(i, d)| {
            let pts = d
                .points
                .iter()
                .filter(|pt| pt.1 > 0.0)
                .map(|&(q, ns)| (x_of(q, d.count), ns / 1e3))
                .collect();
            Curve {
                color: i,
                dist: d,
                points: pts,
            }
        })
        .collect();
    let xmax = curves
        .iter()
        .flat_map(|c| c.points.iter().map(|p| p.0))
        .fold(10.0f64, f64::max);
    let xmax = 10f64.powf(xmax.log10().ceil());
    let (ylo, yhi) = curves
        .iter()
        .flat_map(|c| c.points.iter().map(|p| p.1))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (ylo, yhi) = if ylo.is_finite() {
        (ylo / 1.3, yhi * 1.3)
    } else {
        (0.1, 1000.0)
    };
    // Head-room for the legend: the curves rise to the right, so the upper left is free if the
    // axis reaches far enough above the data for the legend's rows.
    let share = ((p.series.len() as f64 * 19.0 + 24.0) / 520.0).min(0.6);
    let yhi = yhi * (yhi / ylo).powf(share / (1.0 - share));
    let xkeys: Vec<f64> = (0..=xmax.log10().round() as i32)
        .map(|k| 10f64.powi(k))
        .collect();
    let ykeys = ticks_125(ylo, yhi);

    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, (FONT, 19))
        .margin(14)
        .x_label_area_size(48)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (1.0..xmax).log_scale().with_key_points(xkeys),
            (ylo..yhi).log_scale().with_key_points(ykeys),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("percentile")
        .y_desc(format!("{} (µs)", p.quantity))
        .x_label_formatter(&|x| percentile_label(*x))
        .y_label_formatter(&|y| us_label(*y))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(draw_err)?;
    for c in curves {
        let color = PALETTE[c.color % PALETTE.len()];
        chart
            .draw_series(LineSeries::new(c.points, color.stroke_width(2)))
            .map_err(draw_err)?
            .label(format!("{} (n = {})", c.dist.label, c.dist.count))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(3))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .draw()
        .map_err(draw_err)?;
    Ok(())
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    panels: &[Panel],
) -> Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let (top, body) = root.split_vertically(44);
    top.titled(title, (FONT, 22).into_font().style(FontStyle::Bold))
        .map_err(draw_err)?;
    let cols = panels.len().clamp(1, 2);
    let rows = panels.len().div_ceil(cols).max(1);
    for (panel, area) in panels.iter().zip(body.split_evenly((rows, cols)).iter()) {
        draw_panel(area, panel)?;
    }
    Ok(())
}

/// Writes `<prefix>.png` and `<prefix>.svg` and returns their paths.
pub fn save(title: &str, panels: &[Panel], prefix: &Path) -> Result<Vec<PathBuf>> {
    fonts()?;
    let cols = panels.len().clamp(1, 2) as u32;
    let rows = panels.len().div_ceil(cols as usize).max(1) as u32;
    let (w, h) = (PANEL.0 * cols, PANEL.1 * rows + 44);
    let png_path = prefix.with_extension("png");
    let svg_path = prefix.with_extension("svg");
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(&root, title, panels)?;
        root.present().map_err(draw_err)?;
    }
    let file = std::fs::File::create(&png_path)
        .with_context(|| format!("cannot create {}", png_path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc
        .write_header()
        .with_context(|| format!("cannot write {}", png_path.display()))?;
    writer
        .write_image_data(&rgb)
        .with_context(|| format!("cannot write {}", png_path.display()))?;
    writer
        .finish()
        .with_context(|| format!("cannot write {}", png_path.display()))?;
    {
        let root = SVGBackend::new(&svg_path, (w, h)).into_drawing_area();
        draw(&root, title, panels)?;
        root.present().map_err(draw_err)?;
    }
    Ok(vec![png_path, svg_path])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::histogram;

    #[test]
    fn percentile_axis() {
        assert_eq!(percentile_label(1.0), "0%");
        assert_eq!(percentile_label(2.0), "50%");
        assert_eq!(percentile_label(10.0), "90%");
        assert_eq!(percentile_label(100.0), "99%");
        assert_eq!(percentile_label(1000.0), "99.9%");
        assert_eq!(percentile_label(100_000.0), "99.999%");
        assert_eq!(x_of(0.0, 100), 1.0);
        assert!((x_of(0.99, 1000) - 100.0).abs() < 1e-9);
        // The max sits where the sample size resolves it; nothing is drawn beyond that.
        assert_eq!(x_of(1.0, 1000), 1000.0);
        assert_eq!(x_of(0.99999, 1000), 1000.0);
        assert_eq!(
            ticks_125(0.3, 60.0),
            vec![0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0]
        );
        assert_eq!(ticks_125(0.03, 600.0), vec![0.1, 1.0, 10.0, 100.0]);
        assert_eq!(us_label(0.25), "0.25");
        assert_eq!(us_label(20.0), "20");
    }

    #[test]
    fn writes_png_and_svg() {
        let mut a = histogram();
        let mut b = histogram();
        for v in 1..=20_000u64 {
            a.record(200 + v % 97).unwrap();
            b.record(10_000 + (v * 7919) % 5_000).unwrap();
        }
        let panels = [Panel {
            title: "round trip".into(),
            quantity: "round trip".into(),
            series: vec![
                Dist::of_histogram("fast", &a),
                Dist::of_histogram("slow", &b),
                Dist::of_histogram("empty", &histogram()),
            ],
        }];
        let dir = std::env::temp_dir().join(format!("chaosd-bench-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let files = save("test", &panels, &dir.join("lat")).unwrap();
        let png = std::fs::read(&files[0]).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let svg = std::fs::read_to_string(&files[1]).unwrap();
        for label in ["99.9%", "percentile", "fast (n = 20000)", "slow"] {
            assert!(svg.contains(label), "{label} missing from the SVG");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
