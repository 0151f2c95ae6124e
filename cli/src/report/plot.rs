//! Rate-distortion plots (PNG and SVG) with plotters. Text is drawn with a bundled font
//! (DejaVu Sans, ASCII subset, `assets/fonts/`) through plotters' `ab_glyph` backend, so
//! PNGs have readable labels on machines without fontconfig or system fonts.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::run::{ModelReport, Report};
use super::steps::Setting;
use scode::error::{Error, Result};

const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans-ascii.ttf");
const SIZE: (u32, u32) = (900, 600);

/// One polyline and/or point set of a plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend entry; `None` for series that repeat an entry already shown.
    pub label: Option<String>,
    pub color: (u8, u8, u8),
    /// (x, y) in data units; non-positive values are dropped (log scales).
    pub points: Vec<(f64, f64)>,
    pub line: bool,
}

/// A log-log chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
}

const BLUE_: (u8, u8, u8) = (31, 100, 200);
const GREEN_: (u8, u8, u8) = (30, 150, 60);
const RED_: (u8, u8, u8) = (210, 40, 40);
const PURPLE_: (u8, u8, u8) = (130, 60, 170);

fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut ok = true;
    ONCE.call_once(|| {
        ok = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok();
    });
    if ok {
        Ok(())
    } else {
        Err(Error::Parameter("bundled plot font is invalid".into()))
    }
}

fn positive(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    points
        .iter()
        .copied()
        .filter(|&(x, y)| x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite())
        .collect()
}

/// Log range covering `values` with some margin (one decade around a single value).
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.1, 10.0);
    }
    let pad = ((hi / lo).log10() * 0.08).max(0.15);
    (lo / 10f64.powf(pad), hi * 10f64.powf(pad))
}

/// Tick values of a log axis over `lo..hi`: labelled ones at 1, 2 and 5 times a power of
/// ten (denser when that gives fewer than four), and grid lines at every integer multiple
/// of each power of ten. Chosen here rather than by plotters, whose log-axis ticks leave a
/// range within one decade with one label or none and repeat a decade's grid lines.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let within = |mantissas: &[f64]| -> Vec<f64> {
        let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        (first..=last)
            .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    let mut labelled = within(&[1.0, 2.0, 5.0]);
    if labelled.len() < 4 {
        labelled = within(&[1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0]);
    }
    let grid = within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    (labelled, grid)
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    chart: &Chart,
) -> std::result::Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let all: Vec<(f64, f64)> = chart
        .series
        .iter()
        .flat_map(|s| positive(&s.points))
        .collect();
    let (x0, x1) = log_range(all.iter().map(|p| p.0));
    let (y0, y1) = log_range(all.iter().map(|p| p.1));
    let ((x_labels, x_grid), (y_labels, y_grid)) = (log_ticks(x0, x1), log_ticks(y0, y1));
    let mut c = ChartBuilder::on(&root)
        .caption(&chart.title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(55)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (x0..x1)
                .log_scale()
                .with_key_points(x_labels)
                .with_light_points(x_grid),
            (y0..y1)
                .log_scale()
                .with_key_points(y_labels)
                .with_light_points(y_grid),
        )
        .map_err(err)?;
    c.configure_mesh()
        .x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .x_labels(12)
        .y_labels(12)
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .x_label_formatter(&|x| format!("{x:.1e}").replace(".0e", "e"))
        .y_label_formatter(&|y| {
            if *y >= 1e5 || *y < 0.1 {
                format!("{y:.0e}")
            } else {
                format!("{y}")
            }
        })
        .draw()
        .map_err(err)?;
    for s in &chart.series {
        let pts = positive(&s.points);
        let color = RGBColor(s.color.0, s.color.1, s.color.2);
        if s.line && pts.len() > 1 {
            c.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(err)?;
        }
        let anno = c
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(err)?;
        if let Some(label) = &s.label {
            anno.label(label.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        }
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 16))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Draws `chart` to `<stem>.png` and `<stem>.svg`.
pub fn render(chart: &Chart, stem: &Path) -> Result<()> {
    register_font()?;
    let (w, h) = SIZE;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(root, chart).map_err(|e| Error::Parameter(format!("cannot draw plot: {e}")))?;
    }
    let png_path = stem.with_extension("png");
    let file = std::fs::File::create(&png_path).map_err(|e| Error::io(&png_path, e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let png_err = |e: png::EncodingError| Error::io(&png_path, std::io::Error::other(e));
    let mut writer = enc.write_header().map_err(png_err)?;
    writer.write_image_data(&rgb).map_err(png_err)?;
    writer.finish().map_err(png_err)?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        draw(root, chart).map_err(|e| Error::Parameter(format!("cannot draw plot: {e}")))?;
    }
    let svg_path = stem.with_extension("svg");
    std::fs::write(&svg_path, svg).map_err(|e| Error::io(&svg_path, e))
}

/// (max error, y) of a model's measured points with settings matching `keep`, sorted by max
/// error (ties by y), so a line through them runs in error order.
fn points_of(
    m: &ModelReport,
    keep: impl Fn(&Setting) -> bool,
    y: impl Fn(&super::run::Measured) -> f64,
) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = m
        .points
        .iter()
        .filter(|p| keep(&p.setting))
        .filter_map(|p| p.measured().map(|me| (me.rd.max_error, y(me))))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    pts
}

/// The points of `pts` (sorted by error) that no other point beats in both error and size:
/// the smallest file at each accuracy. A baseline on a STEP part has files from several
/// tessellations at several bit counts, and a line through all of them would zig-zag
/// between tessellations.
fn lower_envelope(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for p in pts {
        // Walking from the smallest error up, a point is on the envelope when it is
        // smaller than every more accurate point (the last one kept is the smallest).
        if out.last().is_none_or(|q| p.1 < q.1) {
            out.push(p);
        }
    }
    out
}

/// The curves of one model, one colour per codec: scode fitted (line), scode raw (points),
/// Draco (one line per `-cl`), gltfpack (one line with and one without `-cc`); the
/// baselines' lines follow their smallest file at each accuracy. Labels are the codec
/// names; the caller drops repeated ones.
fn model_series(
    m: &ModelReport,
    draco_levels: &[u8],
    y: impl Fn(&super::run::Measured) -> f64 + Copy,
) -> Vec<Series> {
    let mut series = vec![
        Series {
            label: Some("scode (fitted)".into()),
            color: BLUE_,
            points: points_of(m, |s| matches!(s, Setting::Fitted { .. }), y),
            line: true,
        },
        Series {
            label: Some("scode raw".into()),
            color: GREEN_,
            points: points_of(m, |s| matches!(s, Setting::Raw { .. }), y),
            line: false,
        },
    ];
    for &cl in draco_levels {
        series.push(Series {
            label: Some("Draco".into()),
            color: RED_,
            points: lower_envelope(points_of(
                m,
                |s| matches!(s, Setting::Draco { cl: c, .. } if *c == cl),
                y,
            )),
            line: true,
        });
    }
    for cc in [true, false] {
        series.push(Series {
            label: Some("gltfpack".into()),
            color: PURPLE_,
            points: lower_envelope(points_of(
                m,
                |s| matches!(s, Setting::Gltfpack { cc: c, .. } if *c == cc),
                y,
            )),
            line: true,
        });
    }
    series.retain(|s| !s.points.is_empty());
    series
}

/// Keeps the first series of each label labelled (one legend entry per codec).
fn label_once(series: &mut [Series]) {
    let mut seen = std::collections::BTreeSet::new();
    for s in series {
        if let Some(l) = &s.label {
            if !seen.insert(l.clone()) {
                s.label = None;
            }
        }
    }
}

/// Bytes against max error for one model: scode fitted, scode raw, Draco (every `-cl`),
/// gltfpack.
pub fn model_chart(m: &ModelReport, draco_levels: &[u8]) -> Chart {
    let mut series = model_series(m, draco_levels, |me| me.rd.bytes as f64);
    label_once(&mut series);
    Chart {
        title: format!("{}: bytes vs max error", m.name),
        x_label: "max error (fraction of bbox diagonal)".into(),
        y_label: "bytes".into(),
        series,
    }
}

/// Bits per input vertex against max error for every model (sizes differ by orders of
/// magnitude between models; bits per vertex puts them on one scale): scode fitted, scode
/// raw, Draco at the first `-cl`, gltfpack.
pub fn corpus_chart(report: &Report) -> Chart {
    let levels: Vec<u8> = report.options.draco_cl.iter().copied().take(1).collect();
    let mut series: Vec<Series> = report
        .models
        .iter()
        .filter(|m| m.error.is_none())
        .flat_map(|m| model_series(m, &levels, |me| me.rd.bits_per_vertex))
        .collect();
    label_once(&mut series);
    Chart {
        title: "All models: bits per vertex vs max error".into(),
        x_label: "max error (fraction of bbox diagonal)".into(),
        y_label: "bits per input vertex".into(),
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axes_label_at_least_four_values_once_each() {
        for (lo, hi) in [
            (3e-4, 2.2e-3),
            (300.0, 30_000.0),
            (0.9, 1.1e6),
            (4.5e-5, 5.5e-5),
        ] {
            let (labelled, grid) = log_ticks(lo, hi);
            for ticks in [&labelled, &grid] {
                assert!(ticks.iter().all(|v| (lo..=hi).contains(v)), "{lo} {hi}");
                assert!(ticks.windows(2).all(|w| w[0] < w[1]), "{ticks:?}");
            }
            assert!(
                labelled.len() >= 4 || hi / lo < 1.5,
                "{lo} {hi}: {labelled:?}"
            );
            assert!(labelled.len() <= 20, "{lo} {hi}: {labelled:?}");
        }
        assert_eq!(
            log_ticks(300.0, 30_000.0).0,
            [500.0, 1e3, 2e3, 5e3, 1e4, 2e4]
        );
    }

    #[test]
    fn lower_envelope_keeps_the_smallest_file_at_each_accuracy() {
        // (error, bytes) sorted by error: 700 at 3e-4 is beaten by 500 at 2e-4 (more
        // accurate and smaller); 900 at 1e-4 stays (nothing is as accurate).
        let pts = vec![(1e-4, 900.0), (2e-4, 500.0), (3e-4, 700.0), (4e-4, 300.0)];
        assert_eq!(
            lower_envelope(pts),
            [(1e-4, 900.0), (2e-4, 500.0), (4e-4, 300.0)]
        );
        assert!(lower_envelope(Vec::new()).is_empty());
    }

    #[test]
    fn renders_png_and_svg_with_text() {
        let chart = Chart {
            title: "test: bytes vs max error".into(),
            x_label: "max error".into(),
            y_label: "bytes".into(),
            series: vec![
                Series {
                    label: Some("a".into()),
                    color: BLUE_,
                    points: vec![(1e-3, 500.0), (5e-4, 900.0), (0.0, 1.0)],
                    line: true,
                },
                Series {
                    label: None,
                    color: RED_,
                    points: vec![(2e-3, 300.0)],
                    line: false,
                },
            ],
        };
        let dir = std::env::temp_dir().join(format!("scode-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let stem = dir.join("chart");
        render(&chart, &stem).unwrap();
        let png = std::fs::read(stem.with_extension("png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), SIZE);
        // Text was drawn: the title band above the plot holds dark pixels.
        let dark = buf[..(40 * SIZE.0 * 3) as usize]
            .chunks(3)
            .filter(|p| p.iter().all(|&c| c < 100))
            .count();
        assert!(dark > 50, "no title text drawn ({dark} dark pixels)");
        let svg = std::fs::read_to_string(stem.with_extension("svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("max error"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
