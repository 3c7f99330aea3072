// Every SymForce C++ peer kernel behind the benchmark's one calling
// convention, `void f(const Args *, double *out)`. SymForce's functions are
// templates over Eigen matrices, compiled inline here as a C++ caller's code
// would. Eigen's fixed-size alignment is switched off (as on targets without
// SIMD alignment guarantees) so that the caller's arrays are used in place:
// inputs are read where they are and outputs written straight into `out`,
// each output column-major (Eigen's layout), one after the other.
#define EIGEN_MAX_STATIC_ALIGN_BYTES 0
#include <Eigen/Core>

#include "kernels.h"
#include "../args.h"

namespace {
template <int N>
const Eigen::Matrix<double, N, 1>& in(const double* data) {
  return *reinterpret_cast<const Eigen::Matrix<double, N, 1>*>(data);
}

template <int R, int C>
Eigen::Matrix<double, R, C>* out(double* data) {
  return reinterpret_cast<Eigen::Matrix<double, R, C>*>(data);
}
}  // namespace

using namespace sym;

#define DD_STEP in<3>(a->x), in<2>(a->u), in<2>(a->w), in<5>(a->p), a->dt
#define OC_STEP in<3>(a->x), in<9>(a->u), in<3>(a->w), in<12>(a->p), a->dt
#define UC_OBS in<3>(a->x), in<2>(a->u), in<1>(a->p), in<2>(a->lm)

extern "C" {
void symforce_cpp_dd_step(const Args* a, double* o) {
  DdStep<double>(DD_STEP, out<3, 1>(o), out<3, 3>(o + 3), out<3, 5>(o + 12));
}
void symforce_cpp_uc_landmark(const Args* a, double* o) {
  UcLandmark<double>(UC_OBS, out<2, 1>(o), out<2, 3>(o + 2));
}
void symforce_cpp_oc_twist(const Args* a, double* o) {
  OcTwist<double>(in<9>(a->u), in<12>(a->p), out<3, 1>(o));
}
void symforce_cpp_oc_step(const Args* a, double* o) {
  OcStep<double>(OC_STEP, out<3, 1>(o), out<3, 12>(o + 3));
}
void symforce_cpp_dd_step_exact(const Args* a, double* o) {
  DdStepExact<double>(DD_STEP, out<3, 1>(o));
}
void symforce_cpp_dd_step_exact_jac_x(const Args* a, double* o) {
  DdStepExactJacX<double>(DD_STEP, out<3, 3>(o));
}
void symforce_cpp_dd_step_exact_jac_p(const Args* a, double* o) {
  DdStepExactJacP<double>(DD_STEP, out<3, 5>(o));
}
void symforce_cpp_uc_obs_landmark(const Args* a, double* o) {
  UcObsLandmark<double>(UC_OBS, out<2, 1>(o));
}
void symforce_cpp_uc_obs_landmark_jac_x(const Args* a, double* o) {
  UcObsLandmarkJacX<double>(UC_OBS, out<2, 3>(o));
}
void symforce_cpp_oc_step_exact(const Args* a, double* o) {
  OcStepExact<double>(OC_STEP, out<3, 1>(o));
}
void symforce_cpp_oc_step_exact_jac_p(const Args* a, double* o) {
  OcStepExactJacP<double>(OC_STEP, out<3, 12>(o));
}
void symforce_cpp_dd_step_users(const Args* a, double* o) {
  DdStepUsers<double>(DD_STEP, out<3, 1>(o), out<3, 3>(o + 3), out<3, 5>(o + 12));
}
void symforce_cpp_oc_step_users(const Args* a, double* o) {
  OcStepUsers<double>(OC_STEP, out<3, 1>(o), out<3, 12>(o + 3));
}
void symforce_cpp_dd_step_exact_users(const Args* a, double* o) {
  DdStepExactUsers<double>(DD_STEP, out<3, 1>(o));
}
void symforce_cpp_dd_step_exact_jac_x_users(const Args* a, double* o) {
  DdStepExactJacXUsers<double>(DD_STEP, out<3, 3>(o));
}
void symforce_cpp_dd_step_exact_jac_p_users(const Args* a, double* o) {
  DdStepExactJacPUsers<double>(DD_STEP, out<3, 5>(o));
}
void symforce_cpp_oc_step_exact_users(const Args* a, double* o) {
  OcStepExactUsers<double>(OC_STEP, out<3, 1>(o));
}
void symforce_cpp_oc_step_exact_jac_p_users(const Args* a, double* o) {
  OcStepExactJacPUsers<double>(OC_STEP, out<3, 12>(o));
}
}
