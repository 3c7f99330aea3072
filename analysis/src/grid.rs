//! The occupancy grid and cellular automaton of seed 004: obstacles enlarged
//! by one cell (the safety zone), distances to the goal diffused over the
//! Moore neighbourhood (8 headings), and the path down the distances.
//!
//! Grid files are text, one row per line, top row first: `.` free, `#`
//! obstacle, `S` start, `G` goal (each exactly once). Lines starting with `;`
//! are comments. Row 0 is the top line; y grows upwards, so the bottom line is
//! y = 0.
use crate::log::LogError;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    Free,
    Obstacle,
    /// Free, but next to an obstacle (enlarged by one cell).
    Safety,
}

#[derive(Debug, Clone)]
pub struct Grid {
    pub file: PathBuf,
    /// cells[row][col], row 0 at the top of the file.
    pub cells: Vec<Vec<Cell>>,
    pub start: (usize, usize),
    pub goal: (usize, usize),
    /// Cell side, m.
    pub cell: f64,
}

/// Cellular-automaton distance of a safety cell's neighbours: a path may cross
/// the safety zone only where nothing else leads on (a robot inside one can
/// always leave it), never an obstacle.
const SAFETY_COST: u32 = 20;
pub const UNREACHABLE: u32 = u32::MAX;
/// Penetration (m) below which a robot touching a wall has not collided.
const CONTACT_TOLERANCE: f64 = 1e-3;

/// The 8 headings of the Moore neighbourhood: (d row, d col).
pub const MOORE: [(i64, i64); 8] = [
    (-1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
    (1, 0),
    (1, -1),
    (0, -1),
    (-1, -1),
];

impl Grid {
    pub fn read(path: &Path, cell: f64) -> Result<Grid, LogError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| LogError::new(path, None, None, format!("cannot read the grid: {e}")))?;
        Grid::parse(path, &text, cell)
    }

    pub fn parse(path: &Path, text: &str, cell: f64) -> Result<Grid, LogError> {
        let at = |line: usize, col: Option<usize>, m: String| {
            LogError::new(
                path,
                Some(line),
                None,
                match col {
                    Some(c) => format!("column {c}: {m}"),
                    None => m,
                },
            )
        };
        let mut cells = Vec::new();
        let (mut start, mut goal) = (None, None);
        let mut width = None;
        let mut lines = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim_end();
            if line.is_empty() || line.starts_with(';') {
                continue;
            }
            let row = cells.len();
            let mut r = Vec::new();
            for (j, ch) in line.chars().enumerate() {
                r.push(match ch {
                    '.' => Cell::Free,
                    '#' => Cell::Obstacle,
                    'S' | 'G' => {
                        let slot = if ch == 'S' { &mut start } else { &mut goal };
                        if let Some((pr, pc, pl)) = *slot {
                            let _ = (pr, pc);
                            return Err(at(
                                i + 1,
                                Some(j + 1),
                                format!("a second `{ch}` (the first is on line {pl})"),
                            ));
                        }
                        *slot = Some((row, j, i + 1));
                        Cell::Free
                    }
                    other => {
                        return Err(at(
                            i + 1,
                            Some(j + 1),
                            format!(
                            "`{other}` is not a grid cell (. free, # obstacle, S start, G goal)"
                        ),
                        ))
                    }
                });
            }
            match width {
                None => width = Some(r.len()),
                Some(w) if w != r.len() => {
                    return Err(at(
                        i + 1,
                        Some(r.len().min(w) + 1),
                        format!(
                        "row of {} cells where the first row has {w}: the grid must be rectangular",
                        r.len()
                    ),
                    ))
                }
                _ => {}
            }
            lines.push(i + 1);
            cells.push(r);
        }
        if cells.is_empty() {
            return Err(LogError::new(
                path,
                None,
                None,
                "the grid has no rows".to_string(),
            ));
        }
        let start = start
            .ok_or_else(|| LogError::new(path, None, None, "no start cell `S`".to_string()))?;
        let goal =
            goal.ok_or_else(|| LogError::new(path, None, None, "no goal cell `G`".to_string()))?;
        let mut g = Grid {
            file: path.to_path_buf(),
            cells,
            start: (start.0, start.1),
            goal: (goal.0, goal.1),
            cell,
        };
        g.enlarge();
        let dist = g.distances();
        if dist[start.0][start.1] == UNREACHABLE {
            return Err(at(
                start.2,
                Some(start.1 + 1),
                "no path from the start `S` to the goal `G`: obstacles close every way".into(),
            ));
        }
        Ok(g)
    }

    fn rows(&self) -> usize {
        self.cells.len()
    }

    fn cols(&self) -> usize {
        self.cells[0].len()
    }

    pub fn neighbours(&self, (r, c): (usize, usize)) -> impl Iterator<Item = (usize, usize)> + '_ {
        MOORE.iter().filter_map(move |(dr, dc)| {
            let (nr, nc) = (r as i64 + dr, c as i64 + dc);
            (nr >= 0 && nc >= 0 && (nr as usize) < self.rows() && (nc as usize) < self.cols())
                .then_some((nr as usize, nc as usize))
        })
    }

    /// Mark the free cells next to an obstacle, or on the border (the arena's
    /// walls), as the safety zone.
    #[allow(clippy::needless_range_loop)] // (r, c) index the grid and its neighbours together
    fn enlarge(&mut self) {
        let mut out = self.cells.clone();
        let (rows, cols) = (self.rows(), self.cols());
        for r in 0..rows {
            for c in 0..cols {
                let border = r == 0 || c == 0 || r + 1 == rows || c + 1 == cols;
                if self.cells[r][c] == Cell::Free
                    && (border
                        || self
                            .neighbours((r, c))
                            .any(|(a, b)| self.cells[a][b] == Cell::Obstacle))
                {
                    out[r][c] = Cell::Safety;
                }
            }
        }
        self.cells = out;
    }

    /// The automaton: every cell takes the smallest neighbour distance plus one
    /// (plus SAFETY_COST into a safety cell), from 0 at the goal, until nothing
    /// changes. Obstacles stay unreachable.
    pub fn distances(&self) -> Vec<Vec<u32>> {
        let mut d = vec![vec![UNREACHABLE; self.cols()]; self.rows()];
        d[self.goal.0][self.goal.1] = 0;
        loop {
            let mut changed = false;
            for r in 0..self.rows() {
                for c in 0..self.cols() {
                    if self.cells[r][c] == Cell::Obstacle || (r, c) == self.goal {
                        continue;
                    }
                    let best = self
                        .neighbours((r, c))
                        .map(|(a, b)| d[a][b])
                        .min()
                        .unwrap_or(UNREACHABLE);
                    let cost = if self.cells[r][c] == Cell::Safety {
                        SAFETY_COST
                    } else {
                        1
                    };
                    let v = best.saturating_add(cost);
                    if v < d[r][c] {
                        d[r][c] = v;
                        changed = true;
                    }
                }
            }
            if !changed {
                return d;
            }
        }
    }

    /// Cells from `from` to the goal, always to the neighbour with the smallest
    /// distance (ties: the first of the 8 headings).
    pub fn path(&self, dist: &[Vec<u32>], from: (usize, usize)) -> Vec<(usize, usize)> {
        let mut p = vec![from];
        let mut cur = from;
        while cur != self.goal && p.len() <= self.rows() * self.cols() {
            let Some(next) = self
                .neighbours(cur)
                .filter(|&(a, b)| dist[a][b] < dist[cur.0][cur.1])
                .min_by_key(|&(a, b)| dist[a][b])
            else {
                break;
            };
            p.push(next);
            cur = next;
        }
        p
    }

    /// Centre of a cell in metres (x right, y up, origin at the bottom-left corner).
    pub fn centre(&self, (r, c): (usize, usize)) -> [f64; 2] {
        [
            (c as f64 + 0.5) * self.cell,
            ((self.rows() - 1 - r) as f64 + 0.5) * self.cell,
        ]
    }

    /// The cell under a point, if inside the grid.
    pub fn cell_at(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let c = (x / self.cell).floor();
        let rb = (y / self.cell).floor();
        if c < 0.0 || rb < 0.0 || c as usize >= self.cols() || rb as usize >= self.rows() {
            return None;
        }
        Some((self.rows() - 1 - rb as usize, c as usize))
    }

    /// Does a disc of `radius` at (x, y) press into an obstacle or the grid's
    /// border (a wall) by more than CONTACT_TOLERANCE? (A robot exactly one
    /// radius from a wall, at a cell's centre next to it, only touches it.)
    pub fn collides(&self, x: f64, y: f64, radius: f64) -> bool {
        let (w, h) = (
            self.cols() as f64 * self.cell,
            self.rows() as f64 * self.cell,
        );
        let radius = radius - CONTACT_TOLERANCE;
        if x < radius || y < radius || x > w - radius || y > h - radius {
            return true;
        }
        for r in 0..self.rows() {
            for c in 0..self.cols() {
                if self.cells[r][c] != Cell::Obstacle {
                    continue;
                }
                let [cx, cy] = self.centre((r, c));
                let half = self.cell / 2.0;
                let dx = ((x - cx).abs() - half).max(0.0);
                let dy = ((y - cy).abs() - half).max(0.0);
                if dx * dx + dy * dy < radius * radius {
                    return true;
                }
            }
        }
        false
    }

    pub fn in_safety_zone(&self, x: f64, y: f64) -> bool {
        self.cell_at(x, y)
            .is_some_and(|(r, c)| self.cells[r][c] == Cell::Safety)
    }

    /// Rows of the grid as text (for reports): obstacle, safety zone, free.
    pub fn cell(&self, r: usize, c: usize) -> Cell {
        self.cells[r][c]
    }

    pub fn size(&self) -> (usize, usize) {
        (self.rows(), self.cols())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(text: &str) -> Result<Grid, LogError> {
        Grid::parse(Path::new("t.txt"), text, 0.07)
    }

    #[test]
    fn distances_diffuse_over_the_moore_neighbourhood() {
        let g = grid("......\n.S....\n......\n....G.\n......\n").unwrap();
        let d = g.distances();
        // diagonal moves count one: the start is max(|dr|, |dc|) = 3 away
        assert_eq!(d[1][1], 3);
        let p = g.path(&d, g.start);
        assert_eq!(p.len(), 4);
        assert_eq!(*p.last().unwrap(), g.goal);
    }

    #[test]
    fn the_path_keeps_out_of_the_safety_zone_when_it_can() {
        // a wall with a gap; cells next to it are the safety zone
        let g = grid(concat!(
            ".........\n",
            ".S..#....\n",
            "....#....\n",
            "....#..G.\n",
            ".........\n",
            ".........\n",
            ".........\n",
        ))
        .unwrap();
        assert_eq!(g.cell(1, 3), Cell::Safety);
        assert_eq!(g.cell(1, 0), Cell::Safety, "the border is a wall");
        let d = g.distances();
        let p = g.path(&d, g.start);
        assert_eq!(*p.last().unwrap(), g.goal);
        assert!(p.iter().all(|&(r, c)| g.cell(r, c) != Cell::Obstacle));
        // it goes around the wall's lower end, two rows clear of it
        assert!(p.iter().any(|&(r, _)| r == 5), "{p:?}");
    }

    #[test]
    fn bad_grids_are_located() {
        let e = grid("S..\n.#\n..G\n").unwrap_err().to_string();
        assert!(e.contains("t.txt:2") && e.contains("rectangular"), "{e}");
        let e = grid("S.x\n..G\n").unwrap_err().to_string();
        assert!(e.contains("t.txt:1") && e.contains("column 3"), "{e}");
        let e = grid("S.#..\n###..\n....G\n").unwrap_err().to_string();
        assert!(e.contains("no path"), "{e}");
        let e = grid("S..\n...\n").unwrap_err().to_string();
        assert!(e.contains("no goal"), "{e}");
        let e = grid("S.S\n..G\n").unwrap_err().to_string();
        assert!(e.contains("second `S`"), "{e}");
    }
}
