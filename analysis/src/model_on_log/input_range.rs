//! Inputs that leave the `range` their spec declares. A model written for a
//! steering lock of +-1.2 rad says little about a log that steers to +-pi/2: its
//! error there is the model's domain, not the robot's parameters, and compare, fit
//! and diagnose say so (with the rows) instead of letting a fit blame
//! identifiability.

use crate::model_on_log::run::Run;
use kinegen_model::decl::{Input, InputKind};

/// Stretches listed by name before the rest are only counted.
const SHOWN_STRETCHES: usize = 3;

/// One input of one run outside its declared range.
#[derive(Debug, Clone, PartialEq)]
pub struct Excursion {
    pub path: String,
    pub input: String,
    pub column: String,
    pub range: [f64; 2],
    pub unit: String,
    /// Steps outside the range, and all steps.
    pub steps: usize,
    pub total: usize,
    /// Maximal stretches of steps outside: (first step, one past the last step).
    pub stretches: Vec<(usize, usize)>,
    /// The value furthest outside the range.
    pub extreme: f64,
    /// Start time of each stretch, and end time.
    pub times: Vec<(f64, f64)>,
    /// Rows are CSV lines (a bag's samples are numbered from 1).
    pub csv: bool,
}

impl std::fmt::Display for Excursion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [lo, hi] = self.range;
        let what = match self.unit.as_str() {
            "" => String::new(),
            u => format!(" {u}"),
        };
        write!(
            f,
            "{}: input `{}` (column `{}`) leaves its declared range [{lo}, {hi}]{what} on {} of {} steps (up to {:.4}{what}), ",
            self.path, self.input, self.column, self.steps, self.total, self.extreme
        )?;
        // step k spans rows k and k+1: CSV lines k+2 and k+3 (line 1 is the header)
        let (first, unit) = if self.csv {
            (2, "lines")
        } else {
            (1, "samples")
        };
        let shown: Vec<String> = self
            .stretches
            .iter()
            .zip(&self.times)
            .take(SHOWN_STRETCHES)
            .map(|(&(a, b), &(ta, tb))| {
                format!("{unit} {}-{} (t = {ta:.2}-{tb:.2} s)", a + first, b + first)
            })
            .collect();
        write!(f, "{}", shown.join(", "))?;
        if self.stretches.len() > SHOWN_STRETCHES {
            write!(
                f,
                " and {} more stretch(es)",
                self.stretches.len() - SHOWN_STRETCHES
            )?;
        }
        write!(
            f,
            ": the model was not written for these values, so its errors there may be the model's, not the parameters'"
        )
    }
}

/// Every input of `run` that leaves its declared range (the value of an absolute
/// input, the rate of a cumulative one, as the run holds them).
pub fn excursions(run: &Run, inputs: &[Input]) -> Vec<Excursion> {
    let mut out = Vec::new();
    for (i, input) in inputs.iter().enumerate() {
        let Some([lo, hi]) = input.range else {
            continue;
        };
        let outside = |v: f64| v < lo || v > hi;
        let mut stretches: Vec<(usize, usize)> = Vec::new();
        let (mut steps, mut extreme, mut worst) = (0, 0.0, 0.0);
        for (k, u) in run.u.iter().enumerate() {
            let v = u[i];
            if !outside(v) {
                continue;
            }
            steps += 1;
            let by = (lo - v).max(v - hi);
            if by > worst {
                (worst, extreme) = (by, v);
            }
            match stretches.last_mut() {
                Some(last) if last.1 == k => last.1 = k + 1,
                _ => stretches.push((k, k + 1)),
            }
        }
        if steps == 0 {
            continue;
        }
        let times = stretches
            .iter()
            .map(|&(a, b)| (run.t[a], run.t[b.min(run.t.len() - 1)]))
            .collect();
        out.push(Excursion {
            path: run.path.clone(),
            input: input.name.clone(),
            column: input.column.clone(),
            range: [lo, hi],
            unit: match input.kind {
                InputKind::Cumulative => format!("{}/s", input.unit),
                InputKind::Absolute => input.unit.clone(),
            },
            steps,
            total: run.u.len(),
            stretches,
            extreme,
            times,
            csv: !crate::logs::bag::is_bag(std::path::Path::new(&run.path)),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(range: [f64; 2]) -> Input {
        Input {
            name: "steer".into(),
            column: "steer_pos".into(),
            kind: InputKind::Absolute,
            range: Some(range),
            wrap: None,
            max_rate: None,
            between: None,
            unit: "rad".into(),
            doc: String::new(),
        }
    }

    fn run(values: &[f64]) -> Run {
        let t = (0..=values.len()).map(|k| 0.1 * k as f64).collect();
        Run {
            path: "logs/r.csv".into(),
            dt: vec![0.1; values.len()].into(),
            ..Run::bare(t, values.iter().map(|v| [*v]))
        }
    }

    #[test]
    fn finds_every_stretch_with_its_lines_and_extreme() {
        let r = run(&[0.0, 1.5, 1.6, 0.0, -1.3, 0.0]);
        let e = excursions(&r, &[input([-1.2, 1.2])]);
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].steps, 3);
        assert_eq!(e[0].stretches, vec![(1, 3), (4, 5)]);
        assert_eq!(e[0].extreme, 1.6);
        let text = e[0].to_string();
        assert!(
            text.starts_with("logs/r.csv: input `steer` (column `steer_pos`)"),
            "{text}"
        );
        assert!(text.contains("[-1.2, 1.2] rad on 3 of 6 steps"), "{text}");
        assert!(
            text.contains("lines 3-5 (t = 0.10-0.30 s), lines 6-7"),
            "{text}"
        );
    }

    #[test]
    fn inside_the_range_or_without_one_says_nothing() {
        let r = run(&[0.0, 1.2, -1.2]);
        assert!(excursions(&r, &[input([-1.2, 1.2])]).is_empty());
        let mut free = input([0.0, 0.0]);
        free.range = None;
        assert!(excursions(&run(&[5.0]), &[free]).is_empty());
    }
}
