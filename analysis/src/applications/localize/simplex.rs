//! Nelder-Mead on an objective that costs a whole filter pass, with the
//! points it may need next evaluated side by side.
//!
//! Written here rather than taken from a crate: the objective is a filter
//! pass over a log with a gate in it (piecewise smooth, no gradient), in 2
//! to 11 dimensions, and this is the textbook method in a page; argmin's
//! would bring its own math backend traits for that, and evaluates one
//! point at a time.
//!
//! The iterates are those of the sequential method, to the last bit, on any
//! number of threads: only *when* a point is evaluated changes. Each
//! iteration evaluates the reflection together with the inside contraction,
//! which the method needs next whenever the reflection is no better than
//! the worst vertex: on the MRCLAM logs' noise estimates that was 181 and
//! 120 of 757 and 596 evaluations, the most common second point (expansions
//! 43 and 59, outside contractions 15 and 9). The first simplex and a
//! shrink's vertices are evaluated all at once.
use rayon::prelude::*;

/// The objective: a point's cost (lower is better; may be infinite).
pub type Objective<'a> = dyn Fn(&[f64]) -> f64 + Sync + 'a;

/// Minimise `f` from `x0` by Nelder-Mead (the standard coefficients 1, 2,
/// 1/2, 1/2) with an initial simplex of side `step`, until the simplex's
/// values agree within `tol` (relative) or after `max_evals` evaluations
/// (counted as the sequential method counts them, so the result does not
/// depend on the speculation). Returns the best vertex and its cost.
pub fn minimise(
    f: &Objective,
    x0: Vec<f64>,
    step: f64,
    tol: f64,
    max_evals: usize,
) -> (f64, Vec<f64>) {
    let n = x0.len();
    let first: Vec<Vec<f64>> = std::iter::once(x0.clone())
        .chain((0..n).map(|i| {
            let mut x = x0.clone();
            x[i] += step;
            x
        }))
        .collect();
    let mut simplex: Vec<(f64, Vec<f64>)> = first.into_par_iter().map(|x| (f(&x), x)).collect();
    let mut evals = n + 1;
    while evals < max_evals {
        simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (lo, hi) = (simplex[0].0, simplex[n].0);
        if (hi - lo).abs() <= tol * (1.0 + lo.abs()) && hi.is_finite() {
            break;
        }
        evals += iterate(f, &mut simplex);
    }
    simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
    simplex.swap_remove(0)
}

/// One Nelder-Mead iteration on a sorted simplex: replace its worst vertex,
/// or shrink it toward its best. Returns the evaluations the sequential
/// method would have made.
fn iterate(f: &Objective, simplex: &mut [(f64, Vec<f64>)]) -> usize {
    let n = simplex.len() - 1;
    let centroid: Vec<f64> = (0..n)
        .map(|j| simplex[..n].iter().map(|s| s.1[j]).sum::<f64>() / n as f64)
        .collect();
    let worst = simplex[n].1.clone();
    let reflect = lerp(&centroid, &worst, -1.0);
    let inside = lerp(&centroid, &worst, 0.5);
    let (fr, f_inside) = rayon::join(|| f(&reflect), || f(&inside));
    if fr < simplex[0].0 {
        let expand = lerp(&centroid, &worst, -2.0);
        let fe = f(&expand);
        simplex[n] = if fe < fr { (fe, expand) } else { (fr, reflect) };
        return 2;
    }
    if fr < simplex[n - 1].0 {
        simplex[n] = (fr, reflect);
        return 1;
    }
    let (fc, contract) = if fr < simplex[n].0 {
        let outside = lerp(&centroid, &reflect, 0.5);
        (f(&outside), outside)
    } else {
        (f_inside, inside)
    };
    if fc < simplex[n].0.min(fr) {
        simplex[n] = (fc, contract);
        return 2;
    }
    let best = simplex[0].1.clone();
    simplex[1..].par_iter_mut().for_each(|s| {
        s.1 = lerp(&best, &s.1, 0.5);
        s.0 = f(&s.1);
    });
    2 + n
}

/// `a + t (b - a)`, coordinate by coordinate.
fn lerp(a: &[f64], b: &[f64], t: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| a + t * (b - a)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_quadratic_minimum() {
        let f = |x: &[f64]| (x[0] - 1.0).powi(2) + 10.0 * (x[1] + 2.0).powi(2) + 3.0;
        let (c, x) = minimise(&f, vec![0.0, 0.0], 0.5, 1e-12, 2000);
        assert!(
            (x[0] - 1.0).abs() < 1e-4 && (x[1] + 2.0).abs() < 1e-4,
            "{x:?}"
        );
        assert_eq!(c, f(&x));
    }

    /// The textbook method, one evaluation at a time, counting them.
    fn sequential(
        f: &dyn Fn(&[f64]) -> f64,
        x0: Vec<f64>,
        step: f64,
        tol: f64,
        max_evals: usize,
    ) -> (f64, Vec<f64>) {
        let n = x0.len();
        let mut simplex: Vec<(f64, Vec<f64>)> = vec![(f(&x0), x0.clone())];
        for i in 0..n {
            let mut x = x0.clone();
            x[i] += step;
            simplex.push((f(&x), x));
        }
        let mut evals = n + 1;
        while evals < max_evals {
            simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (lo, hi) = (simplex[0].0, simplex[n].0);
            if (hi - lo).abs() <= tol * (1.0 + lo.abs()) && hi.is_finite() {
                break;
            }
            let centroid: Vec<f64> = (0..n)
                .map(|j| simplex[..n].iter().map(|s| s.1[j]).sum::<f64>() / n as f64)
                .collect();
            let worst = simplex[n].1.clone();
            let reflect = lerp(&centroid, &worst, -1.0);
            let fr = f(&reflect);
            evals += 1;
            if fr < simplex[0].0 {
                let expand = lerp(&centroid, &worst, -2.0);
                let fe = f(&expand);
                evals += 1;
                simplex[n] = if fe < fr { (fe, expand) } else { (fr, reflect) };
            } else if fr < simplex[n - 1].0 {
                simplex[n] = (fr, reflect);
            } else {
                let towards = if fr < simplex[n].0 { &reflect } else { &worst };
                let contract = lerp(&centroid, towards, 0.5);
                let fc = f(&contract);
                evals += 1;
                if fc < simplex[n].0.min(fr) {
                    simplex[n] = (fc, contract);
                } else {
                    let best = simplex[0].1.clone();
                    for s in simplex.iter_mut().skip(1) {
                        s.1 = lerp(&best, &s.1, 0.5);
                        s.0 = f(&s.1);
                        evals += 1;
                    }
                }
            }
        }
        simplex.sort_by(|a, b| a.0.total_cmp(&b.0));
        simplex.swap_remove(0)
    }

    /// The speculation changes when points are evaluated, never which: on a
    /// rugged objective (every move of the method taken, shrinks included)
    /// and under every evaluation budget, the result is the sequential
    /// method's to the bit.
    #[test]
    fn the_iterates_are_the_sequential_methods() {
        let rugged = |x: &[f64]| {
            x.iter()
                .enumerate()
                .map(|(i, v)| (i as f64 + 1.0) * v * v + (3.0 * v).sin().abs())
                .sum::<f64>()
                + if x[0] > 0.7 { f64::INFINITY } else { 0.0 }
        };
        for budget in [5, 9, 17, 40, 120, 600] {
            let x0 = vec![0.3, -1.2, 2.0, 0.5];
            let a = sequential(&rugged, x0.clone(), 0.7, 1e-9, budget);
            let b = minimise(&rugged, x0, 0.7, 1e-9, budget);
            assert_eq!(a.0.to_bits(), b.0.to_bits(), "budget {budget}");
            assert_eq!(a.1, b.1, "budget {budget}");
        }
    }
}
