//! The occupancy grid and cellular automaton of seed 004: obstacles enlarged
//! by one cell (the safety zone), distances to the goal diffused over the
//! Moore neighbourhood (8 headings), and the path down the distances.
//!
//! Grid files are text, one row per line, top row first: `.` free, `#`
//! obstacle, `S` start, `G` goal (each exactly once). Lines starting with `;`
//! are comments. Row 0 is the top line; y grows upwards, so the bottom line is
//! y = 0.
use crate::logs::log::LogError;
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
        let text = kinegen_model::files::read_text(path).map_err(|(at, e)| match at {
            Some((line, col)) => {
                LogError::new(path, Some(line), None, format!("column {col}: {e}"))
            }
            None => LogError::new(path, None, None, format!("cannot read the grid: {e}")),
        })?;
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
    ///
    /// That fixed point is a shortest path from the goal in which entering a
    /// cell costs 1 or SAFETY_COST, so it is computed as one: a wavefront over
    /// buckets of equal distance (Dial's algorithm; the costs are small
    /// integers), each cell settled once, linear in the cells. Sweeping the
    /// grid until nothing changed took a pass per cell of path length: n^3 in
    /// the grid's side (a 1000 x 1000 grid over two minutes).
    pub fn distances(&self) -> Vec<Vec<u32>> {
        let (rows, cols) = (self.rows(), self.cols());
        let mut d = vec![vec![UNREACHABLE; cols]; rows];
        d[self.goal.0][self.goal.1] = 0;
        // bucket i % (SAFETY_COST + 1) holds the cells at distance i to expand
        let width = SAFETY_COST as usize + 1;
        let mut buckets: Vec<Vec<(usize, usize)>> = vec![Vec::new(); width];
        buckets[0].push(self.goal);
        let (mut at, mut pending) = (0u32, 1usize);
        while pending > 0 {
            let bucket = std::mem::take(&mut buckets[at as usize % width]);
            for (r, c) in bucket {
                pending -= 1;
                if d[r][c] != at {
                    continue; // settled earlier at a smaller distance
                }
                for (a, b) in self.neighbours((r, c)) {
                    if self.cells[a][b] == Cell::Obstacle || (a, b) == self.goal {
                        continue;
                    }
                    let cost = if self.cells[a][b] == Cell::Safety {
                        SAFETY_COST
                    } else {
                        1
                    };
                    let v = at.saturating_add(cost);
                    if v < d[a][b] {
                        d[a][b] = v;
                        buckets[v as usize % width].push((a, b));
                        pending += 1;
                    }
                }
            }
            at += 1;
        }
        d
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
        // only the cells within the radius of the point can touch it (all of
        // them, every integration step, made a 1000 x 1000 drive take 50 s)
        let span = |v: f64, n: usize| {
            let lo = ((v - radius) / self.cell).floor().max(0.0) as usize;
            let hi = (((v + radius) / self.cell).floor().max(0.0) as usize).min(n - 1);
            lo..=hi
        };
        let rows = self.rows();
        for rb in span(y, rows) {
            let r = rows - 1 - rb; // row 0 is at the top
            for c in span(x, self.cols()) {
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

    /// The automaton as seed 004 states it: sweep until nothing changes.
    fn swept(g: &Grid) -> Vec<Vec<u32>> {
        let mut d = vec![vec![UNREACHABLE; g.cols()]; g.rows()];
        d[g.goal.0][g.goal.1] = 0;
        loop {
            let mut changed = false;
            for r in 0..g.rows() {
                for c in 0..g.cols() {
                    if g.cells[r][c] == Cell::Obstacle || (r, c) == g.goal {
                        continue;
                    }
                    let best = g.neighbours((r, c)).map(|(a, b)| d[a][b]).min().unwrap();
                    let cost = if g.cells[r][c] == Cell::Safety {
                        SAFETY_COST
                    } else {
                        1
                    };
                    if best.saturating_add(cost) < d[r][c] {
                        d[r][c] = best.saturating_add(cost);
                        changed = true;
                    }
                }
            }
            if !changed {
                return d;
            }
        }
    }

    /// The wavefront reaches the automaton's fixed point, cell for cell, on
    /// 200 random grids with obstacles, walled-off pockets and safety zones.
    #[test]
    fn the_wavefront_is_the_automatons_fixed_point() {
        let mut seed = 12345u64;
        let mut next = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as usize
        };
        for _ in 0..200 {
            let (rows, cols) = (3 + next() % 15, 3 + next() % 15);
            let density = next() % 40;
            let (s, g) = (
                (next() % rows, next() % cols),
                (next() % rows, next() % cols),
            );
            if s == g {
                continue;
            }
            let mut text = String::new();
            for r in 0..rows {
                for c in 0..cols {
                    text.push(if (r, c) == s {
                        'S'
                    } else if (r, c) == g {
                        'G'
                    } else if next() % 100 < density {
                        '#'
                    } else {
                        '.'
                    });
                }
                text.push('\n');
            }
            // (a grid whose goal cannot be reached is refused when read)
            let Ok(grid) = grid(&text) else { continue };
            assert_eq!(grid.distances(), swept(&grid), "{text}");
        }
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
