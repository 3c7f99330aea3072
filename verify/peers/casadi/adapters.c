/* Every CasADi peer kernel behind the benchmark's one calling convention,
 * `void f(const Args *, double *out)`, the same for every side. The adapters
 * include CasADi's generated C so the compiler may inline it into them, as a
 * C caller's code would; CasADi's own convention (argument and result pointer
 * arrays, work arrays) stays, being part of what its generated code costs.
 * Results are written where CasADi writes them: each output's structural
 * non-zeros, column-major, at `out + offset` (offsets set by
 * casadi_adapters_init from CasADi's sparsity queries). */
#include "casadi_kernels.c"
#include "../args.h"

static casadi_int iw_buf[256];
static double w_buf[16384];

#define DECLARE(fn) static casadi_int fn##_off[3];
#define STEP_ARGS(a) {a->x, a->u, a->w, a->p, &a->dt, 0, 0, 0}
#define OBS_ARGS(a) {a->x, a->u, a->p, a->lm, 0, 0, 0, 0}
#define TWIST_ARGS(a) {a->u, a->p, 0, 0, 0, 0, 0, 0}
#define ADAPTER(fn, ARGS)                                                    \
  DECLARE(fn)                                                                \
  void casadi_adapter_##fn(const Args *a, double *out) {                     \
    const double *arg[8] = ARGS(a);                                          \
    double *res[8] = {out + fn##_off[0], out + fn##_off[1], out + fn##_off[2], \
                      0, 0, 0, 0, 0};                                        \
    fn(arg, res, iw_buf, w_buf, 0);                                          \
  }                                                                          \
  /* offsets of the outputs in `out`; 0 if CasADi asks for more work space,  \
     pointer slots or outputs than the adapters have */                     \
  int casadi_adapter_init_##fn(void) {                                       \
    casadi_int sz_arg, sz_res, sz_iw, sz_w, off = 0;                         \
    fn##_work(&sz_arg, &sz_res, &sz_iw, &sz_w);                              \
    if (sz_arg > 8 || sz_res > 8 || sz_iw > 256 || sz_w > 16384 ||           \
        fn##_n_out() > 3)                                                    \
      return 0;                                                              \
    for (casadi_int k = 0; k < fn##_n_out(); k++) {                          \
      const casadi_int *sp = fn##_sparsity_out(k);                           \
      fn##_off[k] = off;                                                     \
      off += sp[2] == 1 ? sp[0] * sp[1] : sp[2 + sp[1]];                     \
    }                                                                        \
    return (int)off;                                                         \
  }

ADAPTER(dd_step, STEP_ARGS)
ADAPTER(uc_landmark, OBS_ARGS)
ADAPTER(oc_twist, TWIST_ARGS)
ADAPTER(oc_step, STEP_ARGS)
ADAPTER(dd_step_exact, STEP_ARGS)
ADAPTER(dd_step_exact_jac_x, STEP_ARGS)
ADAPTER(dd_step_exact_jac_p, STEP_ARGS)
ADAPTER(uc_obs_landmark, OBS_ARGS)
ADAPTER(uc_obs_landmark_jac_x, OBS_ARGS)
ADAPTER(oc_step_exact, STEP_ARGS)
ADAPTER(oc_step_exact_jac_p, STEP_ARGS)
ADAPTER(dd_step_users, STEP_ARGS)
ADAPTER(oc_step_users, STEP_ARGS)
ADAPTER(dd_step_exact_users, STEP_ARGS)
ADAPTER(dd_step_exact_jac_x_users, STEP_ARGS)
ADAPTER(dd_step_exact_jac_p_users, STEP_ARGS)
ADAPTER(oc_step_exact_users, STEP_ARGS)
ADAPTER(oc_step_exact_jac_p_users, STEP_ARGS)
