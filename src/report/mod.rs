//! `--report DIR`: one self-contained HTML page (inline SVG figures drawn with
//! plotters, no external files or scripts), one module per command as the
//! command files are; this one holds what every page shares (the charts, the
//! page around them, the tracks as drawn).
//!
//! A report only draws: every figure it shows is computed by the library
//! and carried in the command's result (tests/module_cycles.rs checks that
//! no module here calls into the library's computing stages).
pub mod compare;
pub mod diagnose;
pub mod fit;
pub mod inverse;
pub mod localize;
pub mod methods;
pub mod navigate;

use kinegen_analysis::model_on_log::run::Run;
use kinegen_analysis::model_on_log::track_rows::{against_truth, TrackRows};
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

pub(crate) const W: u32 = 560;
pub(crate) const H: u32 = 420;

pub(crate) type Series<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);

fn bounds(series: &[Series]) -> ((f64, f64), (f64, f64)) {
    let pts = series.iter().flat_map(|s| s.2.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in pts {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if !x0.is_finite() {
        return ((0.0, 1.0), (0.0, 1.0));
    }
    // a flat series (a constant wheel rate) gets 5% of its value either
    // side, not a range of 1e-9 whose every tick reads the same number
    let pad = |lo: f64, hi: f64| {
        let span = hi - lo;
        let size = lo.abs().max(hi.abs()).max(1.0);
        if span <= 1e-9 * size {
            0.05 * size
        } else {
            0.05 * span
        }
    };
    let (px, py) = (pad(x0, x1), pad(y0, y1));
    ((x0 - px, x1 + px), (y0 - py, y1 + py))
}

/// Index buckets a drawn series is cut into at most (see [`decimated`]).
const BUCKETS: usize = 1000;

/// At most about 4 x [`BUCKETS`] points of `pts`: in each bucket of consecutive
/// points, the ones with the smallest and largest x and y, in their order. A
/// million-row log would otherwise put millions of SVG elements in the page
/// (223 MB seen); this keeps every extreme, so a spike or a collapse stays
/// visible.
pub(crate) fn decimated(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    series_of(pts.len(), pts.iter().copied())
}

/// The points of a series, decimated as they are computed (see [`decimated`]).
pub(crate) fn series_of(len: usize, pts: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    let mut d = Decimator::new(len);
    pts.for_each(|p| d.push(p));
    d.finish()
}

/// [`decimated`] fed one point at a time, for series computed on the fly: a
/// long log's plotted series are never held whole (a 200 MB log would need
/// hundreds of MB for them).
struct Decimator {
    /// Points per bucket (usize::MAX: keep every point).
    size: usize,
    chunk: Vec<(f64, f64)>,
    out: Vec<(f64, f64)>,
    last: Option<(f64, f64)>,
}

impl Decimator {
    /// For a series of `len` points.
    fn new(len: usize) -> Decimator {
        let size = if len <= 4 * BUCKETS {
            usize::MAX
        } else {
            len.div_ceil(BUCKETS)
        };
        Decimator {
            size,
            chunk: Vec::new(),
            out: Vec::with_capacity(len.min(4 * BUCKETS + 1)),
            last: None,
        }
    }

    fn push(&mut self, p: (f64, f64)) {
        self.last = Some(p);
        if self.size == usize::MAX {
            self.out.push(p);
            return;
        }
        self.chunk.push(p);
        if self.chunk.len() == self.size {
            self.flush();
        }
    }

    /// Keep the bucket's points with the smallest and largest x and y, in order.
    fn flush(&mut self) {
        let chunk = &self.chunk;
        if chunk.is_empty() {
            return;
        }
        let pick = |key: &dyn Fn(&(f64, f64)) -> f64, max: bool| {
            let cmp =
                |a: &(usize, &(f64, f64)), c: &(usize, &(f64, f64))| key(a.1).total_cmp(&key(c.1));
            let it = chunk.iter().enumerate();
            if max { it.max_by(cmp) } else { it.min_by(cmp) }.map_or(0, |x| x.0)
        };
        let mut keep = [
            pick(&|p| p.0, false),
            pick(&|p| p.0, true),
            pick(&|p| p.1, false),
            pick(&|p| p.1, true),
        ];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                self.out.push(chunk[k]);
                last = k;
            }
        }
        self.chunk.clear();
    }

    fn finish(mut self) -> Vec<(f64, f64)> {
        self.flush();
        if self.out.last() != self.last.as_ref() {
            self.out.extend(self.last);
        }
        self.out
    }
}

/// A line (or scatter) chart as an SVG string.
pub(crate) fn chart(
    title: &str,
    xl: &str,
    yl: &str,
    series: &[Series],
    scatter: bool,
    equal: bool,
    marks: &[(f64, f64)],
) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let span = squared(legend_room(bounds(series), series), equal);
        let ((_, _), (y0, y1)) = span;
        let mut c = axes(&root, title, xl, yl, span)?;
        // a stretch of a tenth of a second in a minute is under a pixel:
        // every mark is drawn at least 0.6% of the span wide (3 px)
        let ((x0, x1), _) = span;
        let least = 0.006 * (x1 - x0);
        for (a, b) in marks {
            let widen = (least - (b - a)).max(0.0) / 2.0;
            c.draw_series(std::iter::once(Rectangle::new(
                [(*a - widen, y0), (*b + widen, y1)],
                RGBColor(255, 150, 150).mix(0.6).filled(),
            )))
            .map_err(|e| e.to_string())?;
        }
        if series.iter().all(|s| s.2.is_empty()) {
            // an error chart of a run without a ground truth: empty axes
            // under a legend read as a track that was drawn and lost
            let style = ("sans-serif", 18).into_font().color(&BLACK.mix(0.6));
            let (x, y) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
            c.draw_series(std::iter::once(Text::new(
                "nothing to draw: no series has data in this run",
                (x, y),
                style.pos(plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Center,
                    plotters::style::text_anchor::VPos::Center,
                )),
            )))
            .map_err(|e| e.to_string())?;
        }
        // a series without points (the ground truth of a log that has none)
        // gets no legend entry
        for (name, color, pts) in series.iter().filter(|s| !s.2.is_empty()) {
            let color = *color;
            let pts = &decimated(pts);
            // in a scatter chart, a two-point series is a reference line
            // a series named "" is drawn without a legend entry (one of many
            // covariance ellipses)
            if scatter && pts.len() > 2 {
                let d = c
                    .draw_series(pts.iter().map(|p| Circle::new(*p, 1, color.filled())))
                    .map_err(|e| e.to_string())?;
                if !name.is_empty() {
                    d.label(*name)
                        .legend(move |(x, y)| Circle::new((x + 8, y), 3, color.filled()));
                }
            } else {
                let width = if name.is_empty() { 1 } else { 2 };
                let d = c
                    .draw_series(LineSeries::new(
                        pts.iter().copied(),
                        color.stroke_width(width),
                    ))
                    .map_err(|e| e.to_string())?;
                if !name.is_empty() {
                    d.label(*name).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                    });
                }
            }
        }
        // at the top, in the room `legend_room` leaves above the data (none
        // without an entry: an empty box)
        if series.iter().any(|s| !s.0.is_empty() && !s.2.is_empty()) {
            c.configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// Width of the legend strip beside a chart, px.
pub(crate) const LEGEND_W: u32 = 170;

/// A legend in its own strip beside a chart, where it covers no data: each
/// named entry a line (or, `true`, a dot) in its colour and its name.
pub(crate) fn legend_strip<'a>(
    strip: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    entries: impl Iterator<Item = (&'a str, RGBColor, bool)>,
) -> Result<(), String> {
    for (i, (name, color, dot)) in entries.filter(|e| !e.0.is_empty()).enumerate() {
        let y = 40 + 22 * i as i32;
        if dot {
            strip
                .draw(&Circle::new((14, y), 4, color.filled()))
                .map_err(|e| e.to_string())?;
        } else {
            strip
                .draw(&PathElement::new(
                    vec![(4, y), (24, y)],
                    color.stroke_width(2),
                ))
                .map_err(|e| e.to_string())?;
        }
        strip
            .draw(&Text::new(
                name.to_string(),
                (30, y - 7),
                ("sans-serif", 13),
            ))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// `span` with room above the data for the legend, which plotters draws
/// inside the plot at the upper right: without it the legend covers the
/// data there (a flat wheel rate, a reference line at the top).
fn legend_room(span: ((f64, f64), (f64, f64)), series: &[Series]) -> ((f64, f64), (f64, f64)) {
    let entries = series.iter().filter(|s| !s.0.is_empty()).count();
    if entries == 0 {
        return span;
    }
    let ((x0, x1), (y0, y1)) = span;
    // each legend line takes about 20 px of the plot's height (H less the
    // caption and the x labels), plus its border and the gap plotters leaves
    // above it; measured in Chromium: 20 px a line and 16 px left a curve's
    // peak under a two-line legend
    let plot = f64::from(H) - 80.0;
    let frac = ((entries as f64 * 22.0 + 30.0) / plot).min(0.6);
    ((x0, x1), (y0, y1 + (y1 - y0) * frac / (1.0 - frac)))
}

/// `span` made square about its centre when `equal` (a map: metres the
/// same both ways).
pub(crate) fn squared(span: ((f64, f64), (f64, f64)), equal: bool) -> ((f64, f64), (f64, f64)) {
    let ((x0, x1), (y0, y1)) = span;
    if !equal {
        return span;
    }
    let (cx, cy, half) = (
        (x0 + x1) / 2.0,
        (y0 + y1) / 2.0,
        (x1 - x0).max(y1 - y0) / 2.0,
    );
    ((cx - half, cx + half), (cy - half, cy + half))
}

/// A chart over real numbers on both axes.
pub(crate) type RealChart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The captioned axes every chart of the reports draws on.
pub(crate) fn axes<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    title: &str,
    xl: &str,
    yl: &str,
    ((x0, x1), (y0, y1)): ((f64, f64), (f64, f64)),
) -> Result<RealChart<'a, 'b>, String> {
    let mut c = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    c.configure_mesh()
        .x_desc(xl)
        .y_desc(yl)
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(c)
}

pub(crate) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

pub(crate) fn page(
    title: &str,
    answer: &[String],
    intro: &str,
    figures: &[String],
    tables: &str,
    warnings: &[String],
    doc: &Value,
) -> String {
    let figs: String = figures
        .iter()
        .map(|f| format!("<figure>{f}</figure>"))
        .collect();
    // every command's warnings (fit's identifiability, inputs out of range...)
    // stand above its results
    let warnings: String = warnings
        .iter()
        .map(|w| format!("<p class=\"warn\">warning: {}</p>", esc(w)))
        .collect();
    // the answer the terminal gives, in a box above everything else
    let answer = if answer.is_empty() {
        String::new()
    } else {
        format!(
            "<div class=\"answer\"><pre>{}</pre></div>",
            esc(&answer.join("\n"))
        )
    };
    format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
body{{font-family:sans-serif;margin:24px;color:#222;max-width:1200px}}\
figure{{display:inline-block;margin:6px;border:1px solid #ddd}}\
table{{border-collapse:collapse;margin:12px 0}}td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}\
th{{background:#f3f3f3}}td:first-child{{text-align:left}}.warn{{color:#a40}}pre{{background:#f7f7f7;padding:8px;overflow:auto;max-height:300px}}\
.answer{{border:2px solid #2a6;border-radius:6px;background:#f2fbf5;margin:12px 0}}.answer pre{{background:none;max-height:none;margin:0}}\
</style></head><body><h1>{t}</h1>{answer}{intro}{warnings}{tables}<div>{figs}</div>\
<details><summary>JSON</summary><pre>{json}</pre></details></body></html>\n",
        t = esc(title),
        json = esc(&serde_json::to_string_pretty(doc).unwrap_or_default())
    )
}

/// The model's track where the pose sensor sees it (an off-centre tracker's
/// point, not the body origin), so it is drawn against what was measured.
fn traj(run: &Run, tr: &dyn TrackRows) -> Vec<(f64, f64)> {
    series_of(
        run.t.len(),
        tr.rows(run).map(|row| (row.measured[0], row.measured[1])),
    )
}

/// What the pages draw of one track, from one reading of it (a long log's
/// track is computed as it is read, see `kinegen_analysis::model_on_log::track_rows`);
/// [`traj`] alone for a track drawn only as a trajectory.
struct Drawn {
    /// The track where the pose sensor sees it (see [`traj`]).
    traj: Vec<(f64, f64)>,
    /// Position error against time.
    pos_err: Vec<(f64, f64)>,
    /// Heading-error rate residual per step against speed, turn rate and
    /// heading.
    scatter: [Vec<(f64, f64)>; 3],
}

fn drawn(run: &Run, tr: &dyn TrackRows) -> Drawn {
    let mut traj = Decimator::new(run.t.len());
    let mut err = Decimator::new(run.t.len());
    let mut scatter = [0, 1, 2].map(|_| Decimator::new(run.steps()));
    for row in against_truth(tr, run) {
        traj.push((row.measured[0], row.measured[1]));
        if let Some(e) = row.position_error {
            err.push((row.t, e));
        }
        if let Some(r) = row.turn_rate {
            scatter[0].push((r.speed, r.residual));
            scatter[1].push((r.turn_rate, r.residual));
            scatter[2].push((r.heading, r.residual));
        }
    }
    Drawn {
        traj: traj.finish(),
        pos_err: err.finish(),
        scatter: scatter.map(Decimator::finish),
    }
}

/// A run's trajectory chart: `series` on equal axes.
pub(crate) fn trajectory_chart(run: &Run, series: &[Series]) -> Result<String, String> {
    let title = format!("{}: trajectory", run.name);
    chart(&title, "x (m)", "y (m)", series, false, true, &[])
}

/// A position-error-over-time chart titled `title`, `marks` shaded.
pub(crate) fn error_chart(
    title: &str,
    series: &[Series],
    marks: &[(f64, f64)],
) -> Result<String, String> {
    chart(title, "t (s)", "error (m)", series, false, false, marks)
}

pub(crate) fn gt_xy(run: &Run) -> Vec<(f64, f64)> {
    run.gt
        .as_ref()
        .map(|g| series_of(g.len(), g.iter().map(|p| (p[0], p[1]))))
        .unwrap_or_default()
}

pub(crate) fn write(dir: &Path, html: &str) -> Result<(), String> {
    kinegen_model::files::write_atomic(&dir.join("index.html"), html).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A million-point series is drawn from at most ~4000 points, and a single
    /// spike in it survives.
    #[test]
    fn decimation_bounds_the_points_and_keeps_the_extremes() {
        let mut pts: Vec<(f64, f64)> = (0..1_000_000)
            .map(|k| (k as f64, (k as f64 * 1e-3).sin()))
            .collect();
        pts[654_321].1 = 50.0;
        pts[123_456].1 = -7.0;
        let d = decimated(&pts);
        assert!(d.len() <= 4 * BUCKETS + 1, "{} points", d.len());
        assert!(d.contains(&pts[654_321]) && d.contains(&pts[123_456]));
        assert_eq!(d.first(), pts.first());
        assert_eq!(d.last(), pts.last());
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0), "order kept");
        let short = vec![(0.0, 1.0), (1.0, 2.0)];
        assert_eq!(decimated(&short), short);
    }

    /// A series without points (the ground truth of a log that has none)
    /// gets no legend entry, and a chart none of whose series has points
    /// says so instead of drawing empty axes under a legend.
    #[test]
    fn series_without_data_are_left_out_and_said() {
        let track = vec![(0.0, 0.0), (1.0, 0.5), (2.0, 0.7)];
        let svg = chart(
            "trajectory",
            "x",
            "y",
            &[("measured", BLACK, vec![]), ("model", RED, track)],
            false,
            true,
            &[],
        )
        .unwrap();
        assert!(svg.contains("model") && !svg.contains("measured"));
        assert!(!svg.contains("nothing to draw"));
        let empty = chart(
            "position error",
            "t",
            "e",
            &[("model", RED, vec![])],
            false,
            false,
            &[],
        )
        .unwrap();
        assert!(empty.contains("nothing to draw") && !empty.contains("model"));
    }
}
