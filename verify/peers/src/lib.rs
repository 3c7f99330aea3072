//! The sides of the peer benchmark (`cargo bench -p kinegen-peers`): kinegen's
//! generated kernels in its default `no_std` build and with `std`, and every
//! peer build that pip and cargo install here: CasADi's generated C, wrenfold's
//! generated Rust with std's float methods and with libm (its no_std build),
//! and wrenfold's generated C++.
//!
//! Every side is called the same way, through one function pointer of type
//! [`Kernel`]: the arguments behind an [`Args`] and the outputs written into
//! the caller's buffer. Inside, each side computes its kernel as its users
//! would compile it (kinegen's and wrenfold's Rust inlined into the adapter,
//! the C and C++ adapters with the peer's code in the same translation unit),
//! so the call overhead is one indirect call for every side.
//!
//! The kernels are the [`Row`]s: first the outputs a caller needs together
//! in one call (the peers generate one function for them; kinegen calls its
//! fused kernel), then each kernel alone, as firmware calls it.
use wrenfold_traits::{OutputSpan2D, Span2D};

pub mod inputs;
pub mod ops;

/// A kernel's arguments (the ones it does not take are ignored); the C and
/// C++ adapters read the same layout from `args.h`.
#[repr(C)]
pub struct Args {
    pub x: *const f64,
    pub u: *const f64,
    pub w: *const f64,
    pub p: *const f64,
    pub lm: *const f64,
    pub dt: f64,
}

impl Args {
    /// Reads every input these arguments point to (`lengths`: x, u, w, p,
    /// lm, as [`Model::lengths`] gives them), so that the timed calls find
    /// them in cache, as a filter's kernels find the state it just
    /// computed. Returns their sum, for the caller to `black_box`.
    ///
    /// # Safety
    /// Each pointer must hold at least its length of values.
    pub unsafe fn touch(&self, lengths: [usize; 5]) -> f64 {
        let [x, u, w, p, lm] = lengths;
        let mut sum = self.dt;
        for (ptr, n) in [
            (self.x, x),
            (self.u, u),
            (self.w, w),
            (self.p, p),
            (self.lm, lm),
        ] {
            // SAFETY: the caller's promise
            sum += unsafe { std::slice::from_raw_parts(ptr, n) }
                .iter()
                .sum::<f64>();
        }
        sum
    }
}

impl Model {
    /// How many values a sample holds: x, u, w, p, lm.
    pub const fn lengths(self) -> [usize; 5] {
        match self {
            Model::DiffDrive => [3, 2, 2, 5, 0],
            Model::Unicycle => [3, 2, 0, 1, 2],
            Model::OmniCaster => [3, 9, 3, 12, 0],
        }
    }
}

/// The one calling convention of every side.
pub type Kernel = unsafe extern "C" fn(&Args, *mut f64);

/// The model a row's kernel belongs to.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Model {
    /// diff_drive: x 3, u 2, w 2, p 5
    DiffDrive,
    /// unicycle_ekf: x 3, u 2, p 1, lm 2
    Unicycle,
    /// omni_caster (seed 000): x 3, u 9, w 3, p 12
    OmniCaster,
}

/// One row of the benchmark: a set of outputs computed in one call. The
/// step rows come twice: the peers' kernels accuracy-matched to kinegen's
/// (the same series switch near omega dt = 0), and as the peers' users
/// write them (`...Users`: the chord form, verify/casadi/reference.py's
/// `chord_step`); kinegen computes both with its one kernel.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Row {
    DdStepJacXJacP,
    UcLandmarkJacX,
    OcTwist,
    OcStepJacP,
    DdStep,
    DdJacX,
    DdJacP,
    UcLandmark,
    UcJacX,
    OcStep,
    OcJacP,
    DdStepJacXJacPUsers,
    OcStepJacPUsers,
    DdStepUsers,
    DdJacXUsers,
    DdJacPUsers,
    OcStepUsers,
    OcJacPUsers,
}

impl Row {
    pub const ALL: [Row; 18] = [
        Row::DdStepJacXJacPUsers,
        Row::DdStepJacXJacP,
        Row::UcLandmarkJacX,
        Row::OcTwist,
        Row::OcStepJacPUsers,
        Row::OcStepJacP,
        Row::DdStepUsers,
        Row::DdStep,
        Row::DdJacXUsers,
        Row::DdJacX,
        Row::DdJacPUsers,
        Row::DdJacP,
        Row::UcLandmark,
        Row::UcJacX,
        Row::OcStepUsers,
        Row::OcStep,
        Row::OcJacPUsers,
        Row::OcJacP,
    ];

    /// The row with the same outputs whose peers are accuracy-matched (the
    /// row itself when it is one).
    pub fn matched(self) -> Row {
        match self {
            Row::DdStepJacXJacPUsers => Row::DdStepJacXJacP,
            Row::OcStepJacPUsers => Row::OcStepJacP,
            Row::DdStepUsers => Row::DdStep,
            Row::DdJacXUsers => Row::DdJacX,
            Row::DdJacPUsers => Row::DdJacP,
            Row::OcStepUsers => Row::OcStep,
            Row::OcJacPUsers => Row::OcJacP,
            r => r,
        }
    }

    /// Whether the peers' kernels are the chord form their users write.
    pub fn users(self) -> bool {
        self.matched() != self
    }

    /// The peers' function name (verify/casadi/reference.py's PEER_KERNELS).
    pub fn name(self) -> &'static str {
        match self {
            Row::DdStepJacXJacP => "dd_step",
            Row::UcLandmarkJacX => "uc_landmark",
            Row::OcTwist => "oc_twist",
            Row::OcStepJacP => "oc_step",
            Row::DdStep => "dd_step_exact",
            Row::DdJacX => "dd_step_exact_jac_x",
            Row::DdJacP => "dd_step_exact_jac_p",
            Row::UcLandmark => "uc_obs_landmark",
            Row::UcJacX => "uc_obs_landmark_jac_x",
            Row::OcStep => "oc_step_exact",
            Row::OcJacP => "oc_step_exact_jac_p",
            Row::DdStepJacXJacPUsers => "dd_step_users",
            Row::OcStepJacPUsers => "oc_step_users",
            Row::DdStepUsers => "dd_step_exact_users",
            Row::DdJacXUsers => "dd_step_exact_jac_x_users",
            Row::DdJacPUsers => "dd_step_exact_jac_p_users",
            Row::OcStepUsers => "oc_step_exact_users",
            Row::OcJacPUsers => "oc_step_exact_jac_p_users",
        }
    }

    /// What the row computes.
    pub fn what(self) -> &'static str {
        match self.matched() {
            Row::DdStepJacXJacP => "diff_drive pose + F_x + F_p",
            Row::UcLandmarkJacX => "unicycle_ekf landmark h + H_x",
            Row::OcTwist => "omni_caster twist (least squares)",
            Row::OcStepJacP => "omni_caster pose + F_p",
            Row::DdStep => "diff_drive step_exact",
            Row::DdJacX => "diff_drive step_exact_jac_x",
            Row::DdJacP => "diff_drive step_exact_jac_p",
            Row::UcLandmark => "unicycle_ekf obs_landmark",
            Row::UcJacX => "unicycle_ekf obs_landmark_jac_x",
            Row::OcStep => "omni_caster step_exact",
            _ => "omni_caster step_exact_jac_p",
        }
    }

    /// What the row computes, for the table; a step row says which form its
    /// peers take.
    pub fn label(self) -> String {
        let what = self.what();
        if self.users() {
            format!("{what}, peers as their users write it (chord form)")
        } else if self.steps() {
            format!("{what}, peers accuracy-matched (series switch)")
        } else {
            what.to_string()
        }
    }

    /// Every output in one call (the like-for-like rows) rather than one kernel alone.
    pub fn one_call(self) -> bool {
        matches!(
            self.matched(),
            Row::DdStepJacXJacP | Row::UcLandmarkJacX | Row::OcTwist | Row::OcStepJacP
        )
    }

    pub fn model(self) -> Model {
        match self.matched() {
            Row::DdStepJacXJacP | Row::DdStep | Row::DdJacX | Row::DdJacP => Model::DiffDrive,
            Row::UcLandmarkJacX | Row::UcLandmark | Row::UcJacX => Model::Unicycle,
            _ => Model::OmniCaster,
        }
    }

    /// Whether the row integrates a step, so that its inputs fall on either
    /// side of the series switch at |omega dt| = 0.05.
    pub fn steps(self) -> bool {
        !matches!(
            self.matched(),
            Row::UcLandmarkJacX | Row::UcLandmark | Row::UcJacX | Row::OcTwist
        )
    }

    /// The outputs' shapes (rows, columns), stored one after the other,
    /// row-major, in the output buffer.
    pub fn outputs(self) -> &'static [(usize, usize)] {
        match self.matched() {
            Row::DdStepJacXJacP => &[(3, 1), (3, 3), (3, 5)],
            Row::UcLandmarkJacX => &[(2, 1), (2, 3)],
            Row::OcTwist | Row::DdStep | Row::OcStep => &[(3, 1)],
            Row::OcStepJacP => &[(3, 1), (3, 12)],
            Row::DdJacX => &[(3, 3)],
            Row::DdJacP => &[(3, 5)],
            Row::UcLandmark => &[(2, 1)],
            Row::UcJacX => &[(2, 3)],
            _ => &[(3, 12)],
        }
    }

    /// Whether a step of `turn` = omega dt is where the row's peers must
    /// agree with kinegen to 1e-9: everywhere for the accuracy-matched rows;
    /// for the users' chord form only where it is well conditioned (|omega
    /// dt| > 0.05; nearer zero its differences of sines cancel, which the
    /// benchmark reports as its error against a 50-digit reference).
    pub fn agrees_at(self, turn: f64) -> bool {
        !self.users() || turn.abs() > 0.05
    }

    /// Entries in the output buffer.
    pub fn entries(self) -> usize {
        self.outputs().iter().map(|(r, c)| r * c).sum()
    }
}

/// How a side lays out its outputs in the buffer.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Layout {
    /// each output dense and row-major, one after the other
    RowMajor,
    /// each output dense and column-major (Eigen's and nalgebra's layout)
    ColMajor,
    /// CasADi's: each output's structural non-zeros, column-major
    CasadiSparse,
}

/// One build of one tool.
pub struct Side {
    pub name: &'static str,
    /// kinegen (the side being measured) or a peer
    pub kinegen: bool,
    pub layout: Layout,
    pub kernel: fn(Row) -> Option<Kernel>,
}

/// Every side this build has (wrenfold C++ only where its headers were found
/// at build time: see build.rs).
pub fn sides() -> Vec<Side> {
    // mutated only where a C++ peer was built (cfg below)
    #[allow(unused_mut)]
    let mut all = vec![
        Side {
            name: "kinegen no_std",
            kinegen: true,
            layout: Layout::RowMajor,
            kernel: kinegen_no_std::kernel,
        },
        Side {
            name: "kinegen std",
            kinegen: true,
            layout: Layout::RowMajor,
            kernel: kinegen_std::kernel,
        },
        Side {
            name: "CasADi C",
            kinegen: false,
            layout: Layout::CasadiSparse,
            kernel: casadi::kernel,
        },
        Side {
            name: "wrenfold Rust",
            kinegen: false,
            layout: Layout::RowMajor,
            kernel: wrenfold_std::kernel,
        },
        Side {
            name: "wrenfold Rust libm",
            kinegen: false,
            layout: Layout::RowMajor,
            kernel: wrenfold_libm::kernel,
        },
    ];
    #[cfg(wrenfold_cpp)]
    all.push(Side {
        name: "wrenfold C++",
        kinegen: false,
        layout: Layout::RowMajor,
        kernel: wrenfold_cpp::kernel,
    });
    #[cfg(symforce_cpp)]
    all.push(Side {
        name: "SymForce C++",
        kinegen: false,
        layout: Layout::ColMajor,
        kernel: symforce_cpp::kernel,
    });
    all
}

/// Whether the wrenfold C++ peer was built (its headers found).
pub const WRENFOLD_CPP: bool = cfg!(wrenfold_cpp);
/// Whether the SymForce C++ peer was built (Eigen's headers found).
pub const SYMFORCE_CPP: bool = cfg!(symforce_cpp);

/// A side's output buffer as the row's outputs, dense and row-major.
pub fn dense(row: Row, layout: Layout, out: &[f64]) -> Vec<f64> {
    match layout {
        Layout::RowMajor => out[..row.entries()].to_vec(),
        Layout::CasadiSparse => casadi::dense(row, out),
        Layout::ColMajor => {
            let mut at = 0;
            let mut d = Vec::with_capacity(row.entries());
            for &(r, c) in row.outputs() {
                d.extend((0..r * c).map(|k| out[at + (k % c) * r + k / c]));
                at += r * c;
            }
            d
        }
    }
}

/// Largest difference between two sides' outputs over `args`, relative to
/// each output's largest magnitude (infinite where either is not finite).
pub fn disagreement(row: Row, a: (Kernel, Layout), b: (Kernel, Layout), args: &[Args]) -> f64 {
    let (mut oa, mut ob) = (vec![0.0; 64], vec![0.0; 64]);
    let mut worst = 0.0f64;
    for call in args {
        // SAFETY: the arguments point into live samples of the row's model
        // and the buffers hold more than any row's outputs
        unsafe {
            a.0(call, oa.as_mut_ptr());
            b.0(call, ob.as_mut_ptr());
        }
        let (da, db) = (dense(row, a.1, &oa), dense(row, b.1, &ob));
        let mut at = 0;
        for (r, c) in row.outputs() {
            let (xa, xb) = (&da[at..at + r * c], &db[at..at + r * c]);
            at += r * c;
            let scale = xa.iter().chain(xb).fold(1e-300f64, |m, v| m.max(v.abs()));
            for (p, q) in xa.iter().zip(xb) {
                let e = if p.is_finite() && q.is_finite() {
                    (p - q).abs() / scale
                } else {
                    f64::INFINITY
                };
                worst = worst.max(e);
            }
        }
    }
    worst
}

/// `n` values at `p` as an array reference.
///
/// # Safety
/// `p` points at `N` readable f64 that outlive the call.
#[inline(always)]
unsafe fn arr<'a, const N: usize>(p: *const f64) -> &'a [f64; N] {
    &*(p as *const [f64; N])
}

/// Write an output array (any shape of f64 arrays) at `o`.
///
/// # Safety
/// `o` points at `size_of::<T>() / 8` writable f64.
#[inline(always)]
unsafe fn put<T: Copy>(o: *mut f64, v: T) {
    o.cast::<T>().write_unaligned(v)
}

/// `kernel(row)` for a side whose adapters have the names below (kinegen's
/// and wrenfold's Rust sides), with the users' rows' own adapters where the
/// side has them (wrenfold's; kinegen computes every row with its one
/// kernel: see [`Row::matched`]).
macro_rules! kernels_by_row {
    ($( $users_row:pat => $users_fn:ident ),* $(,)?) => {
        pub fn kernel(row: Row) -> Option<Kernel> {
            Some(match row {
                $( $users_row => $users_fn, )*
                Row::DdStepJacXJacP => dd_all,
                Row::UcLandmarkJacX => uc_all,
                Row::OcTwist => oc_twist,
                Row::OcStepJacP => oc_all,
                Row::DdStep => dd_step,
                Row::DdJacX => dd_jac_x,
                Row::DdJacP => dd_jac_p,
                Row::UcLandmark => uc_obs,
                Row::UcJacX => uc_jac_x,
                Row::OcStep => oc_step,
                Row::OcJacP => oc_jac_p,
                #[allow(unreachable_patterns)]
                other => return kernel(other.matched()),
            })
        }
    };
}

/// kinegen's adapters over one build of the generated crate.
macro_rules! kinegen_side {
    ($side:ident, $krate:ident) => {
        mod $side {
            use super::{arr, put, Args, Kernel, Row};
            use $krate::{diff_drive as dd, omni_caster as oc, unicycle_ekf as uc};

            macro_rules! step {
                ($m:ident, $a:ident, $f:ident) => {
                    $m::$f(arr($a.x), arr($a.u), arr($a.w), arr($a.p), $a.dt)
                };
            }
            macro_rules! obs {
                ($a:ident, $f:ident) => {
                    uc::$f(arr($a.x), arr($a.u), arr($a.p), arr($a.lm))
                };
            }
            unsafe extern "C" fn dd_all(a: &Args, o: *mut f64) {
                let (s, fx, fp) = step!(dd, a, step_exact_with_jac_p);
                put(o, s);
                put(o.add(3), fx);
                put(o.add(12), fp);
            }
            unsafe extern "C" fn uc_all(a: &Args, o: *mut f64) {
                // the fused kernel's H_p, not among the row's outputs, is
                // left unwritten (the optimiser drops what nobody reads)
                let (h, hx, _) = obs!(a, obs_landmark_linearized);
                put(o, h);
                put(o.add(2), hx);
            }
            unsafe extern "C" fn oc_twist(a: &Args, o: *mut f64) {
                put(o, oc::twist(arr(a.u), arr(a.p)));
            }
            unsafe extern "C" fn oc_all(a: &Args, o: *mut f64) {
                let (s, _, fp) = step!(oc, a, step_exact_with_jac_p);
                put(o, s);
                put(o.add(3), fp);
            }
            unsafe extern "C" fn dd_step(a: &Args, o: *mut f64) {
                put(o, step!(dd, a, step_exact));
            }
            unsafe extern "C" fn dd_jac_x(a: &Args, o: *mut f64) {
                put(o, step!(dd, a, step_exact_jac_x));
            }
            unsafe extern "C" fn dd_jac_p(a: &Args, o: *mut f64) {
                put(o, step!(dd, a, step_exact_jac_p));
            }
            unsafe extern "C" fn uc_obs(a: &Args, o: *mut f64) {
                put(o, obs!(a, obs_landmark));
            }
            unsafe extern "C" fn uc_jac_x(a: &Args, o: *mut f64) {
                put(o, obs!(a, obs_landmark_jac_x));
            }
            unsafe extern "C" fn oc_step(a: &Args, o: *mut f64) {
                put(o, step!(oc, a, step_exact));
            }
            unsafe extern "C" fn oc_jac_p(a: &Args, o: *mut f64) {
                put(o, step!(oc, a, step_exact_jac_p));
            }

            kernels_by_row!();
        }
    };
}

kinegen_side!(kinegen_no_std, kinegen_generated);
kinegen_side!(kinegen_std, kinegen_generated_std);

/// An input vector of wrenfold's Rust kernels.
pub struct In<const N: usize>(*const f64);

impl<const N: usize> Span2D<N, 1> for In<N> {
    type ValueType = f64;
    #[inline(always)]
    fn get(&self, i: usize, _j: usize) -> f64 {
        // SAFETY: the benchmark's arrays hold N values for this argument
        unsafe { *self.0.add(i) }
    }
}

/// An output matrix of wrenfold's Rust kernels, written row-major into the
/// caller's buffer.
pub struct Out<const R: usize, const C: usize>(*mut f64);

impl<const R: usize, const C: usize> OutputSpan2D<R, C> for Out<R, C> {
    type ValueType = f64;
    #[inline(always)]
    fn set(&mut self, i: usize, j: usize, val: f64) {
        // SAFETY: the buffer holds the row's outputs (Row::entries)
        unsafe { *self.0.add(i * C + j) = val }
    }
}

/// wrenfold's Rust kernels (std's float methods, and libm's), kept as
/// wrenfold wrote them (`wrenfold_kernels.py --check` compares).
#[rustfmt::skip]
#[path = "../wrenfold/kernels.rs"]
pub mod wrenfold;
#[rustfmt::skip]
#[path = "../wrenfold/kernels_libm.rs"]
pub mod wrenfold_no_std;

/// A wrenfold step kernel on the arguments behind `a`.
macro_rules! wf_step {
    ($wf:ident, $a:ident, $nu:literal, $nw:literal, $np:literal, $f:ident, $($out:expr),+) => {
        $wf::$f(&In::<3>($a.x), &In::<$nu>($a.u), &In::<$nw>($a.w),
                &In::<$np>($a.p), $a.dt, $($out),+)
    };
}

/// A wrenfold observation kernel on the arguments behind `a`.
macro_rules! wf_obs {
    ($wf:ident, $a:ident, $f:ident, $($out:expr),+) => {
        $wf::$f(&In::<3>($a.x), &In::<2>($a.u), &In::<1>($a.p), &In::<2>($a.lm), $($out),+)
    };
}

macro_rules! wrenfold_side {
    ($side:ident, $m:ident) => {
        mod $side {
            use super::{$m as wf, Args, In, Kernel, Out, Row};

            unsafe extern "C" fn dd_all(a: &Args, o: *mut f64) {
                wf_step!(
                    wf,
                    a,
                    2,
                    2,
                    5,
                    dd_step,
                    &mut Out::<3, 1>(o),
                    &mut Out::<3, 3>(o.add(3)),
                    &mut Out::<3, 5>(o.add(12))
                );
            }
            unsafe extern "C" fn uc_all(a: &Args, o: *mut f64) {
                wf_obs!(
                    wf,
                    a,
                    uc_landmark,
                    &mut Out::<2, 1>(o),
                    &mut Out::<2, 3>(o.add(2))
                );
            }
            unsafe extern "C" fn oc_twist(a: &Args, o: *mut f64) {
                wf::oc_twist(&In::<9>(a.u), &In::<12>(a.p), &mut Out::<3, 1>(o));
            }
            unsafe extern "C" fn oc_all(a: &Args, o: *mut f64) {
                wf_step!(
                    wf,
                    a,
                    9,
                    3,
                    12,
                    oc_step,
                    &mut Out::<3, 1>(o),
                    &mut Out::<3, 12>(o.add(3))
                );
            }
            unsafe extern "C" fn dd_step(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact, &mut Out::<3, 1>(o));
            }
            unsafe extern "C" fn dd_jac_x(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact_jac_x, &mut Out::<3, 3>(o));
            }
            unsafe extern "C" fn dd_jac_p(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact_jac_p, &mut Out::<3, 5>(o));
            }
            unsafe extern "C" fn uc_obs(a: &Args, o: *mut f64) {
                wf_obs!(wf, a, uc_obs_landmark, &mut Out::<2, 1>(o));
            }
            unsafe extern "C" fn uc_jac_x(a: &Args, o: *mut f64) {
                wf_obs!(wf, a, uc_obs_landmark_jac_x, &mut Out::<2, 3>(o));
            }
            unsafe extern "C" fn oc_step(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 9, 3, 12, oc_step_exact, &mut Out::<3, 1>(o));
            }
            unsafe extern "C" fn oc_jac_p(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 9, 3, 12, oc_step_exact_jac_p, &mut Out::<3, 12>(o));
            }
            unsafe extern "C" fn dd_all_users(a: &Args, o: *mut f64) {
                wf_step!(
                    wf,
                    a,
                    2,
                    2,
                    5,
                    dd_step_users,
                    &mut Out::<3, 1>(o),
                    &mut Out::<3, 3>(o.add(3)),
                    &mut Out::<3, 5>(o.add(12))
                );
            }
            unsafe extern "C" fn oc_all_users(a: &Args, o: *mut f64) {
                wf_step!(
                    wf,
                    a,
                    9,
                    3,
                    12,
                    oc_step_users,
                    &mut Out::<3, 1>(o),
                    &mut Out::<3, 12>(o.add(3))
                );
            }
            unsafe extern "C" fn dd_step_users(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact_users, &mut Out::<3, 1>(o));
            }
            unsafe extern "C" fn dd_jac_x_users(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact_jac_x_users, &mut Out::<3, 3>(o));
            }
            unsafe extern "C" fn dd_jac_p_users(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 2, 2, 5, dd_step_exact_jac_p_users, &mut Out::<3, 5>(o));
            }
            unsafe extern "C" fn oc_step_users(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 9, 3, 12, oc_step_exact_users, &mut Out::<3, 1>(o));
            }
            unsafe extern "C" fn oc_jac_p_users(a: &Args, o: *mut f64) {
                wf_step!(wf, a, 9, 3, 12, oc_step_exact_jac_p_users, &mut Out::<3, 12>(o));
            }

            kernels_by_row!(
                Row::DdStepJacXJacPUsers => dd_all_users,
                Row::OcStepJacPUsers => oc_all_users,
                Row::DdStepUsers => dd_step_users,
                Row::DdJacXUsers => dd_jac_x_users,
                Row::DdJacPUsers => dd_jac_p_users,
                Row::OcStepUsers => oc_step_users,
                Row::OcJacPUsers => oc_jac_p_users,
            );
        }
    };
}

wrenfold_side!(wrenfold_std, wrenfold);
wrenfold_side!(wrenfold_libm, wrenfold_no_std);

/// The C and C++ adapters (casadi/adapters.c, wrenfold/adapters.cpp) by
/// row, from one list of names.
macro_rules! foreign_side {
    ($side:ident, $($cfg:meta)?, $( $row:ident => $sym:ident ),+ $(,)?) => {
        $(#[$cfg])?
        mod $side {
            use super::{Args, Kernel, Row};
            extern "C" {
                $( fn $sym(a: &Args, out: *mut f64); )+
            }
            pub fn kernel(row: Row) -> Option<Kernel> {
                match row {
                    $( Row::$row => Some($sym as Kernel), )+
                }
            }
        }
    };
}

foreign_side!(wrenfold_cpp, cfg(wrenfold_cpp),
    DdStepJacXJacP => wrenfold_cpp_dd_step,
    UcLandmarkJacX => wrenfold_cpp_uc_landmark,
    OcTwist => wrenfold_cpp_oc_twist,
    OcStepJacP => wrenfold_cpp_oc_step,
    DdStep => wrenfold_cpp_dd_step_exact,
    DdJacX => wrenfold_cpp_dd_step_exact_jac_x,
    DdJacP => wrenfold_cpp_dd_step_exact_jac_p,
    UcLandmark => wrenfold_cpp_uc_obs_landmark,
    UcJacX => wrenfold_cpp_uc_obs_landmark_jac_x,
    OcStep => wrenfold_cpp_oc_step_exact,
    OcJacP => wrenfold_cpp_oc_step_exact_jac_p,
    DdStepJacXJacPUsers => wrenfold_cpp_dd_step_users,
    OcStepJacPUsers => wrenfold_cpp_oc_step_users,
    DdStepUsers => wrenfold_cpp_dd_step_exact_users,
    DdJacXUsers => wrenfold_cpp_dd_step_exact_jac_x_users,
    DdJacPUsers => wrenfold_cpp_dd_step_exact_jac_p_users,
    OcStepUsers => wrenfold_cpp_oc_step_exact_users,
    OcJacPUsers => wrenfold_cpp_oc_step_exact_jac_p_users,
);

foreign_side!(symforce_cpp, cfg(symforce_cpp),
    DdStepJacXJacP => symforce_cpp_dd_step,
    UcLandmarkJacX => symforce_cpp_uc_landmark,
    OcTwist => symforce_cpp_oc_twist,
    OcStepJacP => symforce_cpp_oc_step,
    DdStep => symforce_cpp_dd_step_exact,
    DdJacX => symforce_cpp_dd_step_exact_jac_x,
    DdJacP => symforce_cpp_dd_step_exact_jac_p,
    UcLandmark => symforce_cpp_uc_obs_landmark,
    UcJacX => symforce_cpp_uc_obs_landmark_jac_x,
    OcStep => symforce_cpp_oc_step_exact,
    OcJacP => symforce_cpp_oc_step_exact_jac_p,
    DdStepJacXJacPUsers => symforce_cpp_dd_step_users,
    OcStepJacPUsers => symforce_cpp_oc_step_users,
    DdStepUsers => symforce_cpp_dd_step_exact_users,
    DdJacXUsers => symforce_cpp_dd_step_exact_jac_x_users,
    DdJacPUsers => symforce_cpp_dd_step_exact_jac_p_users,
    OcStepUsers => symforce_cpp_oc_step_exact_users,
    OcJacPUsers => symforce_cpp_oc_step_exact_jac_p_users,
);

/// CasADi's adapters, and its sparse output layout.
mod casadi {
    use super::{Args, Kernel, Row};
    use std::os::raw::c_int;
    type CasadiInt = i64;

    macro_rules! casadi_rows {
        ($( $row:ident: $adapter:ident, $init:ident, $sparsity:ident, $n_out:ident; )+) => {
            extern "C" {
                $(
                    fn $adapter(a: &Args, out: *mut f64);
                    fn $init() -> c_int;
                    fn $sparsity(i: CasadiInt) -> *const CasadiInt;
                    fn $n_out() -> CasadiInt;
                )+
            }
            pub fn kernel(row: Row) -> Option<Kernel> {
                // SAFETY: the init functions only read CasADi's static tables
                // and set the adapter's output offsets
                match row {
                    $( Row::$row => (unsafe { $init() } > 0).then_some($adapter as Kernel), )+
                }
            }
            /// (rows, cols, column starts, row indices) of each output
            fn sparsity(row: Row) -> Vec<(usize, usize, Vec<usize>, Vec<usize>)> {
                // SAFETY: CasADi's query functions return static tables
                match row {
                    $( Row::$row => (0..unsafe { $n_out() }).map(|i| unsafe { compact($sparsity(i)) }).collect(), )+
                }
            }
        };
    }

    casadi_rows! {
        DdStepJacXJacP: casadi_adapter_dd_step, casadi_adapter_init_dd_step, dd_step_sparsity_out, dd_step_n_out;
        UcLandmarkJacX: casadi_adapter_uc_landmark, casadi_adapter_init_uc_landmark, uc_landmark_sparsity_out, uc_landmark_n_out;
        OcTwist: casadi_adapter_oc_twist, casadi_adapter_init_oc_twist, oc_twist_sparsity_out, oc_twist_n_out;
        OcStepJacP: casadi_adapter_oc_step, casadi_adapter_init_oc_step, oc_step_sparsity_out, oc_step_n_out;
        DdStep: casadi_adapter_dd_step_exact, casadi_adapter_init_dd_step_exact, dd_step_exact_sparsity_out, dd_step_exact_n_out;
        DdJacX: casadi_adapter_dd_step_exact_jac_x, casadi_adapter_init_dd_step_exact_jac_x, dd_step_exact_jac_x_sparsity_out, dd_step_exact_jac_x_n_out;
        DdJacP: casadi_adapter_dd_step_exact_jac_p, casadi_adapter_init_dd_step_exact_jac_p, dd_step_exact_jac_p_sparsity_out, dd_step_exact_jac_p_n_out;
        UcLandmark: casadi_adapter_uc_obs_landmark, casadi_adapter_init_uc_obs_landmark, uc_obs_landmark_sparsity_out, uc_obs_landmark_n_out;
        UcJacX: casadi_adapter_uc_obs_landmark_jac_x, casadi_adapter_init_uc_obs_landmark_jac_x, uc_obs_landmark_jac_x_sparsity_out, uc_obs_landmark_jac_x_n_out;
        OcStep: casadi_adapter_oc_step_exact, casadi_adapter_init_oc_step_exact, oc_step_exact_sparsity_out, oc_step_exact_n_out;
        OcJacP: casadi_adapter_oc_step_exact_jac_p, casadi_adapter_init_oc_step_exact_jac_p, oc_step_exact_jac_p_sparsity_out, oc_step_exact_jac_p_n_out;
        DdStepJacXJacPUsers: casadi_adapter_dd_step_users, casadi_adapter_init_dd_step_users, dd_step_users_sparsity_out, dd_step_users_n_out;
        OcStepJacPUsers: casadi_adapter_oc_step_users, casadi_adapter_init_oc_step_users, oc_step_users_sparsity_out, oc_step_users_n_out;
        DdStepUsers: casadi_adapter_dd_step_exact_users, casadi_adapter_init_dd_step_exact_users, dd_step_exact_users_sparsity_out, dd_step_exact_users_n_out;
        DdJacXUsers: casadi_adapter_dd_step_exact_jac_x_users, casadi_adapter_init_dd_step_exact_jac_x_users, dd_step_exact_jac_x_users_sparsity_out, dd_step_exact_jac_x_users_n_out;
        DdJacPUsers: casadi_adapter_dd_step_exact_jac_p_users, casadi_adapter_init_dd_step_exact_jac_p_users, dd_step_exact_jac_p_users_sparsity_out, dd_step_exact_jac_p_users_n_out;
        OcStepUsers: casadi_adapter_oc_step_exact_users, casadi_adapter_init_oc_step_exact_users, oc_step_exact_users_sparsity_out, oc_step_exact_users_n_out;
        OcJacPUsers: casadi_adapter_oc_step_exact_jac_p_users, casadi_adapter_init_oc_step_exact_jac_p_users, oc_step_exact_jac_p_users_sparsity_out, oc_step_exact_jac_p_users_n_out;
    }

    /// CasADi's compact sparsity: [rows, cols, 1] for a dense matrix, else
    /// [rows, cols, column starts (cols + 1)..., row indices...].
    ///
    /// # Safety
    /// `p` is a table from a CasADi `*_sparsity_out` function.
    unsafe fn compact(p: *const CasadiInt) -> (usize, usize, Vec<usize>, Vec<usize>) {
        let (rows, cols) = (*p as usize, *p.add(1) as usize);
        if *p.add(2) == 1 {
            let colind = (0..=cols).map(|c| c * rows).collect();
            let row = (0..rows * cols).map(|k| k % rows).collect();
            return (rows, cols, colind, row);
        }
        let colind: Vec<usize> = (0..=cols).map(|k| *p.add(2 + k) as usize).collect();
        let nnz = colind[cols];
        let row = (0..nnz).map(|k| *p.add(3 + cols + k) as usize).collect();
        (rows, cols, colind, row)
    }

    /// CasADi's outputs (non-zeros, column-major, one after the other) as
    /// the row's dense row-major outputs.
    pub fn dense(row: Row, out: &[f64]) -> Vec<f64> {
        let mut d = Vec::with_capacity(row.entries());
        let mut at = 0;
        for (rows, cols, colind, ri) in sparsity(row) {
            let mut m = vec![0.0; rows * cols];
            for c in 0..cols {
                for k in colind[c]..colind[c + 1] {
                    m[ri[k] * cols + c] = out[at + k];
                }
            }
            at += colind[cols];
            d.extend(m);
        }
        d
    }
}
