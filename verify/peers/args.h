/* The arguments of every kernel of the peer benchmark, one layout for the C
 * and C++ adapters and the Rust side (`kinegen_peers::Args`, #[repr(C)]):
 * pointers to the state, inputs, noise, parameters and landmark, and the time
 * step. A kernel ignores the ones it does not take. */
#ifndef KINEGEN_PEERS_ARGS_H
#define KINEGEN_PEERS_ARGS_H
typedef struct {
  const double *x, *u, *w, *p, *lm;
  double dt;
} Args;
#endif
