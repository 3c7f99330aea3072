//! What the filter believes: the pose and its covariance, and the lingering
//! errors of the landmarks' sightings with theirs.
//!
//! A camera's error does not start afresh every frame. The filter carries
//! it as a state (Gelb, Applied Optimal Estimation, 1974, sec. 3.8: a
//! coloured measurement error as a first-order Gauss-Markov process), in up
//! to two parts:
//!
//! - a persistent part per landmark (the error of seeing one landmark from
//!   about one place, or of where the map puts it), of the landmarks most
//!   recently sighted ([`super::active`]);
//! - a shared part, one for every landmark: the camera's own (it tilts, it
//!   rocks). Against Vicon, the bearing errors of two landmarks in one frame
//!   of the MRCLAM robots' cameras correlate 0.68-0.87 and their range
//!   errors per metre 0.43-0.70. Carried per landmark, such an error is
//!   counted once for every landmark that shows it, and the filter trusts
//!   its heading too much.
//!
//! A sighting's error is its landmark's persistent part, the shared part and
//! a white part. Estimating the lingering ones is what keeps a filter that
//! sees one landmark for seconds from trusting the same error a hundred
//! times.
//!
//! The errors change only by decaying toward zero, so their covariance and
//! their correlation with the pose are brought up to date only when a
//! sighting needs them ([`Belief::catch_up`]): between sightings a step costs
//! no more than without them.
use super::active::{Slots, Taken};
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

/// One lingering part of the sightings' errors: the stationary variance of
/// [range, bearing] (the range's per metre of range), how long it lasts, and
/// whose it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorPart {
    pub var: Vector2<f64>,
    pub memory_s: f64,
    pub owner: Owner,
}

/// Whose error a part is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Owner {
    /// Each landmark has its own; the filter carries those of at most this
    /// many landmarks at once (the most recently sighted).
    Landmark(usize),
    /// One error shared by every sighting: the camera's own (it tilts, it
    /// rocks: on the MRCLAM robots the bearing errors of two landmarks in one
    /// frame correlate 0.68-0.87 against Vicon).
    Sensor,
}

/// The most lingering parts a sighting's error has.
pub const PARTS: usize = 2;

/// The slots (over all parts) that hold a sighted landmark's errors.
#[derive(Debug, Clone, Copy, Default)]
pub struct Held {
    slot: [usize; PARTS],
    n: usize,
}

impl Held {
    fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.slot[..self.n].iter().copied()
    }
}

/// One part's table: its slots are `offset..offset + slots.len()` of the
/// belief's.
#[derive(Debug, Clone)]
struct Part {
    var: Matrix2<f64>,
    memory_s: f64,
    /// Which landmark's error each slot holds (None: one shared slot).
    slots: Option<Slots>,
    offset: usize,
    len: usize,
    /// The product of the decays since the blocks were last folded (see
    /// [`Belief::bb`]).
    decay: f64,
}

#[derive(Debug, Clone)]
pub struct Belief {
    pub x: Vector3<f64>,
    /// sin and cos of the heading x[2], kept in step with it.
    pub sin_cos: (f64, f64),
    pub p: Matrix3<f64>,
    /// The lingering errors, [range, bearing] per slot, all parts' slots one
    /// after another.
    bias: Vec<Vector2<f64>>,
    /// The part of each slot.
    part_of: Vec<usize>,
    parts: Vec<Part>,
    /// Pose-error covariance (3 x 2 per slot), as of `since`.
    pb: Vec<Matrix3x2<f64>>,
    /// Error covariance (2 x 2 blocks, row-major over slots, upper triangle
    /// only: it is symmetric, and the update's cost is in these blocks), as
    /// of `since`, stored scaled: block (i, j) of the covariance is
    /// `decay_i * decay_j` times the stored block, plus the stationary
    /// variance on the diagonal blocks, so a decay costs one multiplication
    /// per part instead of a pass over every block.
    bb: Vec<Matrix2<f64>>,
    /// The product of the transitions F since `since`.
    f_acc: Matrix3<f64>,
    since: f64,
    /// Buffers [`Belief::fuse`] reuses (one slot each): an update allocates
    /// nothing, and the noise estimate runs tens of thousands of them.
    fuse_buffers: FuseBuffers,
}

/// Per-slot buffers of one update: the error rows of P H^T, the errors'
/// gains, and each slot's stored-block unscaling.
#[derive(Debug, Clone, Default)]
struct FuseBuffers {
    eh: Vec<Matrix2<f64>>,
    kb: Vec<Matrix2<f64>>,
    unscale: Vec<f64>,
}

/// A stored block's scale is folded in before it falls below this (so
/// dividing by it stays exact enough).
const FOLD_BELOW: f64 = 1e-3;

impl Belief {
    /// The belief at time `t`: pose `x` with covariance `p`, and no errors
    /// yet known for `landmarks` landmarks, each part's at its stationary
    /// variance (a part with no variance is not carried).
    pub fn new(
        x: Vector3<f64>,
        p: Matrix3<f64>,
        landmarks: usize,
        parts: &[ErrorPart],
        t: f64,
    ) -> Belief {
        let mut carried = Vec::new();
        let mut part_of = Vec::new();
        for e in parts.iter().filter(|e| e.var.iter().any(|v| *v > 0.0)) {
            let (len, slots) = match e.owner {
                Owner::Landmark(capacity) => {
                    let len = landmarks.min(capacity);
                    (len, Some(Slots::new(landmarks, len)))
                }
                Owner::Sensor => (1, None),
            };
            part_of.extend(std::iter::repeat_n(carried.len(), len));
            carried.push(Part {
                var: Matrix2::from_diagonal(&e.var),
                memory_s: e.memory_s,
                slots,
                offset: part_of.len() - len,
                len,
                decay: 1.0,
            });
        }
        assert!(carried.len() <= PARTS, "at most {PARTS} lingering parts");
        let n = part_of.len();
        Belief {
            x,
            sin_cos: x[2].sin_cos(),
            p,
            bias: vec![Vector2::zeros(); n],
            part_of,
            parts: carried,
            pb: vec![Matrix3x2::zeros(); n],
            bb: vec![Matrix2::zeros(); n * n],
            f_acc: Matrix3::identity(),
            since: t,
            fuse_buffers: FuseBuffers::default(),
        }
    }

    fn n(&self) -> usize {
        self.bias.len()
    }

    /// Move by `delta` (body frame; its heading change's sine and cosine
    /// `turn`) and add the process noise `q` (world frame): P = F P F^T + Q
    /// with F the identity but for its heading column (-wy, wx, 1), written
    /// out (a third of the general product). The F's since the last sighting
    /// add up instead of multiplying. Returns F.
    pub fn advance(&mut self, delta: [f64; 3], turn: (f64, f64), q: Matrix3<f64>) -> Matrix3<f64> {
        let (sn, cs) = self.sin_cos;
        let [dx, dy, dth] = delta;
        let (wx, wy) = (cs * dx - sn * dy, sn * dx + cs * dy);
        let (a, c) = (-wy, wx);
        let p = &self.p;
        let (p02, p12, p22) = (p[(0, 2)], p[(1, 2)], p[(2, 2)]);
        let n00 = p[(0, 0)] + 2.0 * a * p02 + a * a * p22;
        let n01 = p[(0, 1)] + a * p12 + c * p02 + a * c * p22;
        let n11 = p[(1, 1)] + 2.0 * c * p12 + c * c * p22;
        let n02 = p02 + a * p22;
        let n12 = p12 + c * p22;
        self.p = Matrix3::new(n00, n01, n02, n01, n11, n12, n02, n12, p22) + q;
        self.f_acc[(0, 2)] += a;
        self.f_acc[(1, 2)] += c;
        self.x += Vector3::new(wx, wy, dth);
        let (sd, cd) = turn;
        self.sin_cos = (sn * cd + cs * sd, cs * cd - sn * sd);
        Matrix3::new(1.0, 0.0, a, 0.0, 1.0, c, 0.0, 0.0, 1.0)
    }

    /// The scale of stored block (i, j).
    fn scale(&self, i: usize, j: usize) -> f64 {
        self.parts[self.part_of[i]].decay * self.parts[self.part_of[j]].decay
    }

    /// Block (i, j) of the errors' covariance.
    fn bb_at(&self, i: usize, j: usize) -> Matrix2<f64> {
        let n = self.n();
        let block = if i <= j {
            self.bb[i * n + j]
        } else {
            self.bb[j * n + i].transpose()
        };
        let stored = block * self.scale(i, j);
        if i == j {
            stored + self.parts[self.part_of[i]].var
        } else {
            stored
        }
    }

    /// Bring the errors and their covariances up to time `t`: each part's
    /// decay by phi = exp(-dt/memory) toward its stationary variance.
    pub fn catch_up(&mut self, t: f64) {
        if self.n() == 0 {
            return;
        }
        let dt = (t - self.since).max(0.0);
        for part in &mut self.parts {
            let phi = (-dt / part.memory_s).exp();
            let slots = part.offset..part.offset + part.len;
            for v in &mut self.bias[slots.clone()] {
                *v *= phi;
            }
            for c in &mut self.pb[slots] {
                *c = self.f_acc * *c * phi;
            }
            part.decay *= phi;
        }
        if self.parts.iter().any(|p| p.decay < FOLD_BELOW) {
            self.fold();
        }
        self.f_acc = Matrix3::identity();
        self.since = t;
    }

    /// Fold the decays into the stored blocks.
    fn fold(&mut self) {
        let n = self.n();
        for i in 0..n {
            for j in i..n {
                let k = self.scale(i, j);
                self.bb[i * n + j] *= k;
            }
        }
        self.parts.iter_mut().for_each(|p| p.decay = 1.0);
    }

    /// The slots of landmark `l`'s errors, sighted at `t` (none without
    /// lingering parts). A slot taken from another landmark starts from the
    /// prior: no error, the stationary variance, no correlation.
    pub fn slots_for(&mut self, l: usize, t: f64) -> Held {
        let mut held = Held::default();
        for k in 0..self.parts.len() {
            let part = &mut self.parts[k];
            let taken = part.slots.as_mut().map_or(Taken::Kept(0), |s| s.take(l, t));
            let s = match taken {
                Taken::Kept(s) | Taken::Fresh(s) => part.offset + s,
                Taken::Evicted(s) => {
                    let s = part.offset + s;
                    self.reset(s);
                    s
                }
            };
            held.slot[held.n] = s;
            held.n += 1;
        }
        held
    }

    /// Slot `s` back to the prior (as of `since`, the time the caller has
    /// caught up to).
    fn reset(&mut self, s: usize) {
        let n = self.n();
        self.bias[s] = Vector2::zeros();
        self.pb[s] = Matrix3x2::zeros();
        for j in 0..n {
            let (a, b) = (s.min(j), s.max(j));
            self.bb[a * n + b] = Matrix2::zeros();
        }
    }

    /// The sum of the errors in `held`, its covariance with the pose, and its
    /// own covariance (zeros without lingering parts).
    pub fn of(&self, held: &Held) -> (Vector2<f64>, Matrix3x2<f64>, Matrix2<f64>) {
        let mut e = (Vector2::zeros(), Matrix3x2::zeros(), Matrix2::zeros());
        for i in held.iter() {
            e.0 += self.bias[i];
            e.1 += self.pb[i];
            for j in held.iter() {
                e.2 += self.bb_at(i, j);
            }
        }
        e
    }

    /// The Kalman update with a sighting whose landmark's errors are in
    /// `held` ([`Belief::slots_for`]): H = [hm | d at each of held],
    /// `ph` the pose rows of P H^T, `sm` = H P H^T + R and its inverse `si`.
    pub fn fuse(
        &mut self,
        held: &Held,
        (hm, d): (&Matrix2x3<f64>, &Matrix2<f64>),
        ph: &Matrix3x2<f64>,
        (sm, si): (&Matrix2<f64>, &Matrix2<f64>),
        y: &Vector2<f64>,
    ) {
        let n = self.n();
        let mut buf = std::mem::take(&mut self.fuse_buffers);
        // the error rows of P H^T: P_bp H_x^T + sum over held of P_b,h d
        buf.eh.clear();
        buf.eh.extend((0..n).map(|j| {
            let mut e = self.pb[j].transpose() * hm.transpose();
            for h in held.iter() {
                e += self.bb_at(j, h) * d;
            }
            e
        }));
        let kp = ph * si;
        buf.kb.clear();
        buf.kb.extend(buf.eh.iter().map(|e| e * si));
        self.x += kp * y;
        self.sin_cos = self.x[2].sin_cos();
        for (b, k) in self.bias.iter_mut().zip(&buf.kb) {
            *b += k * y;
        }
        let ks = kp * sm;
        let p = self.p - ks * kp.transpose();
        self.p = (p + p.transpose()) * 0.5;
        for (c, k) in self.pb.iter_mut().zip(&buf.kb) {
            *c -= ks * k.transpose();
        }
        buf.unscale.clear();
        buf.unscale
            .extend(self.part_of.iter().map(|&k| 1.0 / self.parts[k].decay));
        for (i, (row, ki)) in self.bb.chunks_mut(n.max(1)).zip(&buf.kb).enumerate() {
            let ki = ki * sm * buf.unscale[i];
            for ((b, kj), uj) in row.iter_mut().zip(&buf.kb).zip(&buf.unscale).skip(i) {
                *b -= ki * kj.transpose() * *uj;
            }
        }
        self.fuse_buffers = buf;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::applications::localize::active::ACTIVE;

    fn persistent(var: Vector2<f64>) -> ErrorPart {
        ErrorPart {
            var,
            memory_s: 50.0,
            owner: Owner::Landmark(ACTIVE),
        }
    }

    /// A landmark that takes the slot of one sighted longer ago starts from
    /// the prior: no error, the stationary variance, no correlation with
    /// the pose or with the other landmarks' errors.
    #[test]
    fn a_slot_given_to_another_landmark_starts_from_the_prior() {
        let var = Vector2::new(0.01, 0.0004);
        let mut b = Belief::new(
            Vector3::zeros(),
            Matrix3::identity(),
            ACTIVE + 1,
            &[persistent(var)],
            0.0,
        );
        assert_eq!(b.n(), ACTIVE);
        let first = |h: Held| h.slot[0];
        for l in 0..ACTIVE {
            let s = first(b.slots_for(l, l as f64));
            // what sightings would have left: an error, correlations
            b.bias[s] = Vector2::new(0.3, -0.02);
            b.pb[s] = Matrix3x2::from_element(0.001);
        }
        let n = b.n();
        b.bb.iter_mut()
            .for_each(|m| *m = Matrix2::from_element(-0.002));
        b.catch_up(30.0);
        // landmark 0 was sighted longest ago
        let s = first(b.slots_for(ACTIVE, 30.0));
        assert_eq!(s, first(b.slots_for(ACTIVE, 30.0)));
        assert_eq!(b.bias[s], Vector2::zeros());
        assert_eq!(b.pb[s], Matrix3x2::zeros());
        assert!((b.bb_at(s, s) - Matrix2::from_diagonal(&var)).abs().max() < 1e-15);
        for j in (0..n).filter(|&j| j != s) {
            assert_eq!(b.bb_at(s, j), Matrix2::zeros());
            assert_eq!(b.bb_at(j, s), Matrix2::zeros());
        }
        // the others keep theirs
        let other = first(b.slots_for(1, 31.0));
        assert_ne!(other, s);
        assert_ne!(b.bias[other], Vector2::zeros());
    }

    /// The lazily scaled blocks are the covariance a dense filter carries:
    /// the same sightings fused into a belief with two parts of different
    /// memory, and into the dense state [pose, errors] propagated and
    /// updated in full, agree to rounding (pose, errors and every block).
    #[test]
    fn two_parts_decay_each_at_its_own_rate_as_a_dense_filter_would() {
        let parts = [
            persistent(Vector2::new(0.01, 0.0004)),
            ErrorPart {
                var: Vector2::new(0.02, 0.0009),
                memory_s: 0.7,
                owner: Owner::Sensor,
            },
        ];
        let landmarks = 3;
        let p0 = Matrix3::from_diagonal(&Vector3::new(0.04, 0.03, 0.01));
        let mut b = Belief::new(Vector3::zeros(), p0, landmarks, &parts, 0.0);
        let mut dense = dense::Dense::new(p0, landmarks, &parts);
        let hm = Matrix2x3::new(0.6, -0.8, 0.0, 0.3, 0.4, -1.0);
        let rm = Matrix2::from_diagonal(&Vector2::new(0.003, 0.0001));
        let sightings = [
            (0, 0.1),
            (1, 0.3),
            (0, 0.5),
            (2, 2.0),
            (1, 2.2),
            (0, 9.0),
            (2, 9.1),
        ];
        let mut t_prev = 0.0;
        for (k, &(l, t)) in sightings.iter().enumerate() {
            let q = Matrix3::from_diagonal(&Vector3::new(1e-3, 1e-3, 1e-4)) * (t - t_prev);
            let delta = [0.2 * (t - t_prev), 0.0, 0.1 * (t - t_prev)];
            let before = b.x;
            let f = b.advance(delta, delta[2].sin_cos(), q);
            dense.advance(&f, &q, t - t_prev, b.x - before);
            t_prev = t;
            b.catch_up(t);
            let held = b.slots_for(l, t);
            let d = Matrix2::new(2.0 + l as f64, 0.0, 0.0, 1.0);
            let (_, pbs, bbs) = b.of(&held);
            let ph = b.p * hm.transpose() + pbs * d;
            let sm = hm * ph + d * pbs.transpose() * hm.transpose() + d * bbs * d + rm;
            let si = sm.try_inverse().unwrap();
            let y = Vector2::new(0.05 * (k as f64 - 3.0), 0.01);
            b.fuse(&held, (&hm, &d), &ph, (&sm, &si), &y);
            let cols: Vec<usize> = held.iter().collect();
            dense.fuse(&cols, &hm, &d, &rm, &y);
            dense.agrees_with(&b);
        }
    }

    /// A dense filter over [pose, every slot's error], for the test above.
    mod dense {
        use super::*;
        use nalgebra::{DMatrix, DVector};

        pub struct Dense {
            x: DVector<f64>,
            p: DMatrix<f64>,
            memory: Vec<f64>,
            var: Vec<Matrix2<f64>>,
        }

        impl Dense {
            pub fn new(p0: Matrix3<f64>, landmarks: usize, parts: &[ErrorPart]) -> Dense {
                let mut memory = Vec::new();
                let mut var = Vec::new();
                for e in parts {
                    let len = match e.owner {
                        Owner::Landmark(capacity) => landmarks.min(capacity),
                        Owner::Sensor => 1,
                    };
                    for _ in 0..len {
                        memory.push(e.memory_s);
                        var.push(Matrix2::from_diagonal(&e.var));
                    }
                }
                let m = 3 + 2 * memory.len();
                let mut p = DMatrix::zeros(m, m);
                p.view_mut((0, 0), (3, 3)).copy_from(&p0);
                for (s, v) in var.iter().enumerate() {
                    p.view_mut((3 + 2 * s, 3 + 2 * s), (2, 2)).copy_from(v);
                }
                Dense {
                    x: DVector::zeros(m),
                    p,
                    memory,
                    var,
                }
            }

            pub fn advance(
                &mut self,
                f: &Matrix3<f64>,
                q: &Matrix3<f64>,
                dt: f64,
                moved: Vector3<f64>,
            ) {
                let m = self.x.len();
                let mut fm = DMatrix::identity(m, m);
                fm.view_mut((0, 0), (3, 3)).copy_from(f);
                let mut qm = DMatrix::zeros(m, m);
                qm.view_mut((0, 0), (3, 3)).copy_from(q);
                for (s, (mem, v)) in self.memory.iter().zip(&self.var).enumerate() {
                    let phi = (-dt / mem).exp();
                    fm[(3 + 2 * s, 3 + 2 * s)] = phi;
                    fm[(4 + 2 * s, 4 + 2 * s)] = phi;
                    qm.view_mut((3 + 2 * s, 3 + 2 * s), (2, 2))
                        .copy_from(&(v * (1.0 - phi * phi)));
                }
                // the pose moves; F only carries its error
                let pose = self.x.rows(0, 3).into_owned() + moved;
                self.x = &fm * &self.x;
                self.x.rows_mut(0, 3).copy_from(&pose);
                self.p = &fm * &self.p * fm.transpose() + qm;
            }

            pub fn fuse(
                &mut self,
                cols: &[usize],
                hm: &Matrix2x3<f64>,
                d: &Matrix2<f64>,
                rm: &Matrix2<f64>,
                y: &Vector2<f64>,
            ) {
                let m = self.x.len();
                let mut h = DMatrix::zeros(2, m);
                h.view_mut((0, 0), (2, 3)).copy_from(hm);
                for &s in cols {
                    h.view_mut((0, 3 + 2 * s), (2, 2)).copy_from(d);
                }
                let s =
                    &h * &self.p * h.transpose() + DMatrix::from_column_slice(2, 2, rm.as_slice());
                let k = &self.p * h.transpose() * s.try_inverse().unwrap();
                self.x += &k * DVector::from_column_slice(y.as_slice());
                self.p = &self.p - &k * &h * &self.p;
            }

            pub fn agrees_with(&self, b: &Belief) {
                let close = |a: f64, c: f64, what: &str| {
                    assert!((a - c).abs() < 1e-12, "{what}: {a} vs dense {c}");
                };
                for i in 0..3 {
                    close(b.x[i], self.x[i], "pose");
                    for j in 0..3 {
                        close(b.p[(i, j)], self.p[(i, j)], "P");
                    }
                }
                for s in 0..b.n() {
                    for r in 0..2 {
                        close(b.bias[s][r], self.x[3 + 2 * s + r], "error");
                        for i in 0..3 {
                            close(b.pb[s][(i, r)], self.p[(i, 3 + 2 * s + r)], "pose-error");
                        }
                        for t in 0..b.n() {
                            for c in 0..2 {
                                close(
                                    b.bb_at(s, t)[(r, c)],
                                    self.p[(3 + 2 * s + r, 3 + 2 * t + c)],
                                    "error-error",
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
