//! `--report DIR`: one self-contained HTML page (inline SVG figures drawn with
//! plotters, no external files or scripts).
use kinegen_analysis::diagnosis::clock::ClockVerdict;
use kinegen_analysis::logs::log::wrap;
use kinegen_analysis::model_on_log::innovations::Innovation;
use kinegen_analysis::model_on_log::metrics::regime;
use kinegen_analysis::model_on_log::model::Runner;
use kinegen_analysis::model_on_log::run::Run;
use kinegen_analysis::model_on_log::track_rows::{Heading, Recipe, TrackRows};
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
    let gt = run.gt.as_ref();
    for (k, row) in tr.rows(run).enumerate() {
        let m = row.measured;
        traj.push((m[0], m[1]));
        let Some(g) = gt else { continue };
        err.push((
            run.t[k] - run.t[0],
            ((g[k][0] - m[0]).powi(2) + (g[k][1] - m[1]).powi(2)).sqrt(),
        ));
        if let Some(tw) = row.twist {
            let res = tw[2] - wrap(g[k + 1][2] - g[k][2]) / run.dt[k];
            let v = (tw[0].powi(2) + tw[1].powi(2)).sqrt();
            scatter[0].push((v, res));
            scatter[1].push((tw[2], res));
            scatter[2].push((wrap(g[k][2]), res));
        }
    }
    Drawn {
        traj: traj.finish(),
        pos_err: err.finish(),
        scatter: scatter.map(Decimator::finish),
    }
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

fn worst_marks(
    segments: &[kinegen_analysis::model_on_log::metrics::Segment],
    run: &str,
) -> Vec<(f64, f64)> {
    segments
        .iter()
        .filter(|s| s.run == run)
        .map(|s| (s.t_start, s.t_end))
        .collect()
}

/// The compare report's table of where the error grows, by regime.
fn regime_table(regimes: &[kinegen_analysis::model_on_log::metrics::RegimeShare]) -> String {
    let mut t = String::from("<h2>Where the error grows</h2><table><tr><th>regime</th><th>time (s)</th><th>distance (m)</th><th>position error share</th><th>heading error share</th></tr>");
    for g in regimes {
        t += &format!(
            "<tr><td>{}</td><td>{:.1}</td><td>{:.2}</td><td>{:.1}%</td><td>{:.1}%</td></tr>",
            esc(&g.regime),
            g.time_s,
            g.distance_m,
            100.0 * g.position_share,
            100.0 * g.heading_share
        );
    }
    t + "</table>"
}

/// The landmark range and bearing innovations of each run that has sightings.
fn innovation_charts(runs: &[Run], innov: &[Vec<Innovation>]) -> Result<Vec<String>, String> {
    let mut figs = Vec::new();
    for (run, inn) in runs.iter().zip(innov).filter(|(_, i)| !i.is_empty()) {
        let t0 = run.t[0];
        let range: Vec<(f64, f64)> = inn.iter().map(|i| (i.t - t0, i.range_m)).collect();
        let bearing: Vec<(f64, f64)> = inn.iter().map(|i| (i.t - t0, i.bearing_rad)).collect();
        figs.push(chart(
            &format!("{}: landmark range innovation", run.name),
            "t (s)",
            "measured - predicted (m)",
            &[("range", RGBColor(0, 90, 200), range)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            &format!("{}: landmark bearing innovation", run.name),
            "t (s)",
            "measured - predicted (rad)",
            &[("bearing", RGBColor(200, 120, 0), bearing)],
            true,
            false,
            &[],
        )?);
    }
    Ok(figs)
}

/// The compare page, from the comparison itself; `doc` is its JSON, shown
/// on the page as it is.
pub fn compare_report(
    dir: &Path,
    r: &Runner,
    cmp: &kinegen_analysis::model_on_log::comparison::Comparison<'_>,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let runs = &cmp.runs;
    let mut figs = innovation_charts(runs, &cmp.innovations)?;
    for ((run, tr), g) in runs.iter().zip(&cmp.tracks).zip(&cmp.gyro_tracks) {
        let d = drawn(run, tr);
        let mut series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("model (nominal)", RED, d.traj),
        ];
        if let Some(g) = g {
            series.push(("gyrodometry", RGBColor(0, 90, 200), traj(run, g)));
        }
        figs.push(chart(
            &format!("{}: trajectory", run.name),
            "x (m)",
            "y (m)",
            &series,
            false,
            true,
            &[],
        )?);
        figs.push(chart(
            &format!("{}: position error, worst 1 s segments shaded", run.name),
            "t (s)",
            "error (m)",
            &[("model (nominal)", RED, d.pos_err)],
            false,
            false,
            &worst_marks(&cmp.segments, &run.name),
        )?);
        let [a, b, c] = d.scatter;
        figs.push(chart(
            "turn-rate residual vs speed",
            "speed (m/s)",
            "model - measured yaw rate (rad/s)",
            &[("residual", BLUE, a)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            "turn-rate residual vs turn rate",
            "yaw rate (rad/s)",
            "residual (rad/s)",
            &[("residual", BLUE, b)],
            true,
            false,
            &[],
        )?);
        figs.push(chart(
            "turn-rate residual vs heading",
            "heading (rad)",
            "residual (rad/s)",
            &[("residual", BLUE, c)],
            true,
            false,
            &[],
        )?);
    }
    let t = regime_table(&cmp.regimes);
    let e = &cmp.errors;
    let intro = format!(
        "<p>Model <b>{}</b> with nominal parameters against {} run(s): position RMSE <b>{:.4} m</b>, heading RMSE {:.4} rad, final error {:.4} m.</p>",
        esc(&r.ir.name),
        runs.len(),
        e.rmse,
        e.heading_rmse_rad,
        e.final_position_error_m
    );
    write(
        dir,
        &page(
            &format!("kinegen compare: {}", r.ir.name),
            answer,
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}

/// The calibrated parameters: nominal, estimate and standard deviation.
pub fn param_table(r: &Runner, fit: &kinegen_analysis::estimation::fit::FitResult) -> String {
    let mut t = String::from("<h2>Parameters</h2><table><tr><th>parameter</th><th>nominal</th><th>estimate</th><th>std</th></tr>");
    for (k, &i) in fit.free.iter().enumerate() {
        t += &format!(
            "<tr><td>{}</td><td>{:.6}</td><td>{:.6}</td><td>{}</td></tr>",
            esc(&r.names[i]),
            r.p[i],
            fit.p[i],
            crate::output::fmt_std(fit.std.get(k).copied())
        );
    }
    t += "</table>";
    t
}

/// The fit page, from the calibration itself; `doc` is its JSON, shown on
/// the page as it is.
pub fn fit_report(
    dir: &Path,
    r: &Runner,
    runs: &[Run],
    cal: &kinegen_analysis::estimation::fit_job::Calibrated<'_>,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let mut figs = Vec::new();
    for ((run, b), a) in runs.iter().zip(&cal.before.tracks).zip(&cal.after.tracks) {
        let (b, a) = (drawn(run, b), drawn(run, a));
        figs.push(chart(
            &format!("{}: trajectory", run.name),
            "x (m)",
            "y (m)",
            &[
                ("measured", BLACK, gt_xy(run)),
                ("before calibration", RED, b.traj),
                ("after calibration", GREEN, a.traj),
            ],
            false,
            true,
            &[],
        )?);
        figs.push(chart(
            &format!("{}: position error", run.name),
            "t (s)",
            "error (m)",
            &[("before", RED, b.pos_err), ("after", GREEN, a.pos_err)],
            false,
            false,
            &[],
        )?);
        let [sb, _, _] = b.scatter;
        let [sa, _, _] = a.scatter;
        figs.push(chart(
            "turn-rate residual vs speed",
            "speed (m/s)",
            "residual (rad/s)",
            &[("before", RED, sb), ("after", GREEN, sa)],
            true,
            false,
            &[],
        )?);
        let _ = regime;
    }
    let intro = format!(
        "<p>Model <b>{}</b> calibrated on {} run(s): position RMSE <b>{:.4} m</b> before, <b>{:.4} m</b> after.</p>",
        esc(&r.ir.name),
        runs.len(),
        cal.before.errors.rmse,
        cal.after.errors.rmse
    );
    write(
        dir,
        &page(
            &format!("kinegen fit: {}", r.ir.name),
            answer,
            &intro,
            &figs,
            &param_table(r, &cal.fit),
            warnings,
            doc,
        ),
    )
}

/// Diagnosis page: before/after trajectories of the calibrated base model and of
/// the winning effect, the residual signature, and the candidate table.
pub fn diagnose_report(
    dir: &Path,
    base: &Runner,
    runs: &[Run],
    outcome: &kinegen_analysis::diagnosis::diagnose_job::Outcome,
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let d = &outcome.diagnosis;
    let dr = |r, p: &[f64]| Recipe {
        r,
        p: p.to_vec(),
        offset: [0.0; 3],
        heading: Heading::Model,
    };
    let mut figs = Vec::new();
    let chain_label = format!(
        "with {}",
        d.chain
            .iter()
            .map(|c| c.effect.as_str())
            .collect::<Vec<_>>()
            .join(" + ")
    );
    for (k, run) in runs.iter().enumerate() {
        let b = drawn(run, &dr(base, &d.base_fit.p));
        let mut series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("calibrated spec", RED, b.traj),
        ];
        let mut errs: Vec<Series> = vec![("calibrated spec", RED, b.pos_err)];
        if !d.chain.is_empty() {
            let a = drawn(run, &dr(&d.final_runner, &d.final_p));
            series.push((chain_label.as_str(), GREEN, a.traj));
            errs.push((chain_label.as_str(), GREEN, a.pos_err));
        }
        let signature = outcome
            .signature
            .as_ref()
            .and_then(|sig| Some((sig, sig.per_run.get(k)?.as_ref()?)));
        if let Some((sig, (chan, pts))) = signature {
            let (name, param, est, pts) = (&sig.effect, &sig.parameter, sig.estimate, pts.clone());
            let (lo, hi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |m, p| {
                (m.0.min(p.0), m.1.max(p.0))
            });
            let line = vec![(lo, lo), (hi, hi)];
            figs.push(chart(
                &format!("signature of {name}: {chan} one-step residual of the calibrated spec"),
                &format!("change of the prediction by {param} = {est:.4}"),
                "residual",
                &[
                    ("calibrated spec, per step", RED, pts),
                    ("residual = change (the effect explains it)", GREEN, line),
                ],
                true,
                false,
                &[],
            )?);
        }
        figs.insert(
            0,
            chart(
                &format!("{}: trajectory", run.name),
                "x (m)",
                "y (m)",
                &series,
                false,
                true,
                &[],
            )?,
        );
        figs.insert(
            1,
            chart(
                &format!("{}: position error", run.name),
                "t (s)",
                "error (m)",
                &errs,
                false,
                false,
                &[],
            )?,
        );
    }
    let t = candidates_html(d, base);
    let intro = format!(
        "<p>Model <b>{}</b>: error {:.4} with nominal parameters, {:.4} after calibrating the spec as it is (error: RMS of the residuals in units of their sigma). Verdict: <b>{}</b>.</p>",
        esc(&base.ir.name),
        d.baseline_rmse,
        d.calibrated_rmse,
        esc(&if d.chain.is_empty() { "no catalogue effect is significant".to_string() } else { d.chain.iter().map(step_said).collect::<Vec<_>>().join(", then ") })
    );
    if let Some(fig) = sensor_chart(d, base, runs)? {
        figs.push(fig);
    }
    // each effect's change to the spec, as add-effect writes it (the
    // commands that apply them are in the answer box)
    let mut t = t;
    for (step, change) in d.chain.iter().zip(&outcome.spec_changes) {
        if let Some(c) = change {
            t += &format!(
                "<h2>Spec change: <code>{}</code></h2><pre>{}</pre>",
                esc(&step.effect),
                esc(c)
            );
        }
    }
    if let Some(p) = &d.proposed {
        t += &proposal_html(p);
    }
    write(
        dir,
        &page(
            &format!("kinegen diagnose: {}", base.ir.name),
            answer,
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}

/// A correction beyond the catalogue: its terms, its held-out fall, what it
/// may be, and its effect file (written beside the page, `proposed/`).
fn proposal_html(p: &kinegen_analysis::diagnosis::propose::Proposal) -> String {
    let terms: Vec<String> = p
        .terms
        .iter()
        .zip(&p.corrects)
        .zip(&p.gains)
        .map(|((t, c), g)| {
            let v = p.parameters.get(g).map_or(String::new(), |e| {
                format!(" = {}", crate::output::with_std(e.estimate, e.std))
            });
            format!(
                "<li><code>{} += {g} &times; {}</code>{v}</li>",
                esc(c),
                esc(t)
            )
        })
        .collect();
    format!(
        "<h2>Proposed beyond the catalogue: <code>{}</code></h2><p>Not a known physical effect: a correction these logs support. Held-out error {:.3} &rarr; {:.3}. It may be: {}.</p><ul>{}</ul><p>Its effect file, <code>proposed/{}.toml</code> beside this page (<code>kinegen add-effect --effects DIR/proposed --effect {}</code> adds it to the spec):</p><pre>{}</pre>",
        esc(&p.name),
        p.held_out_before,
        p.held_out_after,
        esc(&p.reading),
        terms.join(""),
        esc(&p.name),
        esc(&p.name),
        esc(&p.toml)
    )
}

/// One effect of the verdict's chain, with what proved it.
fn step_said(c: &kinegen_analysis::diagnosis::diagnose::ChainStep) -> String {
    match &c.sightings {
        Some(f) => format!(
            "{} (the sightings' median range error {:.3} -> {:.3} m, bearing {:.4} -> {:.4} rad; proved stretch by stretch)",
            c.effect, f.range_before, f.range_after, f.bearing_before, f.bearing_after
        ),
        None => format!(
            "{} (error after: {:.4}{})",
            c.effect,
            c.rmse_after,
            if c.folds.is_some() { "; proved fold by fold" } else { "" }
        ),
    }
}

/// The range error of every sighting against its bearing, seen from the
/// ground truth, for the calibrated spec and for the model with the
/// sensor's effects found: what a camera reading depth looks like (short
/// at the edges of its view). None when the diagnosis found none.
fn sensor_chart(
    d: &kinegen_analysis::diagnosis::diagnose::Diagnosis,
    base: &Runner,
    runs: &[Run],
) -> Result<Option<String>, String> {
    if !d.chain.iter().any(|c| c.sightings.is_some()) {
        return Ok(None);
    }
    let errors = |r: &Runner, p: &[f64]| -> Vec<(f64, f64)> {
        let sig = kinegen_analysis::model_on_log::landmarks::sigma(r);
        runs.iter()
            .flat_map(|run| {
                let (res, _) =
                    kinegen_analysis::estimation::fit::sightings_from_truth(r, p, &[], run, false);
                // measured minus predicted, m
                let range = res.into_iter().step_by(2).map(move |e| -e * sig[0]);
                run.landmarks
                    .iter()
                    .map(|o| o.bearing)
                    .zip(range)
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let series: Vec<Series> = vec![
        ("calibrated spec", RED, errors(base, &d.base_fit.p)),
        (
            "with the sensor's effects",
            GREEN,
            errors(&d.final_runner, &d.final_p),
        ),
    ];
    chart(
        "landmark sightings seen from the ground truth: range error against bearing",
        "bearing (rad)",
        "range measured - predicted (m)",
        &series,
        true,
        false,
        &[],
    )
    .map(Some)
}

/// The range-bearing sensor's candidates, tested on the sightings seen from
/// the ground truth, as an HTML table (empty when none were tested).
fn sensor_html(d: &kinegen_analysis::diagnosis::diagnose::Diagnosis) -> String {
    let mut t = String::new();
    if let Some(why) = &d.sensor_unmeasured {
        t += &format!(
            "<p>The range-bearing sensor's effects were not tested: {}.</p>",
            esc(&why.to_string())
        );
    }
    if d.sensor_candidates.is_empty() {
        return t;
    }
    t += "<h2>The range-bearing sensor</h2><p>Its effects, calibrated on the landmark sightings seen from the ground truth (Huber's loss) and held out stretch by stretch of the sightings.</p>";
    t += "<table><tr><th>effect</th><th>estimates (± jackknife sd)</th><th>median range error (m)</th><th>median bearing error (rad)</th><th>held out stretch by stretch</th><th>significant</th></tr>";
    for c in &d.sensor_candidates {
        let est: Vec<String> = c
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} = {:.4} ± {:.1e}", v.estimate, v.std))
            .collect();
        let (f, folds) = (&c.fit, &c.fit.folds);
        t += &format!(
            "<tr><td>{}</td><td>{}</td><td>{:.4} -> {:.4}</td><td>{:.4} -> {:.4}</td><td>{:+.0}% in {} stretches (t {:.1}, needs {:.1})</td><td>{}</td></tr>",
            esc(&c.effect),
            esc(&est.join(", ")),
            f.range_before,
            f.range_after,
            f.bearing_before,
            f.bearing_after,
            -100.0 * folds.gain,
            folds.folds,
            folds.t,
            folds.critical,
            match (&c.unphysical, c.significant) {
                (Some(why), _) => format!("no: {}", esc(why)),
                (None, true) => "yes".to_string(),
                (None, false) => "no".to_string(),
            }
        );
    }
    t + "</table>"
}

/// The diagnose report's candidates (table and evidence), the structure the
/// residuals keep, and the effects not tested, as HTML.
fn candidates_html(d: &kinegen_analysis::diagnosis::diagnose::Diagnosis, base: &Runner) -> String {
    let mut t = format!(
        "<h2>Candidates</h2><table><tr><th>effect</th><th>error</th><th>improvement</th><th>BIC gain</th><th>held-out error</th><th>held out fold by fold ({} s motion)</th><th>significant</th></tr>",
        kinegen_analysis::diagnosis::folds::WINDOW_S
    );
    for c in &d.candidates {
        let folds = c.folds.map_or("not run".to_string(), |f| {
            format!(
                "{:+.0}% (t {:.1}, needs {:.1}{})",
                -100.0 * f.gain,
                f.t,
                f.critical,
                f.too_small()
            )
        });
        t += &format!(
            "<tr><td>{}</td><td>{:.4}</td><td>{:.0}%</td><td>{:.0}</td><td>{:.4}</td><td>{}</td><td>{}</td></tr>",
            esc(&c.effect),
            c.rmse,
            100.0 * c.improvement,
            c.bic_gain,
            c.holdout_rmse,
            folds,
            match (c.significant, c.by_folds(), c.clock) {
                (true, true, _) => "yes (fold by fold)",
                (true, false, _) => "yes",
                (false, _, Some(ClockVerdict::Contradicted { .. })) => {
                    "no (the sightings contradict its delay)"
                }
                _ => "no",
            }
        );
    }
    t += "</table>";
    if let Some(clock) = &d.clock {
        t += &format!("<p>Timing: {}.</p>", esc(&clock.to_string()));
    }
    if let Some(why) = &d.clock_unmeasured {
        t += &format!("<p>Timing: {}.</p>", esc(&why.to_string()));
    }
    if let Some(said) = d.spec_clock_said(base) {
        t += &format!("<p>Timing: {}.</p>", esc(&said));
    }
    t += "<ul>";
    for c in &d.candidates {
        t += &format!("<li><b>{}</b>: {}</li>", esc(&c.effect), esc(&c.evidence));
    }
    t += "</ul>";
    t += &sensor_html(d);
    // findings of a structure test that did not run (no ground truth) say
    // why, not what is left
    let said = if d.structure.structured {
        "structure left"
    } else {
        "structure not tested"
    };
    for f in &d.structure.findings {
        t += &format!("<p class=\"warn\">{said}: {}</p>", esc(f));
    }
    if !d.skipped.is_empty() {
        t += "<h2>Not tested</h2><ul>";
        for (n, why) in &d.skipped {
            t += &format!("<li><b>{}</b>: {}</li>", esc(n), esc(why));
        }
        t += "</ul>";
    }
    t
}

/// Colours for the calibration methods, in the order they are listed.
const METHOD_COLORS: [RGBColor; 4] = [
    RGBColor(0, 150, 0),
    RGBColor(0, 90, 200),
    RGBColor(200, 120, 0),
    RGBColor(150, 0, 150),
];

/// `fit --method all` (or one seed method): every method's trajectory and error
/// against the nominal model, and a table comparing their errors, their distance
/// to known true values and their estimates side by side.
pub fn methods_report(
    dir: &Path,
    r: &Runner,
    runs: &[Run],
    compared: &kinegen_analysis::estimation::fit_job::MethodsOutcome<'_>,
    truth: &[(String, f64)],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let mut figs = Vec::new();
    for (k, run) in runs.iter().enumerate() {
        let nominal_drawn = drawn(run, &compared.before.tracks[k]);
        let mut traj_series: Vec<Series> = vec![
            ("measured", BLACK, gt_xy(run)),
            ("nominal", RED, nominal_drawn.traj),
        ];
        let mut err_series: Vec<Series> = vec![("nominal", RED, nominal_drawn.pos_err)];
        for (m, row) in compared.rows.iter().enumerate() {
            let color = METHOD_COLORS[m % METHOD_COLORS.len()];
            let d = drawn(run, &row.after.tracks[k]);
            traj_series.push((row.name.as_str(), color, d.traj));
            err_series.push((row.name.as_str(), color, d.pos_err));
        }
        figs.push(chart(
            &format!("{}: trajectory", run.name),
            "x (m)",
            "y (m)",
            &traj_series,
            false,
            true,
            &[],
        )?);
        figs.push(chart(
            &format!("{}: position error", run.name),
            "t (s)",
            "error (m)",
            &err_series,
            false,
            false,
            &[],
        )?);
    }
    let t = methods_table(r, compared, truth);
    let intro = format!(
        "<p>Model <b>{}</b>, {} run(s): {} calibration method(s) from the same nominal parameters (position RMSE {:.4} m).</p>",
        esc(&r.ir.name),
        runs.len(),
        compared.rows.len(),
        compared.before.errors.rmse
    );
    write(
        dir,
        &page(
            &format!("kinegen fit: methods compared on {}", r.ir.name),
            &[],
            &intro,
            &figs,
            &t,
            warnings,
            doc,
        ),
    )
}

/// The methods' errors, distances to the truth and notes, then their
/// estimates side by side (with the truth where it is known).
fn methods_table(
    r: &Runner,
    compared: &kinegen_analysis::estimation::fit_job::MethodsOutcome<'_>,
    truth: &[(String, f64)],
) -> String {
    let num = |v: Option<f64>, digits: usize| {
        v.filter(|x| x.is_finite())
            .map(|x| format!("{x:.digits$}"))
            .unwrap_or_else(|| "-".into())
    };
    let mut t = String::from("<h2>Methods</h2><table><tr><th>method</th><th>position RMSE (m)</th><th>held-out RMSE (m)</th><th>distance to truth left</th><th>notes</th></tr>");
    for m in &compared.rows {
        t += &format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td style=\"text-align:left;white-space:pre-wrap\">{}</td></tr>",
            esc(&m.name),
            num(Some(m.after.errors.rmse), 4),
            num(m.holdout.as_ref().map(|h| h.rmse), 4),
            m.distance_to_truth.map(|d| format!("{:.1}%", 100.0 * d)).unwrap_or_else(|| "-".into()),
            esc(&m.note)
        );
    }
    t += "</table>";
    if let Some((_, best)) = &compared.closest {
        t += &format!(
            "<p>Closest to the true parameters: <b>{}</b>.</p>",
            esc(best)
        );
    }
    t += "<h2>Estimates</h2><table><tr><th>parameter</th><th>nominal</th>";
    if !truth.is_empty() {
        t += "<th>truth</th>";
    }
    for m in &compared.rows {
        t += &format!("<th>{}</th>", esc(&m.name));
    }
    t += "</tr>";
    for (k, &i) in r.free.iter().enumerate() {
        let pname = &r.names[i];
        t += &format!("<tr><td>{}</td><td>{:.6}</td>", esc(pname), r.p[i]);
        if !truth.is_empty() {
            let v = truth.iter().find(|(n, _)| n == pname).map(|(_, v)| *v);
            t += &format!("<td>{}</td>", num(v, 6));
        }
        for m in &compared.rows {
            let c = &m.calibration;
            t += &format!(
                "<td>{} &plusmn; {}</td>",
                num(c.p.get(i).copied(), 6),
                crate::output::fmt_std(c.std.get(k).copied())
            );
        }
        t += "</tr>";
    }
    t + "</table>"
}

/// `kinegen inverse --report`: the planned path, then per spec each input's
/// profile along it (seed 001 Figs 8-10), with the actuator limits as lines and
/// the stretches the robot cannot drive shaded.
pub fn inverse_report(
    dir: &Path,
    path: &kinegen_analysis::applications::inverse::PlannedPath,
    profiles: &[(String, kinegen_analysis::applications::inverse::Profile)],
    doc: &Value,
) -> Result<(), String> {
    const COLORS: [RGBColor; 6] = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    let mut figs = vec![chart(
        "planned path",
        "x (m)",
        "y (m)",
        &[(
            "path",
            BLACK,
            path.pose.iter().map(|p| (p[0], p[1])).collect(),
        )],
        false,
        true,
        &[],
    )?];
    for (model, prof) in profiles {
        // one figure per unit, so counts/s and rad do not share an axis
        let mut units: Vec<&str> = prof.inputs.iter().map(|i| i.unit.as_str()).collect();
        units.dedup();
        for unit in units {
            let mut series: Vec<Series> = Vec::new();
            let mut limits: Vec<f64> = Vec::new();
            for (k, inp) in prof.inputs.iter().filter(|i| i.unit == unit).enumerate() {
                let c = COLORS[k % COLORS.len()];
                series.push((
                    inp.name.as_str(),
                    c,
                    prof.t
                        .iter()
                        .copied()
                        .zip(inp.value.iter().copied())
                        .collect(),
                ));
                if let (Some(m), kinegen_model::decl::InputKind::Cumulative) =
                    (inp.max_rate, inp.kind)
                {
                    limits.push(m);
                }
            }
            // each distinct rate limit once, as +-max_rate (one legend entry),
            // in grey: no input's colour
            limits.sort_by(f64::total_cmp);
            limits.dedup();
            let grey = RGBColor(128, 128, 128);
            for m in limits {
                let (a, b) = (prof.t[0], *prof.t.last().unwrap());
                series.push(("±max_rate", grey, vec![(a, m), (b, m)]));
                series.push(("", grey, vec![(a, -m), (b, -m)]));
            }
            let names: Vec<&str> = prof
                .inputs
                .iter()
                .filter(|i| i.unit == unit)
                .map(|i| i.name.as_str())
                .collect();
            let marks: Vec<(f64, f64)> = prof
                .infeasible
                .iter()
                .filter(|s| s.input == "path" || names.contains(&s.input.as_str()))
                .map(|s| (s.t_start, s.t_end))
                .collect();
            figs.push(chart(
                &format!("{model}: inputs in {unit}"),
                "t (s)",
                unit,
                &series,
                false,
                false,
                &marks,
            )?);
        }
    }
    let table = inverse_table(profiles);
    let html = page(
        "Inverse kinematics along a planned path",
        &[],
        &format!(
            "<p>{} (the integrated inverse kinematics). Shaded: stretches the robot cannot drive as planned.</p>",
            esc(&path.file.display().to_string())
        ),
        &figs,
        &table,
        &[],
        doc,
    );
    write(dir, &html)
}

/// The inverse report's table: each robot's inputs (peak rate, limit, the
/// stretches beyond it), and the motion it cannot make at all.
fn inverse_table(
    profiles: &[(String, kinegen_analysis::applications::inverse::Profile)],
) -> String {
    let mut table = String::from("<table><tr><th>model</th><th>input</th><th>peak rate</th><th>max_rate</th><th>infeasible stretches</th></tr>");
    for (model, prof) in profiles {
        for inp in &prof.inputs {
            let where_: Vec<String> = prof
                .infeasible
                .iter()
                .filter(|s| s.input == inp.name)
                .map(|s| format!("{:.2}-{:.2} s", s.t_start, s.t_end))
                .collect();
            // an absolute input's rate is its unit per second (a steering
            // angle in rad changes in rad/s); a cumulative input's unit is
            // already a rate
            let rate_unit = match inp.kind {
                kinegen_model::decl::InputKind::Absolute => format!("{}/s", inp.unit),
                _ => inp.unit.clone(),
            };
            table += &format!(
                "<tr><td>{}</td><td>{}</td><td>{:.4} {}</td><td>{}</td><td>{}</td></tr>",
                esc(model),
                esc(&inp.name),
                inp.peak_rate,
                esc(&rate_unit),
                inp.max_rate
                    .map_or("-".into(), |m| format!("{m} {}", esc(&rate_unit))),
                if where_.is_empty() {
                    "none".into()
                } else {
                    where_.join(", ")
                }
            );
        }
        // motion the robot cannot make at all (sideways), shaded on every chart
        let path_stretches: Vec<String> = prof
            .infeasible
            .iter()
            .filter(|s| s.input == "path")
            .map(|s| format!("{:.2}-{:.2} s", s.t_start, s.t_end))
            .collect();
        if !path_stretches.is_empty() {
            table += &format!(
                "<tr><td>{}</td><td>path</td><td>-</td><td>-</td><td>motion it cannot make (sideways): {}</td></tr>",
                esc(model),
                path_stretches.join(", ")
            );
        }
    }
    table += "</table>";
    table
}

/// `kinegen navigate --report`: the grid (obstacles dark, safety zone light),
/// the planned cells, and for each drive the true path (where the robot went)
/// and the odometry (where it believed it was), collisions marked.
pub fn navigate_report(
    dir: &Path,
    grid: &kinegen_analysis::applications::grid::Grid,
    drives: &[(&str, &kinegen_analysis::applications::navigate::Drive)],
    doc: &Value,
) -> Result<(), String> {
    let figs = drives
        .iter()
        .map(|(name, d)| navigation_map(grid, name, d))
        .collect::<Result<Vec<_>, _>>()?;
    let html = page(
        "Cellular-automaton navigation on odometry",
        &[],
        "<p>Dark: obstacles; light: safety zone (obstacles enlarged by one cell); crosses: the robot touching an obstacle; magenta: the goal.</p>",
        &figs,
        "",
        &[],
        doc,
    );
    write(dir, &html)
}

/// One drive on the arena: the planned cells, the odometry, the true path,
/// where it touched an obstacle, and the goal (an SVG).
fn navigation_map(
    grid: &kinegen_analysis::applications::grid::Grid,
    name: &str,
    d: &kinegen_analysis::applications::navigate::Drive,
) -> Result<String, String> {
    let (rows, cols) = grid.size();
    let (w, h) = (cols as f64 * grid.cell, rows as f64 * grid.cell);
    let mut svg = String::new();
    {
        let px = (W as f64 * 1.4) as u32;
        let root =
            SVGBackend::with_string(&mut svg, (px + LEGEND_W, (px as f64 * h / w) as u32 + 60))
                .into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        // the arena fills the plot: the legend stands beside it
        let (area, strip) = root.split_horizontally(px);
        let mut c = ChartBuilder::on(&area)
            .caption(
                format!(
                    "{name}: {} collision(s), {:.1} cm from the goal",
                    d.collisions,
                    100.0 * d.final_error_m
                ),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..w, 0.0..h)
            .map_err(|e| e.to_string())?;
        c.configure_mesh()
            .disable_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .draw()
            .map_err(|e| e.to_string())?;
        draw_arena(&mut c, grid)?;
        // named in the legend strip, in this order
        let line = |pts: Vec<(f64, f64)>,
                    color: RGBColor,
                    c: &mut ChartContext<_, _>|
         -> Result<(), String> {
            c.draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(|e| e.to_string())?;
            Ok(())
        };
        line(
            d.planned.iter().map(|p| (p[0], p[1])).collect(),
            GREEN,
            &mut c,
        )?;
        line(
            series_of(d.odometry.len(), d.odometry.iter().map(|p| (p[0], p[1]))),
            BLUE,
            &mut c,
        )?;
        line(
            series_of(d.truth.len(), d.truth.iter().map(|p| (p[0], p[1]))),
            RED,
            &mut c,
        )?;
        let touching: Vec<(f64, f64)> = d
            .truth
            .iter()
            .filter(|p| grid.collides(p[0], p[1], 0.035))
            .map(|p| (p[0], p[1]))
            .collect();
        c.draw_series(
            touching
                .iter()
                .step_by(5)
                .map(|p| Cross::new(*p, 4, BLACK.stroke_width(2))),
        )
        .map_err(|e| e.to_string())?;
        let g = grid.centre(grid.goal);
        c.draw_series(std::iter::once(Circle::new(
            (g[0], g[1]),
            6,
            MAGENTA.filled(),
        )))
        .map_err(|e| e.to_string())?;
        legend_strip(
            &strip,
            [
                ("planned cells", GREEN, false),
                ("odometry (believed)", BLUE, false),
                ("true path", RED, false),
                ("goal", MAGENTA, true),
            ]
            .into_iter(),
        )?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// A chart over real numbers on both axes.
pub(crate) type RealChart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The arena's obstacles and safety zone, cell by cell.
fn draw_arena(
    c: &mut RealChart<'_, '_>,
    grid: &kinegen_analysis::applications::grid::Grid,
) -> Result<(), String> {
    use kinegen_analysis::applications::grid::Cell;
    let (rows, cols) = grid.size();
    for r in 0..rows {
        for col in 0..cols {
            let color = match grid.cell(r, col) {
                Cell::Obstacle => RGBColor(60, 60, 60),
                Cell::Safety => RGBColor(255, 220, 160),
                Cell::Free => continue,
            };
            let [cx, cy] = grid.centre((r, col));
            let half = grid.cell / 2.0;
            c.draw_series(std::iter::once(Rectangle::new(
                [(cx - half, cy - half), (cx + half, cy + half)],
                color.filled(),
            )))
            .map_err(|e| e.to_string())?;
        }
    }
    Ok(())
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
