/* ns per forward-dynamics call of the n-link chain (bench/chain_scaling.sh):
 * the plantc-generated Rust (through a small staticlib, `Plant::dynamics`),
 * SymPy's M, F + Cholesky and CasADi's solve (bench/chain_peers.py),
 * MuJoCo's mj_forward and Pinocchio's ABA (bench/chain_pinocchio.cpp),
 * interleaved over the same random states and timed on this thread's CPU
 * time (CLOCK_THREAD_CPUTIME_ID: time another process takes from this one
 * is not counted, as it would be on the wall clock); then the agreement of
 * each with plantc (max over states of ||a_peer - a_plantc||_inf /
 * ||a_plantc||_inf over the accelerations).
 * With CHAIN_DUMP=FILE it also writes the states and every implementation's
 * accelerations to FILE (bench/chain_precision.py).
 * Built with -DNL=n and -DHAVE_SYMPY / -DHAVE_MUJOCO / -DHAVE_PINOCCHIO as
 * available. Prints one JSON line. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef HAVE_MUJOCO
#include <mujoco/mujoco.h>
#endif

void *plantc_chain_new(void);
void plantc_chain_dyn(const void *plant, const double *x, const double *u, double *out);
#ifdef HAVE_CASADI
void cas_chain(const double *x, const double *u, double *out);
#endif
#ifdef HAVE_PINOCCHIO
void pin_chain_new(int n, double m, double L, double c, double J, double b, double g);
void pin_chain_dyn(const double *x, const double *u, double *out);
#endif
#ifdef HAVE_SYMPY
void sympy_chain(const double *x, const double *u, double *out);
#endif

#define NS 256
#define ROUNDS 15

static double xs[NS][2 * NL];
static double us[NS];
static double sink;

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e9 + t.tv_nsec;
}

static unsigned long long rng = 0x2545f4914f6cdd1dULL;
static double rnd(void) { /* uniform in [-1, 1) */
  rng ^= rng << 13;
  rng ^= rng >> 7;
  rng ^= rng << 17;
  return (double)(rng >> 11) / 9007199254740992.0 * 2.0 - 1.0;
}

static int cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static double median(double *v, int k) {
  qsort(v, k, sizeof(double), cmp);
  return v[k / 2];
}

static double rel(const double *a, const double *ref) {
  double d = 0, r = 0;
  for (int i = 0; i < NL; i++) {
    d = fmax(d, fabs(a[NL + i] - ref[NL + i]));
    r = fmax(r, fabs(ref[NL + i]));
  }
  return d / r;
}

static const void *plant;
static void f_plantc(const double *x, const double *u, double *out) { plantc_chain_dyn(plant, x, u, out); }

#ifdef HAVE_PINOCCHIO
/* the same mirror as MuJoCo's when its hinge turns the other way */
static void f_pin_mirrored(const double *x, const double *u, double *out) {
  double y[2 * NL], v = -u[0];
  for (int i = 0; i < 2 * NL; i++) y[i] = -x[i];
  pin_chain_dyn(y, &v, out);
  for (int i = 0; i < 2 * NL; i++) out[i] = -out[i];
}
#endif

#ifdef HAVE_MUJOCO
static mjModel *mm;
static mjData *md;
static void f_mujoco(const double *x, const double *u, double *out) {
  memcpy(md->qpos, x, NL * sizeof(double));
  memcpy(md->qvel, x + NL, NL * sizeof(double));
  md->ctrl[0] = u[0];
  mj_forward(mm, md);
  memcpy(out, x + NL, NL * sizeof(double));
  memcpy(out + NL, md->qacc, NL * sizeof(double));
}
/* MuJoCo's hinge about +y turns the other way round: q -> -q, u -> -u. */
static void f_mujoco_mirrored(const double *x, const double *u, double *out) {
  double y[2 * NL], v = -u[0];
  for (int i = 0; i < 2 * NL; i++) y[i] = -x[i];
  f_mujoco(y, &v, out);
  for (int i = 0; i < 2 * NL; i++) out[i] = -out[i];
}
#endif

typedef void (*dyn_fn)(const double *, const double *, double *);

static double time_one(dyn_fn f) {
  double out[2 * NL];
  int reps = (int)(2e6 / (NL * NL + 50)) / NS + 1;
  double t = now();
  for (int r = 0; r < reps; r++)
    for (int s = 0; s < NS; s++) {
      f(xs[s], &us[s], out);
      sink += out[2 * NL - 1];
    }
  return (now() - t) / (reps * NS);
}

static double agree2(dyn_fn f, dyn_fn ref) {
  double a[2 * NL], b[2 * NL], worst = 0;
  for (int s = 0; s < NS; s++) {
    f(xs[s], &us[s], a);
    ref(xs[s], &us[s], b);
    worst = fmax(worst, rel(a, b));
  }
  return worst;
}

static double agree(dyn_fn f) { return agree2(f, f_plantc); }

int main(int argc, char **argv) {
  for (int s = 0; s < NS; s++) {
    for (int i = 0; i < NL; i++) xs[s][i] = rnd();
    for (int i = 0; i < NL; i++) xs[s][NL + i] = 3.0 * rnd();
    us[s] = 0.1 * rnd();
  }
  plant = plantc_chain_new();
  const char *names[5] = {"plantc", "casadi", "sympy", "mujoco", "pinocchio"};
  dyn_fn fns[5] = {f_plantc, 0, 0, 0, 0};
#ifdef HAVE_CASADI
  fns[1] = cas_chain;
#endif
#ifdef HAVE_SYMPY
  fns[2] = sympy_chain;
#endif
  dyn_fn check[5];
  const char *mirror = "";
  const char *pmirror = "";
#ifdef HAVE_PINOCCHIO
  pin_chain_new(NL, 0.1, 0.2, 0.1, 3.3e-4, 1e-4, 9.81);
  fns[4] = pin_chain_dyn;
  check[4] = pin_chain_dyn;
  if (agree(pin_chain_dyn) > 1e-6 && agree(f_pin_mirrored) < agree(pin_chain_dyn)) {
    check[4] = f_pin_mirrored;
    pmirror = ", \"pinocchio_mirrored\": true";
  }
#endif
#ifdef HAVE_MUJOCO
  char err[1000];
  if (argc < 2) {
    fprintf(stderr, "usage: chain_harness CHAIN.xml\n");
    return 2;
  }
  mm = mj_loadXML(argv[1], 0, err, sizeof err);
  if (!mm) {
    fprintf(stderr, "mujoco: %s\n", err);
    return 2;
  }
  md = mj_makeData(mm);
  fns[3] = f_mujoco;
  check[3] = f_mujoco;
  if (agree(f_mujoco) > 1e-6 && agree(f_mujoco_mirrored) < agree(f_mujoco)) {
    check[3] = f_mujoco_mirrored;
    mirror = ", \"mujoco_mirrored\": true";
  }
#endif
  for (int k = 0; k < 3; k++) check[k] = fns[k];
  /* CHAIN_DUMP=FILE: every state and each implementation's accelerations
   * (turned as plantc's, 17 digits) for bench/chain_precision.py */
  const char *dump = getenv("CHAIN_DUMP");
  if (dump) {
    FILE *f = fopen(dump, "w");
    if (!f) {
      fprintf(stderr, "cannot write %s\n", dump);
      return 2;
    }
    double a[2 * NL];
    for (int s = 0; s < NS; s++) {
      fprintf(f, "state");
      for (int i = 0; i < 2 * NL; i++) fprintf(f, " %.17g", xs[s][i]);
      fprintf(f, " %.17g\n", us[s]);
      for (int k = 0; k < 5; k++) {
        if (!fns[k]) continue;
        check[k](xs[s], &us[s], a);
        fprintf(f, "%s", names[k]);
        for (int i = 0; i < NL; i++) fprintf(f, " %.17g", a[NL + i]);
        fprintf(f, "\n");
      }
    }
    fclose(f);
  }
  double t[5][ROUNDS];
  for (int r = 0; r < ROUNDS; r++)
    for (int k = 0; k < 5; k++)
      if (fns[k]) t[k][r] = time_one(fns[k]);
  printf("{\"n\": %d", NL);
  for (int k = 0; k < 5; k++)
    if (fns[k]) printf(", \"%s_ns\": %.1f", names[k], median(t[k], ROUNDS));
  for (int k = 1; k < 5; k++)
    if (fns[k]) printf(", \"%s_rel_err\": %.3g", names[k], agree(check[k]));
#if defined(HAVE_SYMPY) && defined(HAVE_CASADI)
  printf(", \"casadi_vs_sympy_rel_err\": %.3g", agree2(cas_chain, sympy_chain));
#endif
  printf("%s%s, \"sink\": %g}\n", mirror, pmirror, sink != sink ? 0.0 : 1.0);
  (void)argc;
  (void)argv;
  return 0;
}
