//! Neural gyrodometry (seed 000 sec. 3.2): a multilayer perceptron, one hidden
//! layer of tanh units and a linear output, maps a step's joint rates to the
//! robot's yaw rate and stands in for the gyro in gyrodometry (eq. 18). Trained
//! by Levenberg-Marquardt on the gyro of the fitting runs, as in the paper, with
//! early stopping on a validation split (the last 20% of every run) and a
//! deterministic initialisation. It is the black-box baseline the paper sets
//! against the calibrated kinematic model.
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// A trained network, with the standardisation of its inputs and output.
#[derive(Debug, Clone)]
pub struct Mlp {
    /// hidden x inputs
    w1: DMatrix<f64>,
    b1: DVector<f64>,
    w2: DVector<f64>,
    b2: f64,
    x_mean: Vec<f64>,
    x_std: Vec<f64>,
    y_mean: f64,
    y_std: f64,
    /// Which inputs are absolute angles (fed as their sine and cosine).
    angles: Vec<bool>,
}

/// The network's features of one step's inputs: rates and values as they are,
/// absolute angles (a caster's steering angle) as sine and cosine, so an angle
/// that has turned by 2 pi since training means what it meant then.
fn features(u: &[f64], angles: &[bool]) -> Vec<f64> {
    let mut f = Vec::with_capacity(u.len() + angles.iter().filter(|a| **a).count());
    for (v, a) in u.iter().zip(angles) {
        if *a {
            f.push(v.sin());
            f.push(v.cos());
        } else {
            f.push(*v);
        }
    }
    f
}

impl Mlp {
    pub fn hidden(&self) -> usize {
        self.b1.len()
    }

    /// The yaw rate (rad/s) for one step's inputs.
    pub fn predict(&self, u: &[f64]) -> f64 {
        self.predict_features(&features(u, &self.angles))
    }

    fn predict_features(&self, u: &[f64]) -> f64 {
        let x = DVector::from_iterator(
            u.len(),
            u.iter()
                .zip(self.x_mean.iter().zip(&self.x_std))
                .map(|(v, (m, s))| (v - m) / s),
        );
        let h = (&self.w1 * x + &self.b1).map(f64::tanh);
        self.y_mean + self.y_std * (self.w2.dot(&h) + self.b2)
    }
}

/// How training went.
#[derive(Debug, Clone)]
pub struct Training {
    pub iterations: usize,
    /// Iteration whose weights were kept (best on the validation split).
    pub best_iteration: usize,
    pub train_rmse: f64,
    pub validation_rmse: f64,
    pub samples: usize,
}

/// LM iterations at most; training stops earlier when the validation error has
/// not improved for PATIENCE iterations (early stopping).
const MAX_ITERATIONS: usize = 300;
const PATIENCE: usize = 15;
/// Weight decay per training sample (standardised inputs and output).
const DECAY: f64 = 1e-4;
/// Training samples at most (evenly spaced): the cost per LM iteration is
/// samples x weights^2 (50 hidden units, 9 inputs: ~550 weights).
const MAX_SAMPLES: usize = 8000;

/// (inputs, gyro yaw rate) of every step of runs with a gyro: (train, validation).
#[allow(clippy::type_complexity)]
fn samples(
    runs: &[Run],
    angles: &[bool],
) -> ((Vec<Vec<f64>>, Vec<f64>), (Vec<Vec<f64>>, Vec<f64>)) {
    let (mut tr, mut va) = ((Vec::new(), Vec::new()), (Vec::new(), Vec::new()));
    for run in runs {
        let Some(g) = &run.gyro else { continue };
        let cut = run.steps() * 4 / 5;
        for k in 0..run.steps() {
            // the gyro row k+1 reports the mean rate over step k (see Run::gyro)
            let dst = if k < cut { &mut tr } else { &mut va };
            dst.0.push(features(&run.u[k], angles));
            dst.1.push(g[k + 1]);
        }
    }
    (tr, va)
}

fn mean_std(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = v.clone().count().max(1) as f64;
    let m = v.clone().sum::<f64>() / n;
    let s = (v.map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt();
    // a constant input (a joint that never moves in these runs) stays at 0
    (m, if s > 1e-12 { s } else { 1.0 })
}

/// Why the network cannot be trained on the runs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrainError {
    #[error("--hidden: at least one hidden unit")]
    NoHiddenUnit,
    #[error("neural gyrodometry learns the yaw rate from a gyro: the runs have {steps} steps with a gyro, too few for {hidden} hidden units")]
    TooFewSteps { steps: usize, hidden: usize },
}

/// Train a network with `hidden` tanh units on the runs' gyro; `angles` marks
/// the inputs that are absolute angles.
pub fn train(
    runs: &[Run],
    angles: &[bool],
    hidden: usize,
    seed: u64,
) -> Result<(Mlp, Training), TrainError> {
    if hidden == 0 {
        return Err(TrainError::NoHiddenUnit);
    }
    let ((xs, ys), (xv, yv)) = samples(runs, angles);
    if xs.len() < 10 * hidden || xv.is_empty() {
        return Err(TrainError::TooFewSteps {
            steps: xs.len() + xv.len(),
            hidden,
        });
    }
    let data = Standardised::new(&xs, &ys, &xv, &yv);
    let shape = Shape {
        hidden,
        d: xs[0].len(),
    };
    let (best, it) = shape.fit(&data, seed);
    let mut net = shape.unpack(&best.1);
    net.x_mean = data.x_mean;
    net.x_std = data.x_std;
    net.y_mean = data.y_mean;
    net.y_std = data.y_std;
    net.angles = angles.to_vec();
    let rmse = |x: &[Vec<f64>], y: &[f64]| -> f64 {
        let s: f64 = x
            .iter()
            .zip(y)
            .map(|(x, y)| (net.predict_features(x) - y).powi(2))
            .sum();
        (s / y.len().max(1) as f64).sqrt()
    };
    let training = Training {
        iterations: it,
        best_iteration: best.2,
        train_rmse: rmse(&xs, &ys),
        validation_rmse: rmse(&xv, &yv),
        samples: data.train_x.len(),
    };
    Ok((net, training))
}

/// The training and validation samples standardised by the training
/// samples' mean and standard deviation (the training ones thinned to at
/// most `MAX_SAMPLES`).
struct Standardised {
    x_mean: Vec<f64>,
    x_std: Vec<f64>,
    y_mean: f64,
    y_std: f64,
    train_x: Vec<Vec<f64>>,
    train_y: Vec<f64>,
    val_x: Vec<Vec<f64>>,
    val_y: Vec<f64>,
}

impl Standardised {
    fn new(xs: &[Vec<f64>], ys: &[f64], xv: &[Vec<f64>], yv: &[f64]) -> Self {
        let d = xs[0].len();
        let (x_mean, x_std): (Vec<f64>, Vec<f64>) = (0..d)
            .map(|j| mean_std(xs.iter().map(move |x| x[j])))
            .unzip();
        let (y_mean, y_std) = mean_std(ys.iter().copied());
        let norm = |x: &[f64]| -> Vec<f64> {
            x.iter()
                .enumerate()
                .map(|(j, v)| (v - x_mean[j]) / x_std[j])
                .collect()
        };
        let stride = xs.len().div_ceil(MAX_SAMPLES).max(1);
        let train_x: Vec<Vec<f64>> = xs.iter().step_by(stride).map(|x| norm(x)).collect();
        let train_y: Vec<f64> = ys
            .iter()
            .step_by(stride)
            .map(|y| (y - y_mean) / y_std)
            .collect();
        let val_x: Vec<Vec<f64>> = xv.iter().map(|x| norm(x)).collect();
        let val_y: Vec<f64> = yv.iter().map(|y| (y - y_mean) / y_std).collect();
        Standardised {
            x_mean,
            x_std,
            y_mean,
            y_std,
            train_x,
            train_y,
            val_x,
            val_y,
        }
    }
}

/// The network's size: `hidden` tanh units on `d` features. Its weights
/// theta are [w1 (row-major hidden x d), b1, w2, b2].
struct Shape {
    hidden: usize,
    d: usize,
}

impl Shape {
    fn weights(&self) -> usize {
        self.hidden * self.d + 2 * self.hidden + 1
    }

    /// Random starting weights (scaled by each layer's fan-in), zero biases.
    fn initial(&self, seed: u64) -> Vec<f64> {
        let (hidden, d, n_w) = (self.hidden, self.d, self.weights());
        let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
        let init = Normal::new(0.0, 1.0 / (d as f64).sqrt()).expect("finite");
        let init2 = Normal::new(0.0, 1.0 / (hidden as f64).sqrt()).expect("finite");
        (0..n_w)
            .map(|i| {
                if i < hidden * d {
                    init.sample(&mut rng)
                } else if i < hidden * d + hidden {
                    0.0
                } else if i < n_w - 1 {
                    init2.sample(&mut rng)
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// The network of weights `t` (on standardised data).
    fn unpack(&self, t: &[f64]) -> Mlp {
        let (hidden, d, n_w) = (self.hidden, self.d, self.weights());
        Mlp {
            w1: DMatrix::from_row_slice(hidden, d, &t[..hidden * d]),
            b1: DVector::from_column_slice(&t[hidden * d..hidden * d + hidden]),
            w2: DVector::from_column_slice(&t[hidden * d + hidden..n_w - 1]),
            b2: t[n_w - 1],
            x_mean: vec![0.0; d],
            x_std: vec![1.0; d],
            y_mean: 0.0,
            y_std: 1.0,
            angles: Vec::new(),
        }
    }

    fn sse(&self, t: &[f64], x: &[Vec<f64>], y: &[f64]) -> f64 {
        let m = self.unpack(t);
        x.iter()
            .zip(y)
            .map(|(x, y)| (m.predict_features(x) - y).powi(2))
            .sum()
    }

    /// Levenberg-Marquardt on the weights with weight decay, stopped early
    /// on the validation error: (the best (validation SSE, weights,
    /// iteration)), the iterations run).
    fn fit(&self, data: &Standardised, seed: u64) -> ((f64, Vec<f64>, usize), usize) {
        let n_w = self.weights();
        let (train_x, train_y) = (&data.train_x, &data.train_y);
        let mut theta = self.initial(seed);
        // weight decay: the training cost adds DECAY * |theta|^2 (on standardised
        // data), which keeps a large network from fitting the gyro's noise
        let decay = DECAY * train_x.len() as f64;
        let penalised = |t: &[f64]| {
            self.sse(t, train_x, train_y) + decay * t.iter().map(|v| v * v).sum::<f64>()
        };
        let mut lambda = 1e-2;
        let mut cost = penalised(&theta);
        let mut best = (self.sse(&theta, &data.val_x, &data.val_y), theta.clone(), 0);
        let mut it = 0;
        while it < MAX_ITERATIONS && it - best.2 < PATIENCE {
            it += 1;
            let (mut jtj, mut jtr) = self.normal_equations(&theta, train_x, train_y);
            for k in 0..n_w {
                jtj[(k, k)] += decay;
                jtr[k] += decay * theta[k];
            }
            // Marquardt's damping, scaled by the diagonal, until a step lowers the cost
            let mut improved = false;
            for _ in 0..12 {
                let mut a = jtj.clone();
                for k in 0..n_w {
                    a[(k, k)] += lambda * (jtj[(k, k)] + 1e-9);
                }
                let Some(ch) = a.cholesky() else {
                    lambda *= 4.0;
                    continue;
                };
                let step = ch.solve(&(-&jtr));
                let trial: Vec<f64> = theta.iter().zip(step.iter()).map(|(t, s)| t + s).collect();
                let c = penalised(&trial);
                if c.is_finite() && c < cost {
                    theta = trial;
                    cost = c;
                    lambda = (lambda / 3.0).max(1e-12);
                    improved = true;
                    break;
                }
                lambda *= 4.0;
            }
            let v = self.sse(&theta, &data.val_x, &data.val_y);
            if v < best.0 {
                best = (v, theta.clone(), it);
            }
            if !improved {
                break;
            }
        }
        (best, it)
    }

    /// J^T J and J^T r of the training residuals at `theta`.
    fn normal_equations(
        &self,
        theta: &[f64],
        train_x: &[Vec<f64>],
        train_y: &[f64],
    ) -> (DMatrix<f64>, DVector<f64>) {
        let (hidden, d, n_w, n) = (self.hidden, self.d, self.weights(), train_x.len());
        // residuals and Jacobian (n x n_w)
        let m = self.unpack(theta);
        let mut jac = DMatrix::<f64>::zeros(n, n_w);
        let mut res = DVector::<f64>::zeros(n);
        for (i, (x, y)) in train_x.iter().zip(train_y).enumerate() {
            let xv = DVector::from_column_slice(x);
            let h = (&m.w1 * &xv + &m.b1).map(f64::tanh);
            res[i] = m.w2.dot(&h) + m.b2 - y;
            for j in 0..hidden {
                let g = m.w2[j] * (1.0 - h[j] * h[j]);
                for k in 0..d {
                    jac[(i, j * d + k)] = g * x[k];
                }
                jac[(i, hidden * d + j)] = g;
                jac[(i, hidden * d + hidden + j)] = h[j];
            }
            jac[(i, n_w - 1)] = 1.0;
        }
        // (the explicit transpose lets nalgebra use its blocked matrix product;
        // tr_mul goes column by column, 5x slower here)
        let jt = jac.transpose();
        (&jt * &jac, &jt * &res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run whose gyro is a smooth nonlinear function of two inputs.
    fn run(n: usize) -> Run {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.05).collect();
        let u: Vec<Vec<f64>> = (0..n - 1)
            .map(|k| {
                let s = k as f64 * 0.05;
                vec![(0.7 * s).sin() * 3.0, (0.31 * s).cos() * 2.0]
            })
            .collect();
        let mut gyro = vec![0.0];
        gyro.extend(
            u.iter()
                .map(|u| 0.2 * (u[0] - u[1]) + 0.05 * (u[0] * u[1]).tanh()),
        );
        Run {
            gyro: Some(gyro.into()),
            rate_inputs: vec![true, true],
            ..Run::bare(t, u)
        }
    }

    #[test]
    fn learns_a_smooth_yaw_rate_and_is_deterministic() {
        let r = run(2000);
        let (net, tr) = train(std::slice::from_ref(&r), &[false, false], 9, 1).unwrap();
        assert!(tr.validation_rmse < 0.01, "{tr:?}");
        let (net2, _) = train(std::slice::from_ref(&r), &[false, false], 9, 1).unwrap();
        assert_eq!(net.predict(&[1.0, -1.0]), net2.predict(&[1.0, -1.0]));
        assert!((net.predict(&[1.0, -1.0]) - (0.4 + 0.05 * (-1.0f64).tanh())).abs() < 0.02);
    }

    #[test]
    fn refuses_runs_without_a_gyro() {
        let mut r = run(200);
        r.gyro = None;
        let e = train(&[r], &[false, false], 9, 1).unwrap_err();
        assert!(matches!(e, TrainError::TooFewSteps { steps: 0, .. }), "{e}");
        assert!(e.to_string().contains("gyro"), "{e}");
    }
}
