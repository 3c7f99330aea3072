//! Absolute inputs that a planned motion has to set but the inverse kinematics
//! only reads. A car-like robot declared without an `[inverse]` section gets a
//! derived inverse that gives the drive rate from vx with the steering angle
//! as a given configuration (the angle enters omega non-linearly, through a
//! tangent, which symbolic inversion does not undo). To drive a planned twist
//! (`simulate`, `inverse`) the angle is solved for numerically: Gauss-Newton on
//! the model's own twist, starting from the previous solution.
use crate::model_on_log::model::Runner;
use kinegen_model::decl::InputKind;
use kinegen_model::ir::ArgRole;

/// Newton iterations: a steering angle converges in 3-5 from the previous
/// sample's value; more means the twist is out of reach (a curvature beyond
/// the steering lock), and the best angle found is kept.
const MAX_ITERATIONS: usize = 30;

/// The names of the inverse twist's configuration argument, in order. A model
/// without inverse kinematics (`ModelIr::no_inverse`) has every input as
/// configuration: all of them are solved for numerically.
pub fn configuration_names(r: &Runner) -> Vec<String> {
    let Ok(inv) = r.ir.inverse_twist() else {
        return r.ir.inputs.iter().map(|i| i.name.clone()).collect();
    };
    inv.args
        .iter()
        .find(|a| a.role == ArgRole::Configuration)
        .map(|a| a.names.clone())
        .unwrap_or_default()
}

/// Positions in [`configuration_names`] of the absolute inputs the inverse does
/// not produce and `given` does not name: those a planned twist must set
/// (every input not given, for a model without inverse kinematics).
pub fn to_solve(r: &Runner, given: &[String]) -> Vec<usize> {
    let produced: &[String] = match r.ir.inverse_twist() {
        Ok(inv) => &inv.row_names,
        Err(_) => &[],
    };
    let no_inverse = r.ir.inverse_twist().is_err();
    configuration_names(r)
        .iter()
        .enumerate()
        .filter(|(_, n)| !given.contains(n) && !produced.contains(n))
        .filter(|(_, n)| {
            r.ir.inputs
                .iter()
                .any(|i| &i.name == *n && (no_inverse || i.kind == InputKind::Absolute))
        })
        .map(|(k, _)| k)
        .collect()
}

/// The model's inputs (in `r.ir.inputs` order) that the inverse gives for
/// `twist` at configuration `cfg` (one value per [`configuration_names`]).
pub fn inputs_for(r: &Runner, twist: &[f64; 3], cfg: &[f64]) -> Vec<f64> {
    let Ok(inv) = r.ir.inverse_twist() else {
        return cfg.to_vec();
    };
    let args: Vec<&[f64]> = inv
        .args
        .iter()
        .map(|a| match a.role {
            ArgRole::Twist => &twist[..],
            ArgRole::Params => &r.p[..],
            ArgRole::Configuration => cfg,
            _ => &[][..],
        })
        .collect();
    let out = r.eval(inv, &args);
    let names = configuration_names(r);
    r.ir.inputs
        .iter()
        .map(|i| {
            inv.row_names
                .iter()
                .position(|n| *n == i.name)
                .map(|k| out[k])
                .or_else(|| names.iter().position(|n| *n == i.name).map(|k| cfg[k]))
                .unwrap_or(0.0)
        })
        .collect()
}

/// Set `cfg[k]` for every k in `solve` so that the model's twist at the
/// inverse's inputs matches `twist` (least squares over vx, vy, omega), each
/// kept within its input's `range`; `cfg` holds the starting values.
pub fn solve(r: &Runner, twist: &[f64; 3], cfg: &mut [f64], solve: &[usize]) {
    if solve.is_empty() {
        return;
    }
    let names = configuration_names(r);
    let ranges: Vec<[f64; 2]> = solve
        .iter()
        .map(|&k| {
            r.ir.inputs
                .iter()
                .find(|i| i.name == names[k])
                .and_then(|i| i.range)
                .unwrap_or([f64::NEG_INFINITY, f64::INFINITY])
        })
        .collect();
    let miss = |cfg: &[f64]| -> [f64; 3] {
        let u = inputs_for(r, twist, cfg);
        let t = r.eval(r.ir.twist(), &[&u, &r.p]);
        [t[0] - twist[0], t[1] - twist[1], t[2] - twist[2]]
    };
    let norm = |m: &[f64; 3]| m.iter().map(|v| v * v).sum::<f64>();
    let n = solve.len();
    let mut now = miss(cfg);
    for _ in 0..MAX_ITERATIONS {
        // forward differences: the twist is smooth in a steering angle
        let mut jac = nalgebra::DMatrix::zeros(3, n);
        for (c, &k) in solve.iter().enumerate() {
            let h = 1e-7 * (1.0 + cfg[k].abs());
            let keep = cfg[k];
            cfg[k] += h;
            let moved = miss(cfg);
            cfg[k] = keep;
            for row in 0..3 {
                jac[(row, c)] = (moved[row] - now[row]) / h;
            }
        }
        // the minimum-norm Gauss-Newton step: with more inputs than the twist
        // constrains (an Ackermann car's two knuckles set one curvature, its
        // two rear wheels one speed) they move together from where they are.
        // Directions the forward differences cannot tell from the null space
        // (singular values below their ~1e-7 relative precision) are left out:
        // inverting them sends the knuckles to opposite locks and the wheels
        // to thousands of rad/s.
        let Some(svd) = crate::model_on_log::linalg::svd(jac) else {
            return;
        };
        let floor = 1e-6 * svd.singular_values.max().max(1e-300);
        let Ok(step) = svd.solve(&nalgebra::DVector::from_row_slice(&now), floor) else {
            return;
        };
        let before: Vec<f64> = solve.iter().map(|&k| cfg[k]).collect();
        for (c, &k) in solve.iter().enumerate() {
            cfg[k] = (cfg[k] - step[c]).clamp(ranges[c][0], ranges[c][1]);
        }
        let next = miss(cfg);
        // (a NaN miss counts as no progress)
        let progressed = norm(&next) < norm(&now);
        if !progressed {
            // no progress (at a lock, or the twist is out of reach): keep the best
            for (c, &k) in solve.iter().enumerate() {
                cfg[k] = before[c];
            }
            return;
        }
        let converged =
            step.amax() < 1e-12 * (1.0 + before.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        now = next;
        if converged {
            return;
        }
    }
}
