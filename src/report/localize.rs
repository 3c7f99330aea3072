//! `kinegen localize --report`: for each run, a map (estimate, smoothed
//! estimate, ground truth, dead reckoning, landmarks; legend beside the map,
//! never over it), the position error over time with its 3-sigma bound, the
//! NIS over time with its chi-square band, and a table of the figures and
//! the noise; the noise sweep (seed 001 Figs 6-7) when it was run.
use super::{
    axes, decimated, esc, legend_strip, page, series_of, squared, write, Series, H, LEGEND_W, W,
};
use kinegen_analysis::applications::localize::figures::{ErrorFigures, RunFigures};
use kinegen_analysis::applications::localize::{
    Bounds, Consistency, GateTail, Localization, Overconfident, Spread, Summary,
};
use kinegen_analysis::model_on_log::run::Run;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// One run's inputs to the page.
pub struct RunPage<'a> {
    pub run: &'a Run,
    pub loc: &'a Localization,
    pub summary: &'a Summary,
    pub figures: &'a RunFigures,
}

// the page's parts, each its own argument as the other reports take them
#[allow(clippy::too_many_arguments)]
pub fn localize_report(
    dir: &Path,
    runs: &[RunPage],
    noise: &[String],
    sweep: &[kinegen_analysis::applications::sweep::SweepPoint],
    answer: &[String],
    warnings: &[String],
    doc: &Value,
) -> Result<(), String> {
    let mut figs = Vec::new();
    for p in runs {
        figs.push(map(p)?);
        if let Some(errors) = &p.figures.errors {
            figs.push(error_over_time(p, errors)?);
        }
        if !p.loc.nis.is_empty() {
            figs.push(nis_over_time(p)?);
        }
    }
    if !sweep.is_empty() {
        figs.push(sweep_chart(sweep)?);
    }
    let html = page(
        "EKF localisation",
        answer,
        "<p>Extended Kalman filter on the model's own kernels, predicting to each sighting's own time; \
         the smoother (with --smooth) also uses the sightings after each moment.</p>",
        &figs,
        &tables(runs, noise),
        warnings,
        doc,
    );
    write(dir, &html)
}

/// A chart whose legend stands in a strip to its right.
fn chart_beside(
    title: &str,
    xl: &str,
    yl: &str,
    series: &[Series],
    points: &[Series],
    equal: bool,
) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W + LEGEND_W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (area, legend) = root.split_horizontally(W);
        let all: Vec<(f64, f64)> = series
            .iter()
            .chain(points)
            .flat_map(|s| s.2.iter().copied())
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        let mut c = axes(&area, title, xl, yl, squared(span(&all), equal))?;
        for (_, color, pts) in points {
            c.draw_series(pts.iter().map(|p| Circle::new(*p, 2, color.filled())))
                .map_err(|e| e.to_string())?;
        }
        for (name, color, pts) in series {
            let width = if name.is_empty() { 1 } else { 2 };
            c.draw_series(LineSeries::new(decimated(pts), color.stroke_width(width)))
                .map_err(|e| e.to_string())?;
        }
        let entries = series
            .iter()
            .map(|s| (s.0, s.1, false))
            .chain(points.iter().map(|s| (s.0, s.1, true)));
        legend_strip(&legend, entries)?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// The bounding box of `pts` with a 5% margin.
fn span(pts: &[(f64, f64)]) -> ((f64, f64), (f64, f64)) {
    if pts.is_empty() {
        return ((0.0, 1.0), (0.0, 1.0));
    }
    let fold = |f: fn(&(f64, f64)) -> f64| {
        pts.iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
    };
    let ((x0, x1), (y0, y1)) = (fold(|p| p.0), fold(|p| p.1));
    let (px, py) = (((x1 - x0) * 0.05).max(1e-9), ((y1 - y0) * 0.05).max(1e-9));
    ((x0 - px, x1 + px), (y0 - py, y1 + py))
}

/// The last two parts of a run's path (`robot3/log.csv`): enough to tell
/// runs apart in a chart's title.
pub(crate) fn short(path: &str) -> String {
    let parts: Vec<&str> = path.rsplit('/').take(2).collect();
    parts.into_iter().rev().collect::<Vec<_>>().join("/")
}

fn xy(track: &[[f64; 3]]) -> Vec<(f64, f64)> {
    series_of(track.len(), track.iter().map(|p| (p[0], p[1])))
}

fn map(p: &RunPage) -> Result<String, String> {
    let (run, loc) = (p.run, p.loc);
    let dead = &p.figures.dead_reckoning;
    let mut series: Vec<Series> = vec![("dead reckoning", RGBColor(170, 170, 170), xy(dead))];
    if let Some(g) = &run.gt {
        series.push((
            "ground truth",
            BLACK,
            // rows where the motion capture lost the robot have none
            series_of(
                g.len(),
                g.iter().filter(|p| p[0].is_finite()).map(|p| (p[0], p[1])),
            ),
        ));
    }
    series.push(("EKF estimate", BLUE, xy(&loc.track)));
    if let Some((s, _)) = &loc.smoothed {
        series.push(("smoothed (RTS)", RGBColor(0, 150, 60), xy(s)));
    }
    let mut marks: Vec<(f64, f64)> = run.landmarks.iter().map(|z| (z.xl, z.yl)).collect();
    marks.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    marks.dedup();
    // the map is drawn around the robot's paths and the landmarks it saw;
    // dead reckoning that wanders far off would shrink everything else
    let keep: Vec<(f64, f64)> = series[1..]
        .iter()
        .flat_map(|s| s.2.iter().copied())
        .chain(marks.iter().copied())
        .collect();
    let ((x0, x1), (y0, y1)) = span(&keep);
    let pad = 0.25 * (x1 - x0).max(y1 - y0);
    series[0]
        .2
        .retain(|q| q.0 > x0 - pad && q.0 < x1 + pad && q.1 > y0 - pad && q.1 < y1 + pad);
    chart_beside(
        &format!("{}: map", short(&run.path)),
        "x (m)",
        "y (m)",
        &series,
        &[("landmarks", RED, marks)],
        true,
    )
}

fn error_over_time(p: &RunPage, e: &ErrorFigures) -> Result<String, String> {
    let run = p.run;
    let drawn = |pts: &[(f64, f64)]| series_of(pts.len(), pts.iter().copied());
    let mut series: Vec<Series> = vec![
        ("EKF error", BLUE, drawn(&e.filter.error)),
        (
            "EKF 3-sigma",
            RGBColor(120, 160, 255),
            drawn(&e.filter.bound),
        ),
    ];
    if let Some(s) = &e.smoothed {
        series.push(("smoothed error", RGBColor(0, 150, 60), drawn(&s.error)));
        series.push(("smoothed 3-sigma", RGBColor(140, 210, 160), drawn(&s.bound)));
    }
    chart_beside(
        &format!("{}: position error, 3-sigma bound", short(&run.path)),
        "t (s)",
        "position error (m)",
        &series,
        &[],
        false,
    )
}

fn nis_over_time(p: &RunPage) -> Result<String, String> {
    let run = p.run;
    let nis = &p.figures.nis;
    let (w, (lo, hi)) = (nis.window, nis.band);
    let pts = &nis.points;
    let mean = nis.mean.clone();
    let (a, b) = (
        pts.first().map_or(0.0, |q| q.0),
        pts.last().map_or(1.0, |q| q.0),
    );
    chart_beside(
        &format!("{}: NIS of each sighting used", short(&run.path)),
        "t (s)",
        "NIS (chi-square, 2 dof)",
        &[
            (&format!("mean of {w}"), BLUE, mean),
            ("95% band of the mean", RED, vec![(a, lo), (b, lo)]),
            ("", RED, vec![(a, hi), (b, hi)]),
        ],
        &[("each sighting", RGBColor(150, 150, 150), decimated(pts))],
        false,
    )
}

fn sweep_chart(
    sweep: &[kinegen_analysis::applications::sweep::SweepPoint],
) -> Result<String, String> {
    const COLORS: [RGBColor; 4] = [BLUE, RED, GREEN, MAGENTA];
    let mut names: Vec<&str> = sweep.iter().map(|p| p.noise.as_str()).collect();
    names.dedup();
    let series: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            (
                *n,
                COLORS[i % COLORS.len()],
                sweep
                    .iter()
                    .filter(|p| p.noise == *n)
                    .map(|p| (p.sigma.log10(), p.position_rmse_m))
                    .collect(),
            )
        })
        .collect();
    chart_beside(
        "noise sweep: position RMSE against each sigma",
        "log10(sigma)",
        "position RMSE (m)",
        &series,
        &[],
        false,
    )
}

/// A mean and its 95% bounds as a table cell.
fn bounded(m: Option<f64>, b: Option<Bounds>) -> String {
    match (m, b) {
        // the rows or sightings counted as the independent values they are
        // worth, which is what makes the bounds wide
        (Some(m), Some(b)) => format!(
            "{m:.2} ({:.2}-{:.2}, as {:.0} independent values)",
            b.lo, b.hi, b.independent
        ),
        _ => "n/a".into(),
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or("n/a".into(), |v| format!("{v:.digits$}"))
}

fn tables(runs: &[RunPage], noise: &[String]) -> String {
    let mut t = String::from(
        "<table><tr><th>run</th><th>position RMSE (m)</th><th>smoothed RMSE (m)</th><th>dead reckoning RMSE (m)</th>\
         <th>mean NEES (95% bounds)</th><th>smoothed mean NEES (95% bounds)</th><th>NEES median (chi-square's) / beyond 95% point</th>\
         <th>mean NIS (95% bounds)</th><th>NIS median (chi-square's) / beyond 95% point</th>\
         <th>sightings used</th><th>rejected (a consistent filter's share, at most by chance)</th><th>outside the log</th></tr>",
    );
    for p in runs {
        let s = p.summary;
        let spread = |x: Option<Spread>| {
            x.map_or("n/a".into(), |x| {
                format!(
                    "{:.2} ({:.2}) / {:.1}%",
                    x.median,
                    x.chi2_median,
                    100.0 * x.beyond_95
                )
            })
        };
        t += &format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&p.run.path),
            num(s.rmse, 4),
            num(s.smoothed.and_then(|x| x.rmse), 4),
            num(s.dead_reckoning, 4),
            bounded(s.nees, s.nees_bounds),
            s.smoothed.map_or("n/a".into(), |x| bounded(x.nees, x.nees_bounds)),
            spread(s.nees_spread),
            bounded(s.nis, s.nis_bounds),
            spread(s.nis_spread),
            p.loc.accepted,
            rejected_cell(p.loc.rejected, s.gate_tail),
            p.loc.outside,
        );
    }
    t += "</table>";
    t += &nees_parts_table(runs);
    // what NIS and NEES say together, where their means contradict each other
    for p in runs {
        if let Some(line) = say_consistency(p.summary) {
            t += &format!("<p>{}: {}</p>", esc(&p.run.path), esc(&line));
        }
    }
    t += "<table><tr><th>noise the filter ran with</th></tr>";
    for line in noise {
        t += &format!("<tr><td>{}</td></tr>", esc(line));
    }
    t + "</table>"
}

/// The gate's rejections with their share against a consistent filter's.
fn rejected_cell(rejected: usize, tail: Option<GateTail>) -> String {
    match tail {
        Some(g) => format!(
            "{rejected}: {:.2}% ({:.2}%, at most {:.2}%){}",
            100.0 * g.share(),
            100.0 * g.expected,
            100.0 * g.bound,
            if g.overconfident() {
                ": the innovations' tail is overconfident"
            } else {
                ""
            }
        ),
        None => rejected.to_string(),
    }
}

/// The NEES taken apart (runs with a ground truth): which belief is
/// overconfident, and when.
fn nees_parts_table(runs: &[RunPage]) -> String {
    let rows: String = runs
        .iter()
        .filter_map(|p| {
            let n = p.summary.nees_parts?;
            Some(format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td></tr>",
                esc(&p.run.path),
                bounded(Some(n.position.0), Some(n.position.1)),
                bounded(Some(n.heading.0), Some(n.heading.1)),
                n.near_sightings,
                n.far_from_sightings
            ))
        })
        .collect();
    if rows.is_empty() {
        return rows;
    }
    format!(
        "<table><tr><th>run</th><th>mean NEES of the position alone (95% bounds)</th>\
         <th>of the heading alone (95% bounds)</th><th>of the pose, the half of the rows just after sightings</th>\
         <th>the half far from them</th></tr>{rows}</table>"
    )
}

/// What NIS and NEES say together, when their means contradict each other.
pub fn say_consistency(s: &Summary) -> Option<String> {
    match s.consistency()? {
        Consistency::Agree => None,
        Consistency::HeavyTails { pessimistic_core } => Some(format!(
            "the means contradict each other, the medians do not: most of the time the filter is {} (both medians {} chi-square's), and its errors have heavier tails than its Gaussian: at times it is far more wrong than its covariance says (the report's error chart shows when)",
            if pessimistic_core { "pessimistic" } else { "overconfident" },
            if pessimistic_core { "below" } else { "above" },
        )),
        Consistency::Contradict => Some(format!(
            "the medians contradict each other too: the sightings and the ground truth disagree about how large the errors are{}; {}",
            if s.tail_sides_with_the_nees() {
                " (though the gate's rejections side with the NEES: the sightings' innovations are overconfident in their tail)"
            } else {
                ""
            },
            s.overconfident_part()
                .map_or(UNSEEN_ERROR, what_is_overconfident)
        )),
    }
}

/// What the gate's rejections say (None where they are within what a
/// consistent filter rejects by chance).
pub fn say_gate_tail(s: &Summary) -> Option<String> {
    let g = s.gate_tail.filter(|g| g.overconfident())?;
    Some(format!(
        "the gate rejected {:.2}% of the sightings, where a consistent filter rejects {:.2}% (at most {:.2}% by chance): the innovations have a heavier tail than the filter's covariance says (gross sensor errors, or moments the filter is far more wrong than it believes), which the mean NIS over the sightings let through does not count",
        100.0 * g.share(),
        100.0 * g.expected,
        100.0 * g.bound
    ))
}

/// What the innovations' likelihood that chose the noise may not see, when
/// the NEES's parts do not say which belief is wrong.
const UNSEEN_ERROR: &str = "the innovations' likelihood that chose the noise does not see an error the spec leaves out (a motion error that lasts or grows with the commands, which white process noise does not describe; a camera offset; a landmark map error; a lag)";

/// Where to look, by the belief the NEES's parts find overconfident.
fn what_is_overconfident(o: Overconfident) -> &'static str {
    match o {
        Overconfident::Heading => "the heading is overconfident: the robot turns otherwise than the model and its noise say (a turn-rate error that grows with the commands, a deadband, a lag)",
        Overconfident::PositionNearSightings => "the position is overconfident and the heading is not, most just after the sightings: the sightings place the robot more tightly than they should, by an error they share that their innovations cannot show (the camera's range reading or mounting, a landmark map error, an error that follows the viewing geometry), or along a direction they cannot check (a tight cluster of landmarks seen with a heading the motion got wrong in a turn)",
        Overconfident::PositionFarFromSightings => "the position is overconfident and the heading is not, most far from the sightings: the motion between them errs more than its noise says (a speed error that lasts or grows with the commands, a lag)",
        Overconfident::Position => "the position is overconfident and the heading is not, as much just after the sightings as far from them: both the sightings' shared errors (the camera's range reading or mounting, a landmark map error) and the motion's lasting errors (a speed error that grows with the commands, a lag) are candidates",
    }
}
