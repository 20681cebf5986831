/* Thin fixed-signature wrappers around the CasADi-generated functions. */
#include "cas.h"

static casadi_int iw[256];
static casadi_real w[4096];

void cas_dyn(const double *x, const double *u, double *out) {
    const casadi_real *arg[2] = {x, u};
    casadi_real *res[1] = {out};
    cas_dynamics(arg, res, iw, w, 0);
}

void cas_law(const double *x, double *out) {
    const casadi_real *arg[1] = {x};
    casadi_real *res[1] = {out};
    cas_fl_law(arg, res, iw, w, 0);
}

void cas_step(const double *x, const double *u, double *out) {
    const casadi_real *arg[2] = {x, u};
    casadi_real *res[1] = {out};
    cas_rk4(arg, res, iw, w, 0);
}
