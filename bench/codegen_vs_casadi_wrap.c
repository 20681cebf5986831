/* Thin fixed-signature wrappers around the CasADi-generated functions:
 * cas_* take the parameters and gains as an input array (live, like
 * plantc's), casc_* have them compiled in (bench/codegen_vs_casadi.py). */
#include "cas.h"

static casadi_int iw[256];
static casadi_real w[4096];
/* the thesis set (Fg1 = 0) and the gains wn = 4, zeta = 0.7, in the order
 * of codegen_vs_casadi.py's `names`; volatile-free but set at run time by
 * cas_set_params, so the compiler cannot fold them either */
static casadi_real p[19];

void cas_set_params(const double *values) {
    for (int i = 0; i < 19; i++) p[i] = values[i];
}

void cas_dyn(const double *x, const double *u, double *out) {
    const casadi_real *arg[3] = {x, u, p};
    casadi_real *res[1] = {out};
    cas_dynamics(arg, res, iw, w, 0);
}

void cas_law(const double *x, double *out) {
    const casadi_real *arg[2] = {x, p};
    casadi_real *res[1] = {out};
    cas_fl_law(arg, res, iw, w, 0);
}

void cas_step(const double *x, const double *u, double *out) {
    const casadi_real *arg[3] = {x, u, p};
    casadi_real *res[1] = {out};
    cas_rk4(arg, res, iw, w, 0);
}

void casc_dyn(const double *x, const double *u, double *out) {
    const casadi_real *arg[2] = {x, u};
    casadi_real *res[1] = {out};
    casc_dynamics(arg, res, iw, w, 0);
}

void casc_law(const double *x, double *out) {
    const casadi_real *arg[1] = {x};
    casadi_real *res[1] = {out};
    casc_fl_law(arg, res, iw, w, 0);
}

void casc_step(const double *x, const double *u, double *out) {
    const casadi_real *arg[2] = {x, u};
    casadi_real *res[1] = {out};
    casc_rk4(arg, res, iw, w, 0);
}
