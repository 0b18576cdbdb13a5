/*
 * The compiled step kernels (issue 39): the steps, inputs and outputs of a block in C, without Python.
 *
 * The slave hands the bridge an IMAGE of itself (fmus/runtime/slave/kernel.py): one vector of doubles (the
 * time, the state x, the inputs w with their record and derivatives, the block's constants, the parameter
 * values) and a layout of int64 saying where each is.  These kinds of block have a kernel:
 *
 *   KK_AFFINE (observers/kernel_forms.py: LTI plant, Luenberger observer, state feedback), exact over a step
 *     whose inputs are linear, w0 + s dw:
 *         x(t + h) = Phi(h) x + G0(h) w0 + G1(h) dw          out = C x + D w + e
 *   KK_EXPRESSION (plants/expression.py: a continuous plant of expressions), x' = f(t, x, u, p), y = g(t, x, u, p)
 *     by observers.integrators.rk4_controlled, operation for operation; f and g are the FMU's own compiled
 *     expressions (observers/expressions_c.py), found by the bridge in the FMU's kernel library;
 *     out = [g(t, x, w, p); x].
 *   KK_LTV, KK_LTV_PLANT (kernel_ltv.h: paper 001's adaptive observer with least squares, and its plant): the
 *     block's whole state packed into x (observers/ltv/kernel.py), its step written again in C; A(t), L(t), f(y, t)
 *     and C(t) are the FMU's compiled expressions.
 *   KK_NOISE_FILTER (kernel_noise.h: band-limited noise): the filter's recurrence over the white samples, which
 *     are the FMU's compiled expressions of numpy's random stream.
 *
 * The input segments are built as the Python slave builds them (fmus/runtime/slave/step.py): a port given a
 * derivative follows it; otherwise its <port>_interpolation mode: hold, extrapolate from the previous
 * communication point, interpolate from it (the value set belongs to the step end).  A constant column 1
 * follows the inputs of an affine block when the layout says so (columns = m + 1).
 *
 * Everything here is plain C on the image; the bridge (bridge.c) loads and stores it.  A call the kernel cannot
 * vouch for returns 0 having changed nothing, and the bridge hands it to the Python path, which carries it out
 * or refuses it with its message: a value that is not finite or beyond the bound, a step size that is not
 * positive, a step beyond the sub-step budget, a value reference of another kind.
 */
#ifndef OBSFMU_KERNEL_H
#define OBSFMU_KERNEL_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#define OBSFMU_KERNEL_ABI 4 /* = fmus.runtime.slave.kernel.KERNEL_ABI */
/* The matrices of this many step sizes are kept (= fmus.runtime.slave.kernel.SLOTS): an importer that steps
 * t_(k+1) - t_k, like fmusim, gives a few step sizes one ulp apart, alternating */
#define OBSFMU_KERNEL_SLOTS 8
/* The exported functions of an FMU's kernel library (= fmus.runtime.slave.kernel.SYMBOLS) */
#define OBSFMU_KERNEL_F "obsfmu_kernel_f"
#define OBSFMU_KERNEL_G "obsfmu_kernel_g"
#define OBSFMU_KERNEL_L "obsfmu_kernel_l"
#define OBSFMU_KERNEL_C "obsfmu_kernel_c"
#define OBSFMU_KERNEL_V "obsfmu_kernel_v"

/* The layout's header, in the order of fmus.runtime.slave.kernel.HEADER */
enum {
    KL_ABI, KL_KIND, KL_N, KL_M, KL_COLUMNS, KL_Q, KL_PORTS, KL_VARIABLES, KL_PARAMETERS,
    KL_TIME, KL_X, KL_W, KL_D, KL_PREVIOUS, KL_PREVIOUS_TIME, KL_MOVING, KL_OUT, KL_C, KL_DMATRIX, KL_E,
    KL_PHI, KL_G0, KL_G1, KL_H, KL_BOUND, KL_VALUES, KL_P, KL_SETTINGS, KL_SCRATCH, KL_SIZE, KL_HEADER
};
/* kinds of kernel */
enum { KK_AFFINE = 1, KK_EXPRESSION = 2, KK_LTV = 3, KK_LTV_PLANT = 4, KK_NOISE_FILTER = 5 };
/* classes of a value reference (the layout's table) */
enum { KV_PYTHON, KV_INPUT, KV_OUTPUT, KV_VALUE, KV_INTEGER };
/* <port>_interpolation (fmus.runtime.slave.common.InputMode) */
enum { KM_HOLD, KM_EXTRAPOLATE, KM_INTERPOLATE };
/* settings of an expression kernel (observers.integrators.rk4_controlled's) */
enum { KS_MAX_SUBSTEP, KS_RTOL, KS_ATOL, KS_BUDGET, KS_COUNT };

/* an expression vector: out[i] = expression i at (t, x, u, p) */
typedef void KernelFunction(double t, const double *x, const double *u, const double *p, double *out);

typedef struct {
    int kind;
    size_t n, m, columns, q, ports, variables, parameters;
    double *time, *x, *w, *d, *previous, *previous_time, *moving, *out, *C, *D, *e, *Phi, *G0, *G1, *h, *bound,
        *values, *p, *settings, *scratch;
    const int64_t *start, *mode, *table; /* port starts (ports + 1), port modes, (class, index) per variable */
    KernelFunction *f, *g, *l, *c, *v;   /* the FMU's compiled expressions (set by the bridge): f, g of KK_EXPRESSION;
                                            f(y, t), A(t), L(t) and C(t) of KK_LTV (KK_LTV_PLANT: no L, and v(t), its
                                            measurement noise) */
    int outputs_valid;                   /* out holds the outputs of the present x and w */
    int slot;                            /* of the matrices: the one of the last step, or the one to fill next */
} KernelImage;

#include "kernel_ltv.h"   /* KK_LTV, KK_LTV_PLANT: paper 001's adaptive observer and plant */
#include "kernel_noise.h" /* KK_NOISE_FILTER: band-limited noise */

/* The doubles each field of the image holds (KL_TIME .. KL_SCRATCH) for these sizes. */
static size_t kernel_field_size(const KernelImage *k, int field)
{
    size_t n = k->n, m = k->m, q = k->q, W = k->columns, affine = k->kind == KK_AFFINE;
    switch (field) {
    case KL_TIME: case KL_BOUND: return 1;
    case KL_X: return n;
    case KL_W: case KL_D: case KL_PREVIOUS: return m;
    case KL_PREVIOUS_TIME: case KL_MOVING: return k->ports;
    case KL_OUT: return q;
    case KL_C: return affine * q * n;
    case KL_DMATRIX: return affine * q * m;
    case KL_E: return affine * q;
    case KL_PHI: return affine * OBSFMU_KERNEL_SLOTS * n * n;
    case KL_G0: case KL_G1: return affine * OBSFMU_KERNEL_SLOTS * n * W;
    case KL_H: return affine * OBSFMU_KERNEL_SLOTS;
    case KL_VALUES: return k->variables;
    case KL_P: return k->parameters;
    case KL_SETTINGS:
        return affine ? 0 : k->kind == KK_LTV ? KT_COUNT : k->kind == KK_LTV_PLANT ? KQ_COUNT
                          : k->kind == KK_NOISE_FILTER ? KN_COUNT : KS_COUNT;
    case KL_SCRATCH: return n + 2 * W + m + q + 7 * n + m;
    default: return 0;
    }
}

/* Bind the image to the slave's vectors; 0 when they fit each other, -1 (and the image unusable) otherwise. */
static int kernel_bind(KernelImage *k, double *memory, size_t memory_size, const int64_t *layout, size_t layout_size)
{
    memset(k, 0, sizeof *k);
    if (layout_size < KL_HEADER || layout[KL_ABI] != OBSFMU_KERNEL_ABI || layout[KL_SIZE] != (int64_t)memory_size ||
        layout[KL_KIND] < KK_AFFINE || layout[KL_KIND] > KK_NOISE_FILTER)
        return -1;
    for (int field = KL_N; field < KL_HEADER; field++)
        if (layout[field] < 0 || layout[field] > (int64_t)memory_size) return -1;
    k->kind = (int)layout[KL_KIND];
    k->n = (size_t)layout[KL_N], k->m = (size_t)layout[KL_M], k->columns = (size_t)layout[KL_COLUMNS];
    k->q = (size_t)layout[KL_Q], k->ports = (size_t)layout[KL_PORTS], k->variables = (size_t)layout[KL_VARIABLES];
    k->parameters = (size_t)layout[KL_PARAMETERS];
    if (k->columns < k->m || k->columns > k->m + 1 || (k->kind == KK_EXPRESSION && k->q < k->n) ||
        layout_size != KL_HEADER + (k->ports + 1) + k->ports + 2 * k->variables)
        return -1;
    double **fields[] = {&k->time, &k->x, &k->w, &k->d, &k->previous, &k->previous_time, &k->moving, &k->out, &k->C,
                         &k->D, &k->e, &k->Phi, &k->G0, &k->G1, &k->h, &k->bound, &k->values, &k->p, &k->settings,
                         &k->scratch};
    for (int field = KL_TIME; field <= KL_SCRATCH; field++) {
        if ((size_t)layout[field] + kernel_field_size(k, field) > memory_size) return -1;
        *fields[field - KL_TIME] = memory + layout[field];
    }
    k->start = layout + KL_HEADER;
    k->mode = k->start + k->ports + 1;
    k->table = k->mode + k->ports;
    if (k->start[0] != 0 || (size_t)k->start[k->ports] != k->m) return -1;
    for (size_t port = 0; port < k->ports; port++)
        if (k->start[port + 1] < k->start[port]) return -1;
    for (size_t i = 0; i < k->variables; i++) {
        int64_t kind = k->table[2 * i], index = k->table[2 * i + 1];
        if ((kind == KV_INPUT && (index < 0 || (size_t)index >= k->m)) ||
            (kind == KV_OUTPUT && (index < 0 || (size_t)index >= k->q)) ||
            ((kind == KV_VALUE || kind == KV_INTEGER) && (size_t)index != i))
            return -1;
    }
    if ((k->kind == KK_LTV && !kt_fits(k)) || (k->kind == KK_LTV_PLANT && !kq_fits(k)) ||
        (k->kind == KK_NOISE_FILTER && !kn_fits(k)))
        return -1;
    return 0;
}

/* |v| <= bound, and not NaN */
static int kernel_within(double v, double bound) { return v >= -bound && v <= bound; }

/* The sum of squares of x[0..n) is within (bound / 2)^2: the Python slave's test (each port's or array's norm within
 * the bound) passes, with a margin; NaN and inf fail. */
static int kernel_small(const double *x, size_t n, double bound)
{
    double sum = 0.0;
    for (size_t i = 0; i < n; i++) sum += x[i] * x[i];
    return sum <= 0.25 * bound * bound;
}

/* The value reference's (class, index); KV_PYTHON for one beyond the table. */
static int kernel_class(const KernelImage *k, unsigned vr, size_t *index)
{
    if (vr >= k->variables) return KV_PYTHON;
    *index = (size_t)k->table[2 * vr + 1];
    return (int)k->table[2 * vr];
}

/* fmi2SetReal of inputs: 1 when every value reference is an input and every value finite within the bound (then
 * set); 0 and nothing set otherwise. */
static int kernel_set_inputs(KernelImage *k, const unsigned vr[], size_t nvr, const double value[])
{
    size_t index;
    for (size_t i = 0; i < nvr; i++)
        if (kernel_class(k, vr[i], &index) != KV_INPUT || !kernel_within(value[i], *k->bound)) return 0;
    for (size_t i = 0; i < nvr; i++) {
        kernel_class(k, vr[i], &index);
        k->w[index] = value[i];
    }
    k->outputs_valid = 0;
    return 1;
}

/* The port of input element i. */
static size_t kernel_port(const KernelImage *k, size_t i)
{
    size_t port = 0;
    while ((size_t)k->start[port + 1] <= i) port++;
    return port;
}

/* fmi2SetRealInputDerivatives (first order): as the slave's set_real_input_derivatives -- a port given a
 * derivative follows its slope in the next step, its other elements with slope 0 (order NULL: every order 1).  1 when
 * carried out; 0 and nothing set when a value reference is not an input, an order is not 1 or a value is not within
 * the bound. */
static int kernel_set_derivatives(KernelImage *k, const unsigned vr[], size_t nvr, const int order[],
                                  const double value[])
{
    size_t index;
    for (size_t i = 0; i < nvr; i++)
        if (kernel_class(k, vr[i], &index) != KV_INPUT || (order != NULL && order[i] != 1) ||
            !kernel_within(value[i], *k->bound))
            return 0;
    for (size_t i = 0; i < nvr; i++) {
        kernel_class(k, vr[i], &index);
        size_t port = kernel_port(k, index);
        if (!k->moving[port]) {
            for (size_t j = (size_t)k->start[port]; j < (size_t)k->start[port + 1]; j++) k->d[j] = 0.0;
            k->moving[port] = 1.0;
        }
        k->d[index] = value[i];
    }
    return 1;
}

/* y = A x (+ y when add), A rows x columns given column by column (A[i][j] at A[j * rows + i]: the image holds C, D,
 * Phi, G0 and G1 so).  Each y[i] is summed 0 + A[i][0] x[0] + A[i][1] x[1] + ... in that order, as a plain dot
 * product; but the rows of a block are summed side by side, column after column, over contiguous entries: no
 * addition waits for the one before it (a dot product is a chain of dependent additions), and the compiler can
 * pack the rows into vector instructions. */
#define KERNEL_ROWS 64
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((optimize("O3"))) /* GCC vectorizes these loops at -O3 (Clang at -O2): the same operations, 2 at a time */
#endif
static void kernel_product(const double *A, const double *x, size_t rows, size_t columns, double *y, int add)
{
    double sum[KERNEL_ROWS];
    for (size_t first = 0; first < rows; first += KERNEL_ROWS) {
        size_t count = rows - first < KERNEL_ROWS ? rows - first : KERNEL_ROWS;
        for (size_t i = 0; i < count; i++) sum[i] = 0.0;
        for (size_t j = 0; j < columns; j++) {
            const double *column = A + j * rows + first;
            double xj = x[j];
            for (size_t i = 0; i < count; i++) sum[i] += column[i] * xj;
        }
        for (size_t i = 0; i < count; i++) y[first + i] = add ? y[first + i] + sum[i] : sum[i];
    }
}

/* The outputs at time t of this x and w: C x + D w + e (affine); [g(t, x, w, p); x] (expression); the LTV
 * observer's of its packed state (kt_outputs: 1 when its converged flag is held at 0 by the step, else 0). */
static int kernel_outputs(const KernelImage *k, double t, const double *x, const double *w, double *out)
{
    if (k->kind == KK_LTV) return kt_outputs(k, x, out);
    if (k->kind == KK_LTV_PLANT) return kq_outputs(k, t, x, out);
    if (k->kind == KK_NOISE_FILTER) return kn_outputs(k, t, x, w, out);
    if (k->kind == KK_EXPRESSION) {
        size_t q = k->q - k->n;
        k->g(t, x, w, k->p, out);
        memcpy(out + q, x, k->n * sizeof *x);
        return 0;
    }
    kernel_product(k->C, x, k->q, k->n, out, 0);
    kernel_product(k->D, w, k->q, k->m, out, 1);
    for (size_t i = 0; i < k->q; i++) out[i] += k->e[i];
    return 0;
}

/* 1 when every value reference is a Real input, output or parameter: the kernel reads them. */
static int kernel_readable(const KernelImage *k, const unsigned vr[], size_t nvr)
{
    size_t index;
    for (size_t i = 0; i < nvr; i++) {
        int kind = kernel_class(k, vr[i], &index);
        if (kind == KV_PYTHON || kind == KV_INTEGER) return 0;
    }
    return 1;
}

/* fmi2GetInteger of Integer parameters (the <port>_interpolation modes, fixed while stepping): 1 when every value
 * reference is one (then read), 0 otherwise. */
static int kernel_get_integers(const KernelImage *k, const unsigned vr[], size_t nvr, int value[])
{
    size_t index;
    for (size_t i = 0; i < nvr; i++)
        if (kernel_class(k, vr[i], &index) != KV_INTEGER) return 0;
    for (size_t i = 0; i < nvr; i++) {
        kernel_class(k, vr[i], &index);
        value[i] = (int)k->values[index];
    }
    return 1;
}

/* fmi2GetReal: 1 when every value reference is an input, an output or a parameter (then read); 0 otherwise (an
 * output the kernel cannot vouch for too: not finite or beyond the bound -- the Python path refuses it). */
static int kernel_get(KernelImage *k, const unsigned vr[], size_t nvr, double value[])
{
    size_t index;
    if (!kernel_readable(k, vr, nvr)) return 0;
    if (!k->outputs_valid) {
        kernel_outputs(k, *k->time, k->x, k->w, k->out);
        if (!kernel_small(k->out, k->q, *k->bound)) return 0;
        k->outputs_valid = 1;
    }
    for (size_t i = 0; i < nvr; i++) {
        int kind = kernel_class(k, vr[i], &index);
        value[i] = kind == KV_INPUT ? k->w[index] : kind == KV_OUTPUT ? k->out[index] : k->values[index];
    }
    return 1;
}

/* The input segments of a step from t of size h into w0, dw (fmus/runtime/slave/step.py: Stepping._step and
 * _held_segment), and the inputs at the step end into end. */
static void kernel_segments(const KernelImage *k, double t, double h, double *w0, double *dw, double *end)
{
    for (size_t port = 0; port < k->ports; port++) {
        int moving = k->moving[port] != 0.0;
        int64_t mode = k->mode[port];
        double since = t - k->previous_time[port];
        for (size_t i = (size_t)k->start[port]; i < (size_t)k->start[port + 1]; i++) {
            double value = k->w[i], previous = k->previous[i];
            end[i] = value;
            if (moving) {
                w0[i] = value, dw[i] = k->d[i];
                end[i] = k->d[i] * h + value;
            } else if (mode == KM_INTERPOLATE) {
                w0[i] = previous, dw[i] = (value - previous) / h;
            } else if (mode == KM_EXTRAPOLATE && k->previous_time[port] < t) {
                w0[i] = value, dw[i] = (value - previous) / since;
            } else {
                w0[i] = value, dw[i] = 0.0;
            }
        }
    }
    if (k->columns > k->m) w0[k->m] = 1.0, dw[k->m] = 0.0;
}

/* KK_AFFINE: x(t + h) into next; 1, or -1 when the matrices of h are needed first (into slot k->slot). */
static int kernel_affine(KernelImage *k, double h, const double *w0, const double *dw, double *next)
{
    if (k->n && k->h[k->slot] != h) {
        int found = -1;
        for (int slot = 0; slot < OBSFMU_KERNEL_SLOTS && found < 0; slot++)
            if (k->h[slot] == h) found = slot;
        if (found < 0) { /* the slave fills the next slot, round robin */
            k->slot = (k->slot + 1) % OBSFMU_KERNEL_SLOTS;
            return -1;
        }
        k->slot = found;
    }
    size_t n = k->n, W = k->columns, slot = (size_t)k->slot;
    kernel_product(k->Phi + slot * n * n, k->x, n, n, next, 0);
    kernel_product(k->G0 + slot * n * W, w0, n, W, next, 1);
    kernel_product(k->G1 + slot * n * W, dw, n, W, next, 1);
    return 1;
}

/* f(s, x, u(s), p) with the input u(s) = w0 + (s - t) dw of the step from t (plants/expression.py: rhs) */
static void kernel_rhs(const KernelImage *k, double t, double s, const double *x, const double *w0,
                       const double *dw, double *u, double *out)
{
    double elapsed = s - t;
    for (size_t i = 0; i < k->m; i++) u[i] = w0[i] + elapsed * dw[i];
    k->f(s, x, u, k->p, out);
}

/* KK_EXPRESSION: x(t + h) into next by observers.integrators.substep_count and rk4_controlled, operation for
 * operation (numpy's elementwise order); 1, or 0 when the Python path must take the step (a budget exceeded, a state
 * that is not finite: it refuses them, naming why). */
static int kernel_expression(KernelImage *k, double t, double h, const double *w0, const double *dw, double *next,
                             double *work)
{
    size_t n = k->n;
    double max_substep = k->settings[KS_MAX_SUBSTEP], rtol = k->settings[KS_RTOL], atol = k->settings[KS_ATOL];
    double budget = k->settings[KS_BUDGET];
    double by_length = h / max_substep;
    if (!(by_length <= budget * (1.0 + 1e-9))) return 0;                  /* substep_count's BudgetError */
    double count = ceil(by_length - 1e-9);
    long substeps = count > 1.0 ? (long)count : 1;
    double *x = work, *k1 = x + n, *k2 = k1 + n, *k3 = k2 + n, *k4 = k3 + n, *k5 = k4 + n, *stage = k5 + n;
    double *u = stage + n, *swap;
    memcpy(x, k->x, n * sizeof *x);
    double nominal = h / (double)substeps, dt = nominal, s = t, stop = t + h, ratio = 0.0, end;
    long attempts = 0, i = 0;
    int rejected = 0;
    kernel_rhs(k, t, t, x, w0, dw, u, k1);
    for (;;) {
        if (!rejected) {                                   /* rk4_step's grid, to the last bit */
            s = t + (double)i * nominal, end = t + (double)(i + 1) * nominal, dt = nominal;
        } else {
            end = s + dt < stop - 1e-12 * fabs(h) ? s + dt : stop;
            dt = end - s;
        }
        if ((double)++attempts > budget) return 0;         /* the BudgetError of rk4_controlled */
        double half = dt / 2, sixth = dt / 6;
        for (size_t j = 0; j < n; j++) stage[j] = x[j] + half * k1[j];
        kernel_rhs(k, t, s + half, stage, w0, dw, u, k2);
        for (size_t j = 0; j < n; j++) stage[j] = x[j] + half * k2[j];
        kernel_rhs(k, t, s + half, stage, w0, dw, u, k3);
        for (size_t j = 0; j < n; j++) stage[j] = x[j] + dt * k3[j];
        kernel_rhs(k, t, end, stage, w0, dw, u, k4);
        int finite = 1;
        for (size_t j = 0; j < n; j++) {
            next[j] = x[j] + sixth * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
            finite &= isfinite(next[j]) != 0;
        }
        if (!finite) return 0;
        kernel_rhs(k, t, end, next, w0, dw, u, k5);
        ratio = 0.0;
        for (size_t j = 0; j < n; j++) {                   /* np.max: NaN wins */
            double a = fabs(x[j]), b = fabs(next[j]);
            double scale = atol + rtol * (a >= b ? a : b);
            double error = fabs(sixth * (k4[j] - k5[j])) / scale;
            if (error != error || error > ratio) ratio = error;
            if (ratio != ratio) break;
        }
        if (!(ratio <= 1.0)) {                             /* NaN too: shorter */
            rejected = 1;
            double factor = 0.9 * pow(ratio, -0.25);
            dt *= isfinite(ratio) ? (factor > 0.1 ? factor : 0.1) : 0.1;
            continue;
        }
        memcpy(x, next, n * sizeof *x);
        swap = k1, k1 = k5, k5 = swap;
        s = end;
        i++;
        if (s >= stop || (!rejected && i == substeps)) {
            memcpy(next, x, n * sizeof *x);
            return 1;
        }
        if (rejected) {
            double grow = ratio > 0 ? 0.9 * pow(ratio, -0.25) : 5.0;
            double longer = dt * (grow < 5.0 ? grow : 5.0);
            dt = longer < nominal ? longer : nominal;
        }
    }
}

/* fmi2DoStep from t (the instance's time: the loader checked it) of size h.  1: stepped (state, inputs, their
 * record and the outputs at the step end); 0: not for the kernel, nothing changed (a bad step size, a value that
 * is not finite or beyond the bound, a budget exceeded: the Python path refuses it, naming it); -1: the matrices of
 * this h are needed first, into slot k->slot (the slave's kernel_matrices(h, slot)), nothing changed. */
static int kernel_step(KernelImage *k, double t, double h)
{
    if (!(h > 0.0 && h <= 1.7976931348623157e308 && t == t)) return 0;
    double *next = k->scratch, *w0 = next + k->n, *dw = w0 + k->columns, *end = dw + k->columns, *out = end + k->m;
    double *work = out + k->q;
    kernel_segments(k, t, h, w0, dw, end);
    int taken = k->kind == KK_AFFINE ? kernel_affine(k, h, w0, dw, next)
                : k->kind == KK_EXPRESSION ? kernel_expression(k, t, h, w0, dw, next, work)
                : k->kind == KK_LTV        ? kernel_ltv(k, t, h, w0, dw, next, work)
                : k->kind == KK_LTV_PLANT  ? kernel_ltv_plant(k, t, h, w0, dw, next, work)
                                           : kernel_noise_filter(k, t, h, next, work);
    if (taken <= 0) return taken;
    if (kernel_outputs(k, t + h, next, end, out) && next[(size_t)k->settings[KT_X_NOTED]] == 0.0)
        return 0; /* converged held at 0 by the step for the first time: the slave says so (in Python) */
    double bound = *k->bound;
    if (!kernel_small(next, k->n, bound) || !kernel_small(out, k->q, bound) || !kernel_small(end, k->m, bound))
        return 0;
    /* taken: the state, the inputs at the end and their record (fmus/runtime/slave/step.py: _last_inputs) */
    memcpy(k->x, next, k->n * sizeof *next);
    for (size_t port = 0; port < k->ports; port++) {
        int moving = k->moving[port] != 0.0;
        for (size_t i = (size_t)k->start[port]; i < (size_t)k->start[port + 1]; i++) {
            k->w[i] = end[i];
            k->previous[i] = end[i];
        }
        k->previous_time[port] = moving || k->mode[port] == KM_INTERPOLATE ? t + h : t;
        k->moving[port] = 0.0;
    }
    memcpy(k->out, out, k->q * sizeof *out);
    k->outputs_valid = 1;
    *k->time = t + h;
    return 1;
}

#endif
