/*
 * The compiled step kernel of a linear block (issue 39): its steps, inputs and outputs in C, without Python.
 *
 * The slave hands the bridge an IMAGE of itself (fmus/runtime/slave/kernel.py): one vector of doubles (the
 * time, the state x, the inputs w with their record and derivatives, the matrices, the parameter values) and a
 * layout of int64 saying where each is.  The block is affine (observers/affine_form.py):
 *
 *     x(t + h) = Phi(h) x + G0(h) w0 + G1(h) dw          (inputs linear over the step: w0 + s dw)
 *     out      = C x + D w + e                            (every output element, in declaration order)
 *
 * with the input segments built as the Python slave builds them (fmus/runtime/slave/step.py): a port given a
 * derivative follows it; otherwise its <port>_interpolation mode: hold, extrapolate from the previous
 * communication point, interpolate from it (the value set belongs to the step end).  A constant column 1
 * follows the inputs when the layout says so (columns = m + 1).
 *
 * Everything here is plain C on the image; the bridge (bridge.c) loads and stores it.  A call the kernel cannot
 * vouch for returns 0 having changed nothing, and the bridge hands it to the Python path, which carries it out
 * or refuses it with its message: a value that is not finite or beyond the bound, a step size that is not
 * positive, a value reference of another kind.
 */
#ifndef OBSFMU_KERNEL_H
#define OBSFMU_KERNEL_H

#include <stdint.h>
#include <string.h>

#define OBSFMU_KERNEL_ABI 1 /* = fmus.runtime.slave.kernel.KERNEL_ABI */
/* The matrices of this many step sizes are kept (= fmus.runtime.slave.kernel.SLOTS): an importer that steps
 * t_(k+1) - t_k, like fmusim, gives a few step sizes one ulp apart, alternating */
#define OBSFMU_KERNEL_SLOTS 8

/* The layout's header, in the order of fmus.runtime.slave.kernel.HEADER */
enum {
    KL_ABI, KL_N, KL_M, KL_COLUMNS, KL_Q, KL_PORTS, KL_VARIABLES,
    KL_TIME, KL_X, KL_W, KL_D, KL_PREVIOUS, KL_PREVIOUS_TIME, KL_MOVING, KL_OUT, KL_C, KL_DMATRIX, KL_E,
    KL_PHI, KL_G0, KL_G1, KL_H, KL_BOUND, KL_VALUES, KL_SCRATCH, KL_SIZE, KL_HEADER
};
/* classes of a value reference (the layout's table) */
enum { KV_PYTHON, KV_INPUT, KV_OUTPUT, KV_VALUE, KV_INTEGER };
/* <port>_interpolation (fmus.runtime.slave.common.InputMode) */
enum { KM_HOLD, KM_EXTRAPOLATE, KM_INTERPOLATE };

typedef struct {
    size_t n, m, columns, q, ports, variables;
    double *time, *x, *w, *d, *previous, *previous_time, *moving, *out, *C, *D, *e, *Phi, *G0, *G1, *h, *bound,
        *values, *scratch;
    const int64_t *start, *mode, *table; /* port starts (ports + 1), port modes, (class, index) per variable */
    int outputs_valid;                   /* out holds C x + D w + e of the present x and w */
    int slot;                            /* of the matrices: the one of the last step, or the one to fill next */
} KernelImage;

/* Bind the image to the slave's vectors; 0 when they fit each other, -1 (and the image unusable) otherwise. */
static int kernel_bind(KernelImage *k, double *memory, size_t memory_size, const int64_t *layout, size_t layout_size)
{
    memset(k, 0, sizeof *k);
    if (layout_size < KL_HEADER || layout[KL_ABI] != OBSFMU_KERNEL_ABI || layout[KL_SIZE] != (int64_t)memory_size)
        return -1;
    for (int field = KL_N; field < KL_HEADER; field++)
        if (layout[field] < 0 || layout[field] > (int64_t)memory_size) return -1;
    k->n = (size_t)layout[KL_N], k->m = (size_t)layout[KL_M], k->columns = (size_t)layout[KL_COLUMNS];
    k->q = (size_t)layout[KL_Q], k->ports = (size_t)layout[KL_PORTS], k->variables = (size_t)layout[KL_VARIABLES];
    if (k->columns < k->m || k->columns > k->m + 1 ||
        layout_size != KL_HEADER + (k->ports + 1) + k->ports + 2 * k->variables ||
        (size_t)layout[KL_SCRATCH] + k->n + 2 * k->columns + k->m + k->q > memory_size)
        return -1;
    double **fields[] = {&k->time, &k->x, &k->w, &k->d, &k->previous, &k->previous_time, &k->moving, &k->out, &k->C,
                         &k->D, &k->e, &k->Phi, &k->G0, &k->G1, &k->h, &k->bound, &k->values, &k->scratch};
    for (int field = KL_TIME; field <= KL_SCRATCH; field++) *fields[field - KL_TIME] = memory + layout[field];
    k->start = layout + KL_HEADER;
    k->mode = k->start + k->ports + 1;
    k->table = k->mode + k->ports;
    if (k->start[0] != 0 || (size_t)k->start[k->ports] != k->m) return -1;
    for (size_t i = 0; i < k->variables; i++) {
        int64_t kind = k->table[2 * i], index = k->table[2 * i + 1];
        if ((kind == KV_INPUT && (index < 0 || (size_t)index >= k->m)) ||
            (kind == KV_OUTPUT && (index < 0 || (size_t)index >= k->q)) ||
            ((kind == KV_VALUE || kind == KV_INTEGER) && (size_t)index != i))
            return -1;
    }
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
        if (kernel_class(k, vr[i], &index) != KV_INPUT || (order != NULL && order[i] != 1) || !kernel_within(value[i], *k->bound))
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

/* y = A x (+ y when add), A rows x columns, row-major */
static void kernel_product(const double *A, const double *x, size_t rows, size_t columns, double *y, int add)
{
    for (size_t i = 0; i < rows; i++) {
        double sum = 0.0;
        for (size_t j = 0; j < columns; j++) sum += A[i * columns + j] * x[j];
        y[i] = add ? y[i] + sum : sum;
    }
}

/* out = C x + D w + e of this x and w */
static void kernel_outputs(const KernelImage *k, const double *x, const double *w, double *out)
{
    kernel_product(k->C, x, k->q, k->n, out, 0);
    kernel_product(k->D, w, k->q, k->m, out, 1);
    for (size_t i = 0; i < k->q; i++) out[i] += k->e[i];
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

/* fmi2GetReal: 1 when every value reference is an input, an output or a parameter (then read); 0 otherwise. */
static int kernel_get(KernelImage *k, const unsigned vr[], size_t nvr, double value[])
{
    size_t index;
    if (!kernel_readable(k, vr, nvr)) return 0;
    if (!k->outputs_valid) {
        kernel_outputs(k, k->x, k->w, k->out);
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

/* fmi2DoStep from t (the instance's time: the loader checked it) of size h.  1: stepped (state, inputs, their
 * record and the outputs at the step end); 0: not for the kernel, nothing changed (a bad step size, a value that
 * is not finite or beyond the bound: the Python path refuses it, naming it); -1: the matrices of this h are
 * needed first, into slot k->slot (the slave's kernel_matrices(h, slot)), nothing changed. */
static int kernel_step(KernelImage *k, double t, double h)
{
    if (!(h > 0.0 && h <= 1.7976931348623157e308 && t == t)) return 0;
    if (k->n && k->h[k->slot] != h) {
        int found = -1;
        for (int slot = 0; slot < OBSFMU_KERNEL_SLOTS && found < 0; slot++)
            if (k->h[slot] == h) found = slot;
        if (found < 0) {                         /* the slave fills the next slot, round robin */
            k->slot = (k->slot + 1) % OBSFMU_KERNEL_SLOTS;
            return -1;
        }
        k->slot = found;
    }
    const double *Phi = k->Phi + (size_t)k->slot * k->n * k->n, *G0 = k->G0 + (size_t)k->slot * k->n * k->columns,
                 *G1 = k->G1 + (size_t)k->slot * k->n * k->columns;
    double *next = k->scratch, *w0 = next + k->n, *dw = w0 + k->columns, *end = dw + k->columns, *out = end + k->m;
    kernel_segments(k, t, h, w0, dw, end);
    kernel_product(Phi, k->x, k->n, k->n, next, 0);
    kernel_product(G0, w0, k->n, k->columns, next, 1);
    kernel_product(G1, dw, k->n, k->columns, next, 1);
    kernel_outputs(k, next, end, out);
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
