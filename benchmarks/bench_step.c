/* Times the exported observer and controller steps (built by bench_codegen.py).
 * Usage: bench_step N; prints "phso_ns eso_ns phdo_ns controller_ns" per step. */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "bw.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv)
{
    const long n = argc > 1 ? atol(argv[1]) : 10000000L;
    bw_observer s;
    bw_phdo_observer sd;
    bw_controller c;
    bw_real xhat[3] = {0, 0, 0};
    volatile bw_real sink = 0;
    double t0, t_phso, t_eso, t_phdo, t_ctrl;
    long k;
    /* a 1 Hz sine at dt = 0.2 ms, as a table so the input costs nothing inside the loop */
    enum { M = 5000 };
    static bw_real u[M], z[M];
    for (k = 0; k < M; k++) {
        u[k] = (bw_real)(70.0 + 60.0 * sin(6.283185307179586 * (double)k / M));
        z[k] = (bw_real)(1.39 * (double)u[k] - 1.0);
    }
    bw_phso_init(&s);
    t0 = now();
    for (k = 0; k < n; k++) {
        bw_phso_step(&s, u[k % M], z[k % M]);
    }
    t_phso = now() - t0;
    sink = s.x[0];
    bw_eso_init(&s);
    t0 = now();
    for (k = 0; k < n; k++) {
        bw_eso_step(&s, u[k % M], z[k % M]);
    }
    t_eso = now() - t0;
    sink = s.x[0];
    bw_phdo_init(&sd);
    t0 = now();
    for (k = 0; k < n; k++) {
        bw_phdo_step(&sd, u[k % M], z[k % M]);
    }
    t_phdo = now() - t0;
    sink = sd.x[0];
    bw_controller_init(&c);
    t0 = now();
    for (k = 0; k < n; k++) {
        xhat[0] = z[k % M];
        sink = bw_controller_compute(&c, xhat, z[k % M], u[k % M], 0);
    }
    t_ctrl = now() - t0;
    (void)sink;
    printf("%.3f %.3f %.3f %.3f\n", 1e9 * t_phso / (double)n, 1e9 * t_eso / (double)n,
        1e9 * t_phdo / (double)n, 1e9 * t_ctrl / (double)n);
    return 0;
}
