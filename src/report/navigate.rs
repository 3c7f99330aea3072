//! `kinegen navigate --report`: the grid, the planned cells, and each
//! drive's true path against its odometry.
use super::{legend_strip, page, series_of, write, RealChart, LEGEND_W, W};
use kinegen_analysis::applications::grid::Grid;
use kinegen_analysis::applications::navigate::Drive;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;

/// `kinegen navigate --report`: the grid (obstacles dark, safety zone light),
/// the planned cells, and for each drive the true path (where the robot went)
/// and the odometry (where it believed it was), collisions marked.
pub fn navigate_report(
    dir: &Path,
    grid: &Grid,
    drives: &[(&str, &Drive)],
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
fn navigation_map(grid: &Grid, name: &str, d: &Drive) -> Result<String, String> {
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

/// The arena's obstacles and safety zone, cell by cell.
fn draw_arena(c: &mut RealChart<'_, '_>, grid: &Grid) -> Result<(), String> {
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
