//! The peers of the benchmark. CasADi's generated C functions behind a safe
//! call: inputs as slices, outputs as dense row-major matrices (CasADi writes
//! only the structural non-zeros, column-major; [`CasadiKernel::dense`]
//! scatters them). wrenfold's generated Rust ([`wrenfold`], written by
//! `verify/peers/wrenfold_kernels.py`) reads and writes through its span
//! traits, implemented here for arrays ([`Col`], [`Out`]).
use std::os::raw::c_int;

type CasadiInt = i64;
type Eval = unsafe extern "C" fn(
    arg: *const *const f64,
    res: *const *mut f64,
    iw: *mut CasadiInt,
    w: *mut f64,
    mem: c_int,
) -> c_int;
type Work =
    unsafe extern "C" fn(*mut CasadiInt, *mut CasadiInt, *mut CasadiInt, *mut CasadiInt) -> c_int;
type Sparsity = unsafe extern "C" fn(CasadiInt) -> *const CasadiInt;
type Count = unsafe extern "C" fn() -> CasadiInt;

macro_rules! casadi_fn {
    ($($name:ident, $work:ident, $sp:ident, $nout:ident;)*) => {
        extern "C" {
            $(
                fn $name(arg: *const *const f64, res: *const *mut f64, iw: *mut CasadiInt, w: *mut f64, mem: c_int) -> c_int;
                fn $work(a: *mut CasadiInt, r: *mut CasadiInt, iw: *mut CasadiInt, w: *mut CasadiInt) -> c_int;
                fn $sp(i: CasadiInt) -> *const CasadiInt;
                fn $nout() -> CasadiInt;
            )*
        }
    };
}

casadi_fn! {
    dd_step, dd_step_work, dd_step_sparsity_out, dd_step_n_out;
    uc_landmark, uc_landmark_work, uc_landmark_sparsity_out, uc_landmark_n_out;
    oc_twist, oc_twist_work, oc_twist_sparsity_out, oc_twist_n_out;
    oc_step, oc_step_work, oc_step_sparsity_out, oc_step_n_out;
}

/// One CasADi function with its work arrays and output buffers.
pub struct CasadiKernel {
    eval: Eval,
    iw: Vec<CasadiInt>,
    w: Vec<f64>,
    /// (rows, cols, column starts, row indices) per output
    sparsity: Vec<(usize, usize, Vec<usize>, Vec<usize>)>,
    /// non-zeros per output, as CasADi writes them
    pub out: Vec<Vec<f64>>,
    /// pointers into `out` (its buffers never move), built once so that a call
    /// does not allocate
    res: Vec<*mut f64>,
}

impl CasadiKernel {
    fn new(eval: Eval, work: Work, sparsity: Sparsity, n_out: Count) -> CasadiKernel {
        // SAFETY: the CasADi-generated query functions only read static tables
        // and write the four sizes.
        unsafe {
            let (mut a, mut r, mut iw, mut w) = (0, 0, 0, 0);
            work(&mut a, &mut r, &mut iw, &mut w);
            let sparsity: Vec<_> = (0..n_out())
                .map(|i| {
                    let p = sparsity(i);
                    let (rows, cols) = (*p as usize, *p.add(1) as usize);
                    // CasADi's compact form: [rows, cols, 1] for a dense matrix,
                    // else [rows, cols, column starts (from 0)..., row indices...]
                    if *p.add(2) == 1 {
                        let colind = (0..=cols).map(|c| c * rows).collect();
                        let row = (0..rows * cols).map(|k| k % rows).collect();
                        return (rows, cols, colind, row);
                    }
                    let colind: Vec<usize> = (0..=cols).map(|k| *p.add(2 + k) as usize).collect();
                    let nnz = colind[cols];
                    let row = (0..nnz).map(|k| *p.add(3 + cols + k) as usize).collect();
                    (rows, cols, colind, row)
                })
                .collect();
            let mut out: Vec<Vec<f64>> = sparsity.iter().map(|s| vec![0.0; s.2[s.1]]).collect();
            let res = out.iter_mut().map(|o| o.as_mut_ptr()).collect();
            CasadiKernel {
                eval,
                iw: vec![0; iw as usize],
                w: vec![0.0; w as usize],
                sparsity,
                out,
                res,
            }
        }
    }

    /// Evaluate on `args` (one slice per CasADi input, in its order).
    #[inline]
    pub fn call(&mut self, args: &[*const f64]) {
        // SAFETY: args point at vectors of the sizes the function was generated
        // for (checked by the benchmark's agreement test); res at buffers of each
        // output's non-zero count; iw and w at the sizes it asked for.
        unsafe {
            (self.eval)(
                args.as_ptr(),
                self.res.as_ptr(),
                self.iw.as_mut_ptr(),
                self.w.as_mut_ptr(),
                0,
            );
        }
    }

    /// Output `i` as a dense row-major matrix (rows x cols).
    pub fn dense(&self, i: usize) -> Vec<f64> {
        let (rows, cols, colind, row) = &self.sparsity[i];
        let mut d = vec![0.0; rows * cols];
        for c in 0..*cols {
            for k in colind[c]..colind[c + 1] {
                d[row[k] * cols + c] = self.out[i][k];
            }
        }
        d
    }
}

/// diff_drive: (x, u, w, p, dt) -> step_exact, step_exact_jac_x, step_exact_jac_p
pub fn diff_drive_step() -> CasadiKernel {
    CasadiKernel::new(dd_step, dd_step_work, dd_step_sparsity_out, dd_step_n_out)
}
/// unicycle_ekf: (x, u, p, lm) -> obs_landmark, obs_landmark_jac_x
pub fn unicycle_landmark() -> CasadiKernel {
    CasadiKernel::new(
        uc_landmark,
        uc_landmark_work,
        uc_landmark_sparsity_out,
        uc_landmark_n_out,
    )
}
/// omni_caster: (u, p) -> twist
pub fn omni_caster_twist() -> CasadiKernel {
    CasadiKernel::new(
        oc_twist,
        oc_twist_work,
        oc_twist_sparsity_out,
        oc_twist_n_out,
    )
}
/// omni_caster: (x, u, w, p, dt) -> step_exact, step_exact_jac_p
pub fn omni_caster_step() -> CasadiKernel {
    CasadiKernel::new(oc_step, oc_step_work, oc_step_sparsity_out, oc_step_n_out)
}

/// wrenfold's generated kernels (same names and argument order as CasADi's),
/// kept as wrenfold wrote them (`wrenfold_kernels.py --check` compares).
#[rustfmt::skip]
#[path = "../wrenfold/kernels.rs"]
pub mod wrenfold;

/// An input column for wrenfold's kernels.
pub struct Col<'a, const N: usize>(pub &'a [f64; N]);

impl<const N: usize> wrenfold_traits::Span2D<N, 1> for Col<'_, N> {
    type ValueType = f64;
    #[inline(always)]
    fn get(&self, i: usize, _j: usize) -> f64 {
        self.0[i]
    }
}

/// An output matrix of wrenfold's kernels, row-major.
pub struct Out<const R: usize, const C: usize>(pub [[f64; C]; R]);

impl<const R: usize, const C: usize> Default for Out<R, C> {
    fn default() -> Self {
        Out([[0.0; C]; R])
    }
}

impl<const R: usize, const C: usize> Out<R, C> {
    /// The entries, row after row.
    pub fn flat(&self) -> Vec<f64> {
        self.0.concat()
    }
}

impl<const R: usize, const C: usize> wrenfold_traits::OutputSpan2D<R, C> for Out<R, C> {
    type ValueType = f64;
    #[inline(always)]
    fn set(&mut self, i: usize, j: usize, val: f64) {
        self.0[i][j] = val;
    }
}
