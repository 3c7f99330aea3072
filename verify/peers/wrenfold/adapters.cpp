// Every wrenfold C++ peer kernel behind the benchmark's one calling
// convention, `void f(const Args *, double *out)`. wrenfold's functions are
// templates in a header, so each adapter compiles its kernel inline, as a C++
// caller's code would. Inputs are wrenfold spans over the caller's arrays,
// outputs row-major spans written straight into `out`.
#include "kernels.h"
#include "../args.h"

namespace {
template <std::size_t N>
auto in(const double* data) {
  return wf::make_span(data, wf::make_constant_value_pack<N, 1>(),
                       wf::make_constant_value_pack<1, 1>());
}

template <std::size_t R, std::size_t C>
auto out(double* data) {
  return wf::make_span(data, wf::make_constant_value_pack<R, C>(),
                       wf::make_constant_value_pack<C, 1>());
}
}  // namespace

using namespace wrenfold_peer;

#define DD_STEP in<3>(a->x), in<2>(a->u), in<2>(a->w), in<5>(a->p), a->dt
#define OC_STEP in<3>(a->x), in<9>(a->u), in<3>(a->w), in<12>(a->p), a->dt
#define UC_OBS in<3>(a->x), in<2>(a->u), in<1>(a->p), in<2>(a->lm)

extern "C" {
void wrenfold_cpp_dd_step(const Args* a, double* o) {
  dd_step<double>(DD_STEP, out<3, 1>(o), out<3, 3>(o + 3), out<3, 5>(o + 12));
}
void wrenfold_cpp_uc_landmark(const Args* a, double* o) {
  uc_landmark<double>(UC_OBS, out<2, 1>(o), out<2, 3>(o + 2));
}
void wrenfold_cpp_oc_twist(const Args* a, double* o) {
  oc_twist<double>(in<9>(a->u), in<12>(a->p), out<3, 1>(o));
}
void wrenfold_cpp_oc_step(const Args* a, double* o) {
  oc_step<double>(OC_STEP, out<3, 1>(o), out<3, 12>(o + 3));
}
void wrenfold_cpp_dd_step_exact(const Args* a, double* o) {
  dd_step_exact<double>(DD_STEP, out<3, 1>(o));
}
void wrenfold_cpp_dd_step_exact_jac_x(const Args* a, double* o) {
  dd_step_exact_jac_x<double>(DD_STEP, out<3, 3>(o));
}
void wrenfold_cpp_dd_step_exact_jac_p(const Args* a, double* o) {
  dd_step_exact_jac_p<double>(DD_STEP, out<3, 5>(o));
}
void wrenfold_cpp_uc_obs_landmark(const Args* a, double* o) {
  uc_obs_landmark<double>(UC_OBS, out<2, 1>(o));
}
void wrenfold_cpp_uc_obs_landmark_jac_x(const Args* a, double* o) {
  uc_obs_landmark_jac_x<double>(UC_OBS, out<2, 3>(o));
}
void wrenfold_cpp_oc_step_exact(const Args* a, double* o) {
  oc_step_exact<double>(OC_STEP, out<3, 1>(o));
}
void wrenfold_cpp_oc_step_exact_jac_p(const Args* a, double* o) {
  oc_step_exact_jac_p<double>(OC_STEP, out<3, 12>(o));
}
void wrenfold_cpp_dd_step_users(const Args* a, double* o) {
  dd_step_users<double>(DD_STEP, out<3, 1>(o), out<3, 3>(o + 3), out<3, 5>(o + 12));
}
void wrenfold_cpp_oc_step_users(const Args* a, double* o) {
  oc_step_users<double>(OC_STEP, out<3, 1>(o), out<3, 12>(o + 3));
}
void wrenfold_cpp_dd_step_exact_users(const Args* a, double* o) {
  dd_step_exact_users<double>(DD_STEP, out<3, 1>(o));
}
void wrenfold_cpp_dd_step_exact_jac_x_users(const Args* a, double* o) {
  dd_step_exact_jac_x_users<double>(DD_STEP, out<3, 3>(o));
}
void wrenfold_cpp_dd_step_exact_jac_p_users(const Args* a, double* o) {
  dd_step_exact_jac_p_users<double>(DD_STEP, out<3, 5>(o));
}
void wrenfold_cpp_oc_step_exact_users(const Args* a, double* o) {
  oc_step_exact_users<double>(OC_STEP, out<3, 1>(o));
}
void wrenfold_cpp_oc_step_exact_jac_p_users(const Args* a, double* o) {
  oc_step_exact_jac_p_users<double>(OC_STEP, out<3, 12>(o));
}
}
