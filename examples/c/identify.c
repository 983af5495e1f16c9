/* boucwen from C: the model, the online methods, the inverse and a bank of channels on one record.
 *
 * Build (from the repository root):
 *   cargo build --release --features ffi
 *   cc -O2 -Iinclude examples/c/identify.c -Ltarget/release -lboucwen -Wl,-rpath,$PWD/target/release -o identify
 * Run:
 *   ./identify record.txt
 * record.txt: one sample per line, "u x" (u [V], measured x [um]), 10 kHz.
 * Prints one line per sample, every value with %.17g (exact round trip):
 *   model(u)  rpem(u, x)  paper(u, x)  bank channel 0..2 (channel c sees u*(1 - 0.1c), x + 0.01c)
 *   horizon(u, x) (the recommended model: input lag identified from fc = 0.3/dt)  inverse(x)
 *   (the voltage that makes the paper's model reach x)
 * then the final rpem estimates, then the horizon's estimates and identified fc [Hz]. Every online method runs
 * behind the one BwIdentifier handle. Exit code 1 on any error, with the message on stderr; also when a
 * rejected sample changed an identifier, when a restored snapshot does not continue bit for bit, or when a
 * call of another method is not refused. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "boucwen.h"

#define CHANNELS 3

static int check(BwStatus s, const char *what) {
  if (s != BW_OK) {
    fprintf(stderr, "%s: %s\n", what, bw_status_message(s));
    return 1;
  }
  return 0;
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: %s record.txt\n", argv[0]);
    return 1;
  }
  FILE *f = fopen(argv[1], "r");
  if (!f) {
    perror(argv[1]);
    return 1;
  }
  size_t cap = 1024, len = 0;
  double *u = malloc(cap * sizeof *u), *x = malloc(cap * sizeof *x);
  while (u && x && fscanf(f, "%lf %lf", &u[len], &x[len]) == 2) {
    if (++len == cap) {
      cap *= 2;
      u = realloc(u, cap * sizeof *u);
      x = realloc(x, cap * sizeof *x);
    }
  }
  fclose(f);
  if (!u || !x) return 1;

  const double dt = 1e-4;
  BwParams p;
  BwModel *model = NULL;
  BwIdentifier *rpem = NULL, *paper = NULL, *horizon = NULL;
  BwBank *bank = NULL;
  BwInverse *inverse = NULL;
  BwPaperConfig paper_cfg;
  if (check(bw_params_paper_1hz(&p), "params") || check(bw_model_new(&p, dt, 0.0, &model), "model") ||
      check(bw_identifier_new_rpem(dt, &p, 0.0, NULL, &rpem), "rpem") ||
      check(bw_paper_config_default(200, &paper_cfg), "paper config") ||
      check(bw_identifier_new_paper(dt, &p, 0.0, &paper_cfg, &paper), "paper") ||
      check(bw_bank_new(CHANNELS, dt, rpem, &bank), "bank") ||
      check(bw_identifier_new_horizon(dt, &p, 0.0, 0.3 / dt, NULL, &horizon), "horizon") ||
      check(bw_inverse_new(&p, dt, 0.0, -1.0 / 0.0, 1.0 / 0.0, &inverse), "inverse"))
    return 1;

  for (size_t k = 0; k < len; k++) {
    double xm, xr, xp, xh, ui, bu[CHANNELS], bx[CHANNELS], bout[CHANNELS];
    for (int c = 0; c < CHANNELS; c++) {
      bu[c] = u[k] * (1.0 - 0.1 * c);
      bx[c] = x[k] + 0.01 * c;
    }
    if (check(bw_model_step(model, u[k], &xm), "model step") || check(bw_identifier_push(rpem, u[k], x[k], &xr), "rpem push") ||
        check(bw_identifier_push(paper, u[k], x[k], &xp), "paper push") || check(bw_bank_push(bank, bu, bx, bout), "bank push") ||
        check(bw_identifier_push(horizon, u[k], x[k], &xh), "horizon push") ||
        check(bw_inverse_step(inverse, x[k], &ui), "inverse step"))
      return 1;
    printf("%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", xm, xr, xp, bout[0], bout[1], bout[2], xh, ui);
  }
  BwParams est;
  if (check(bw_identifier_params(rpem, &est), "rpem params")) return 1;
  printf("%.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", est.kv, est.x0, est.a, est.beta, est.gamma, est.n, est.delta);
  double fc;
  if (check(bw_identifier_params(horizon, &est), "horizon params") || check(bw_identifier_lag_fc(horizon, &fc), "horizon fc"))
    return 1;
  printf("%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", est.kv, est.x0, est.a, est.beta, est.gamma, est.n, est.delta, fc);

  /* A rejected sample leaves the identifier as it was: a snapshot taken before and one
   * taken after are the same bytes, and a copy restored from them continues bit for bit. */
  BwIdentifier *ids[3] = {rpem, paper, horizon};
  const BwMethod methods[3] = {BW_METHOD_RPEM, BW_METHOD_PAPER, BW_METHOD_HORIZON};
  for (int i = 0; i < 3; i++) {
    size_t n = 0, n_after = 0;
    BwMethod method;
    BwIdentifierStatus status;
    if (bw_identifier_snapshot(ids[i], NULL, 0, &n) != BW_BUFFER_TOO_SMALL) return 1;
    unsigned char *before = malloc(n), *after = malloc(n);
    BwIdentifier *copy = NULL;
    double dummy, a, b;
    if (!before || !after || check(bw_identifier_snapshot(ids[i], before, n, &n), "snapshot") ||
        bw_identifier_push(ids[i], 0.0 / 0.0, 1.0, &dummy) != BW_NON_FINITE_SAMPLE ||
        check(bw_identifier_snapshot(ids[i], after, n, &n_after), "snapshot") || n_after != n ||
        memcmp(before, after, n) != 0 || check(bw_identifier_restore(before, n, &copy), "restore") ||
        check(bw_identifier_method(copy, &method), "method") || method != methods[i] ||
        check(bw_identifier_push(ids[i], u[0], x[0], &a), "push") || check(bw_identifier_push(copy, u[0], x[0], &b), "push") ||
        memcmp(&a, &b, sizeof a) != 0 || check(bw_identifier_status(copy, &status), "status") ||
        status.method != methods[i] || status.samples != len + 1)
      return 1;
    /* The horizon method's window pass is its own: another method refuses it. */
    size_t ran;
    BwStatus refine = bw_identifier_refine(copy, 16, &ran);
    if (refine != (methods[i] == BW_METHOD_HORIZON ? BW_OK : BW_WRONG_METHOD)) return 1;
    bw_identifier_free(copy);
    free(before);
    free(after);
  }

  bw_inverse_free(inverse);
  bw_identifier_free(horizon);
  bw_bank_free(bank);
  bw_identifier_free(paper);
  bw_identifier_free(rpem);
  bw_model_free(model);
  free(u);
  free(x);
  return 0;
}
