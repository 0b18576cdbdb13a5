/*
 * KK_LTV: the step of paper 001's adaptive observer (observers/ltv/observer.py) in C, least squares (issue 39);
 * KK_LTV_PLANT (end of the file): its plant.  Included by kernel.h; the image's x is the block's whole state packed
 * into one vector (observers/ltv/kernel.py), settings its sizes, gains and the offsets of every part, p the
 * constants of its compiled functions A(t), L(t), f(y, t), C(t) (the FMU's kernel library: g, l, f, c), or C itself
 * when it is constant, and of Theta.
 *
 * One communication step, as LTVAdaptiveObserver.advance, operation for operation:
 *   - the inputs y and u as the polynomials through their last samples (stepping.PolynomialInputs.step);
 *   - the sub-step count (integrators.substep_count), y at the sub-steps' points, resolving the fast part
 *     m f(y) drives when f_correction (stepping.resolved_output, IntegralSamples);
 *   - the filters S' = A0(t) S + G(t) by RK4 with its dense output at the Gauss nodes (stepping.rk4_linear);
 *   - the regression (7) at the nodes, weighted by the quadrature weights (observer._quadrature_weights), and the
 *     least-squares information step (estimation/least_squares.py: P, Theta_hat, lambda_min(P), e^{-beta t}).
 * Matrix products, the solve and the smallest eigenvalue are computed here in plain loops where numpy calls BLAS
 * and LAPACK: the two paths agree to round-off, not to the bit (tests/fmus/native/test_kernels.py).  Anything the
 * kernel cannot vouch for -- a value not finite or beyond the bound, the budget exceeded, A0 not stable, the gain
 * bound M met (F frozen), a sample time whose rounding to 12 decimals is a tie -- returns 0: the Python path takes
 * that step and refuses it, or carries it out, in its own words.
 */
#ifndef OBSFMU_KERNEL_LTV_H
#define OBSFMU_KERNEL_LTV_H

/* The settings of an LTV image (= observers.ltv.kernel.SETTINGS) */
enum {
    KT_N, KT_P, KT_R, KT_DEGREE, KT_F_CORRECTION, KT_F_TIME, KT_C_VARIES, KT_MAX_SUBSTEP, KT_MAX_DY, KT_BUDGET, KT_GAMMA, KT_BETA,
    KT_F0, KT_M, KT_INITIAL_ERROR, KT_TOLERANCE, KT_EPSILON, KT_STEP_RATE, KT_PHI_LIMIT, KT_SIGNAL_BOUND, KT_INPUT_U,
    KT_INPUT_Y, KT_X_S, KT_X_THETA, KT_X_P, KT_X_LAMBDA, KT_X_DECAY, KT_X_U, KT_X_Y, KT_X_INTEGRAL, KT_X_MEMO,
    KT_X_LONGEST, KT_X_NOTED, KT_X_SIZE, KT_P_F, KT_P_A, KT_P_L, KT_P_C, KT_P_WHERE, KT_P_KNOWN, KT_P_POINTS,
    KT_P_SIZE, KT_COUNT
};
/* p at KT_P_POINTS: stepping.SUBSTEP_POINTS (4), then RK4's dense weights (b1, b23, b4) at each of them (12) */
#define KT_POINTS 4
#define KT_MAX_DEGREE 5

typedef struct {
    const KernelImage *k;
    size_t n, np, r, full, columns, d;     /* state, nonlinearities, unknowns, Theta, columns of S, input degree */
    const double *s, *C, *where, *known, *points, *dense;
    const double *pf;                      /* the constants of f */
    int f_time, c_varies;                  /* f is f(t, y); C is C(t) (C: the constants of its function) */
    double bound;
} Ltv;

typedef struct {
    double c[KT_MAX_DEGREE + 2];
    int size; /* coefficients */
    double h;
} Poly;

static double (*volatile kt_pow)(double, double) = pow; /* Python's float ** float: libm's pow, never folded */

static double kt_at(const Poly *q, double s)
{
    double value = 0.0;
    for (int k = q->size - 1; k >= 0; k--) value = value * s + q->c[k];
    return value;
}

/* InputPolynomial.max_rate */
static double kt_max_rate(const Poly *q)
{
    double sum = 0.0;
    for (int k = 1; k < q->size; k++) sum += (double)k * fabs(q->c[k]) * kt_pow(q->h, (double)(k - 1));
    return sum;
}

/* Python's round(x, 12) into *out; 0 when it cannot be told here (a tie at 12 decimals, or |x| too large) */
static int kt_round12(double x, double *out)
{
    double scaled = x * 1e12;
    if (!(fabs(scaled) < 1e14)) return 0;
    double fraction = scaled - floor(scaled);
    if (fabs(fraction - 0.5) < 1e-3) return 0;
    *out = nearbyint(scaled) / 1e12;
    return 1;
}

/* The inverse of the Vandermonde matrix of nodes (increasing powers) into rows (size x size); 0 when singular */
static int kt_monomial_map(const double *nodes, int size, double *rows)
{
    double a[(KT_MAX_DEGREE + 2) * (KT_MAX_DEGREE + 2)];
    for (int i = 0; i < size; i++) {
        double power = 1.0;
        for (int j = 0; j < size; j++) {
            a[i * size + j] = power, power *= nodes[i];
            rows[i * size + j] = i == j;
        }
    }
    for (int col = 0; col < size; col++) { /* Gauss-Jordan, partial pivoting */
        int pivot = col;
        for (int i = col + 1; i < size; i++)
            if (fabs(a[i * size + col]) > fabs(a[pivot * size + col])) pivot = i;
        if (a[pivot * size + col] == 0.0) return 0;
        for (int j = 0; j < size; j++) {
            double swap = a[col * size + j];
            a[col * size + j] = a[pivot * size + j], a[pivot * size + j] = swap;
            swap = rows[col * size + j];
            rows[col * size + j] = rows[pivot * size + j], rows[pivot * size + j] = swap;
        }
        double scale = a[col * size + col];
        for (int j = 0; j < size; j++) a[col * size + j] /= scale, rows[col * size + j] /= scale;
        for (int i = 0; i < size; i++) {
            if (i == col) continue;
            double factor = a[i * size + col];
            for (int j = 0; j < size; j++) {
                a[i * size + j] -= factor * a[col * size + j];
                rows[i * size + j] -= factor * rows[col * size + j];
            }
        }
    }
    return 1;
}

/* integrators.substep_count(h, max_substep, rate, max_change, budget): equal sub-steps each at most max_substep long,
 * over which a signal changing at rate changes by at most max_change; 0 when more than budget are needed (the
 * Python path refuses that step, naming substep_budget) */
static size_t kt_substep_count(double h, double max_substep, double rate, double max_change, double budget)
{
    double by_length = h / max_substep, by_change = rate != 0.0 ? fabs(rate) * h / max_change : 0.0;
    double limit = budget * (1.0 + 1e-9);
    if (!(by_length <= limit && by_change <= limit)) return 0;
    double counted = fmax(ceil(by_length - 1e-9), ceil(by_change - 1e-9));
    return counted > 1.0 ? (size_t)counted : 1;
}

/* The polynomial through (nodes in units of h, values): coefficient k = sum_i rows[k][i] values[i] / h^k */
static int kt_through(const double *nodes, const double *values, int size, double h, Poly *q)
{
    double rows[(KT_MAX_DEGREE + 2) * (KT_MAX_DEGREE + 2)];
    if (!kt_monomial_map(nodes, size, rows)) return 0;
    for (int k = 0; k < size; k++) {
        double sum = 0.0;
        for (int i = 0; i < size; i++) sum += rows[k * size + i] * values[i];
        q->c[k] = sum / kt_pow(h, (double)k);
    }
    q->size = size, q->h = h;
    return 1;
}

/* A history of samples (PolynomialInputs' and IntegralSamples' layout): [count, times (d + 1), values (d + 1)] */
static const double *kt_times(const Ltv *L, const double *history) { return history + 1 + L->d + 1 - (size_t)history[0]; }
static const double *kt_values(const Ltv *L, const double *history) { return history + 2 * (L->d + 1) + 1 - (size_t)history[0]; }

/* The history after a step: times, values (count of them) then (t + h, end), the last d + 1 kept, zeros in front */
static void kt_history(const Ltv *L, double *after, const double *times, const double *values, size_t count,
                       double next_time, double end)
{
    size_t size = L->d + 1, kept = count + 1 > size ? size : count + 1, skip = count + 1 - kept;
    memset(after, 0, (2 * size + 1) * sizeof *after);
    after[0] = (double)kept;
    for (size_t i = 0; i < kept; i++) {
        size_t j = skip + i;
        after[1 + size - kept + i] = j < count ? times[j] : next_time;
        after[1 + 2 * size - kept + i] = j < count ? values[j] : end;
    }
}

/* PolynomialInputs.step for one input: its polynomial over [t, t + h] and its history after the step */
static int kt_input(const Ltv *L, const double *history, double t, double h, double start, double slope, Poly *q,
                    double *after)
{
    double end = start + h * slope, bound = L->bound;
    if (!(fabs(start) <= bound && fabs(end) <= bound && isfinite(slope) && isfinite(t + h))) return 0;
    size_t count = (size_t)history[0];
    const double *times = kt_times(L, history), *values = kt_values(L, history);
    int continues = count > 0 && fabs(times[count - 1] - t) <= 1e-9 * fmax(1.0, fabs(t)) &&
                    fabs(values[count - 1] - start) <=
                        1e-12 * fmax(fmax(1.0, fabs(start)), fabs(values[count - 1]));
    double T[KT_MAX_DEGREE + 1], V[KT_MAX_DEGREE + 2], nodes[KT_MAX_DEGREE + 2];
    size_t size = 1;
    T[0] = t, V[0] = start;
    if (continues) {
        size = count < L->d ? count : L->d;
        memcpy(T, times + count - size, size * sizeof *T);
        memcpy(V, values + count - size, size * sizeof *V);
    }
    for (size_t i = 0; i < size; i++)
        if (!kt_round12((T[i] - t) / h, &nodes[i])) return 0;
    nodes[size] = 1.0;
    for (size_t i = 0; i <= size; i++)
        for (size_t j = 0; j < i; j++)
            if (nodes[i] == nodes[j]) size = 1, T[0] = t, V[0] = start; /* the samples coincide at its scale */
    if (size == 1) {
        q->c[0] = start, q->c[1] = slope, q->size = 2, q->h = h;
    } else {
        V[size] = end;
        if (!kt_through(nodes, V, (int)size + 1, h, q)) return 0;
    }
    kt_history(L, after, T, V, size, t + h, end);
    return 1;
}

/* f_1 .. f_p at (t, y) (Nonlinearities.values: f(y) unless f depends on t) */
static void kt_f(const Ltv *L, double t, double y, double *out)
{
    double none = 0.0;
    L->k->f(L->f_time ? t : 0.0, &y, &none, L->pf, out);
}

/* C(t) of y = C^T(t) x (model.OutputVector.at): the constant, or its compiled function at t into buffer */
static const double *kt_output_vector(const Ltv *L, double t, double *buffer)
{
    double none = 0.0;
    if (!L->c_varies) return L->C;
    L->k->c(t, &none, &none, L->C, buffer);
    return buffer;
}

/* IntegralSamples.at(times): I(time) - I(times[-1]) into past; 0 when unknown (a time that is not a sample) or when
 * Python's 12-decimal keys cannot be told from here (a time within 2e-12 of a sample but not equal to it). */
static int kt_integral_at(const Ltv *L, const double *integral, const double *times, size_t count, double *past)
{
    size_t stored = (size_t)integral[0];
    const double *at = kt_times(L, integral), *values = kt_values(L, integral);
    double found[KT_MAX_DEGREE + 2];
    for (size_t i = 0; i < count; i++) {
        int hit = 0;
        for (size_t j = stored; j-- > 0 && !hit;) {
            double gap = fabs(at[j] - times[i]);
            if (gap == 0.0) found[i] = values[j], hit = 1;
            else if (gap <= 2e-12) return 0;
        }
        if (!hit) return -1;
    }
    for (size_t i = 0; i < count; i++) past[i] = found[i] - found[count - 1];
    return 1;
}

/* without_fast_part of resolved_output: q = p - mu Pi J (Pi J through the values past + [J_end]) */
static void kt_without_fast_part(const Poly *y, const double *rows, int size, const double *past, double J_end,
                                 double mu, Poly *q)
{
    double values[KT_MAX_DEGREE + 2];
    memcpy(values, past, (size_t)(size - 1) * sizeof *values);
    values[size - 1] = J_end;
    *q = *y;
    for (int k = y->size; k < size; k++) q->c[k] = 0.0;
    if (size > q->size) q->size = size;
    for (int k = 0; k < size; k++) {
        double sum = 0.0;
        for (int i = 0; i < size; i++) sum += rows[k * size + i] * values[i];
        q->c[k] -= mu * sum / kt_pow(y->h, (double)k);
    }
}

/* One sub-step i of _rk4_integral: J' = f(q(s) + mu J) from J; J at the sub-step's points into points (may be
 * NULL); returns J at its end */
static double kt_integral_substep(const Ltv *L, const Poly *q, double mu, double dt, size_t i, double J, double *points)
{
    double s = (double)i * dt, middle = kt_at(q, s + 0.5 * dt), k1, k2, k3, k4, value;
    kt_f(L, 0.0, kt_at(q, s) + mu * J, &k1);
    kt_f(L, 0.0, middle + mu * (J + 0.5 * dt * k1), &k2);
    kt_f(L, 0.0, middle + mu * (J + 0.5 * dt * k2), &k3);
    kt_f(L, 0.0, kt_at(q, s + dt) + mu * (J + dt * k3), &k4);
    double end = J;
    for (int point = 0; point < KT_POINTS; point++) {
        const double *b = L->dense + 3 * point;
        value = J + dt * (b[0] * k1 + b[1] * (k2 + k3) + b[2] * k4);
        if (points) points[point] = value;
        if (point == 1) end = value;
    }
    return end;
}

/* How y is known inside the step (observer._output_inside): the polynomial, or with f_correction the polynomial q
 * without the fast part and the integrator of J, run again in step with the filters (resolved_output's 2nd pass) */
typedef struct {
    Poly y, q;
    int resolved;
    double mu, J;
} Inside;

/* y at the points of sub-step i (advancing the integral's J when resolved) */
static void kt_y_points(const Ltv *L, Inside *in, double dt, size_t i, double *y)
{
    if (!in->resolved) {
        for (int point = 0; point < KT_POINTS; point++) y[point] = kt_at(&in->y, ((double)i + L->points[point]) * dt);
        return;
    }
    double J[KT_POINTS];
    in->J = kt_integral_substep(L, &in->q, in->mu, dt, i, in->J, J);
    for (int point = 0; point < KT_POINTS; point++)
        y[point] = kt_at(&in->y, ((double)i + L->points[point]) * dt) + in->mu * J[point];
}

/* resolved_output and IntegralSamples.after: *in ready for kt_y_points, the integral's history after the step */
static int kt_resolve(const Ltv *L, const double *state, const double *y_after, double t, double h, size_t count,
                      const double *full, Inside *in, double *integral_after)
{
    double dt = h / (double)count, J_end = 0.0, value;
    in->resolved = 0, in->J = 0.0;
    const double *integral = state + (size_t)L->s[KT_X_INTEGRAL];
    if (L->s[KT_F_CORRECTION] == 0.0) {
        memcpy(integral_after, integral, (2 * L->d + 3) * sizeof *integral_after);
        return 1;
    }
    double mu = 0.0;
    for (size_t i = 0; i < L->n; i++) mu += L->C[i] * full[3 * L->n + i];
    size_t size = (size_t)y_after[0];
    const double *times = kt_times(L, y_after);
    double past[KT_MAX_DEGREE + 2];
    int known = fabs(mu) * h <= 0.5 ? kt_integral_at(L, integral, times, size - 1, past) : -1;
    if (known == 0) return 0;
    for (size_t i = 0; i < count; i++)
        for (int point = 2; point < KT_POINTS; point++) {
            kt_f(L, 0.0, kt_at(&in->y, ((double)i + L->points[point]) * dt), &value);
            J_end += 0.5 * dt * value;
        }
    if (known > 0 && mu != 0.0) {
        double nodes[KT_MAX_DEGREE + 2], rows[(KT_MAX_DEGREE + 2) * (KT_MAX_DEGREE + 2)];
        for (size_t i = 0; i < size; i++)
            if (!kt_round12((times[i] - times[size - 2]) / h, &nodes[i])) return 0;
        if (!kt_monomial_map(nodes, (int)size, rows)) return 0;
        for (int pass = 0; pass < 2; pass++) { /* J(h) from f(p), then from the first pass */
            kt_without_fast_part(&in->y, rows, (int)size, past, J_end, mu, &in->q);
            double J = 0.0;
            for (size_t i = 0; i < count; i++) J = kt_integral_substep(L, &in->q, mu, dt, i, J, NULL);
            if (pass == 0) J_end = J;
            else { /* the second pass's q gives the points; y through the final J(h) */
                kt_without_fast_part(&in->y, rows, (int)size, past, J, mu, &in->y);
                J_end = J;
            }
        }
        in->resolved = 1, in->mu = mu;
    }
    /* IntegralSamples.after(t, h, change = J_end) */
    size_t stored = (size_t)integral[0];
    const double *at = kt_times(L, integral), *values = kt_values(L, integral);
    double restart_time = t, restart_value = 0.0;
    if (!(stored && fabs(at[stored - 1] - t) <= 1e-9 * fmax(1.0, fabs(t)))) at = &restart_time, values = &restart_value,
                                                                                 stored = 1;
    double total = values[stored - 1] + J_end;
    if (!(fabs(total) <= L->bound && isfinite(t + h))) return 0;
    kt_history(L, integral_after, at, values, stored, t + h, total);
    return 1;
}

/* (A0(t), G(t)) of the filters (observer._evaluate): A0 = A(t) - L(t) C^T, G = [L y, 0, I y, I u, I f_1, ...] */
static void kt_evaluate(const Ltv *L, double t, double y, double u, double *A0, double *G)
{
    size_t n = L->n, W = L->columns;
    double gain[64], none = 0.0, values[2 + 32], buffer[32];
    const double *p = L->k->p, *C = kt_output_vector(L, t, buffer);
    L->k->g(t, &none, &none, p + (size_t)L->s[KT_P_A], A0);
    L->k->l(t, &none, &none, p + (size_t)L->s[KT_P_L], gain);
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++) A0[i * n + j] -= gain[i] * C[j];
    values[0] = y, values[1] = u;
    kt_f(L, t, y, values + 2);
    memset(G, 0, n * W * sizeof *G);
    for (size_t i = 0; i < n; i++) {
        G[i * W] = gain[i] * y;
        for (size_t k = 0; k < 2 + L->np; k++) G[i * W + 1 + (k + 1) * n + i] = values[k];
    }
}

/* out = A0 S + G (n x W) */
static void kt_slope(const Ltv *L, const double *A0, const double *S, const double *G, double *out)
{
    size_t n = L->n, W = L->columns;
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < W; j++) {
            double sum = 0.0;
            for (size_t l = 0; l < n; l++) sum += A0[i * n + l] * S[l * W + j];
            out[i * W + j] = sum + G[i * W + j];
        }
}

/* phi1(x) = (1 - e^-x) / x (estimation/exponential.py) */
static double kt_phi1(double x) { return x == 0.0 ? 1.0 : -expm1(-x) / x; }

/* The smallest eigenvalue of the symmetric r x r matrix a (destroyed): cyclic Jacobi */
static double kt_smallest_eigenvalue(double *a, size_t r)
{
    for (int sweep = 0; sweep < 100; sweep++) {
        double off = 0.0, diagonal = 0.0;
        for (size_t i = 0; i < r; i++) {
            diagonal += a[i * r + i] * a[i * r + i];
            for (size_t j = i + 1; j < r; j++) off += a[i * r + j] * a[i * r + j];
        }
        if (off <= 1e-36 * diagonal || off == 0.0) break;
        for (size_t p = 0; p < r; p++)
            for (size_t q = p + 1; q < r; q++) {
                double apq = a[p * r + q];
                if (apq == 0.0) continue;
                double theta = (a[q * r + q] - a[p * r + p]) / (2.0 * apq);
                double tangent = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(tangent * tangent + 1.0), s = tangent * c;
                for (size_t k = 0; k < r; k++) { /* columns p, q */
                    double akp = a[k * r + p], akq = a[k * r + q];
                    a[k * r + p] = c * akp - s * akq, a[k * r + q] = s * akp + c * akq;
                }
                for (size_t k = 0; k < r; k++) { /* rows p, q */
                    double apk = a[p * r + k], aqk = a[q * r + k];
                    a[p * r + k] = c * apk - s * aqk, a[q * r + k] = s * apk + c * aqk;
                }
            }
    }
    double smallest = a[0];
    for (size_t i = 1; i < r; i++)
        if (a[i * r + i] < smallest) smallest = a[i * r + i];
    return smallest;
}

/* x = a^-1 b by Gaussian elimination with partial pivoting (a, b destroyed); 0 when singular */
static int kt_solve(double *a, double *b, size_t r, double *x)
{
    for (size_t col = 0; col < r; col++) {
        size_t pivot = col;
        for (size_t i = col + 1; i < r; i++)
            if (fabs(a[i * r + col]) > fabs(a[pivot * r + col])) pivot = i;
        if (a[pivot * r + col] == 0.0) return 0;
        if (pivot != col) {
            for (size_t j = 0; j < r; j++) {
                double swap = a[col * r + j];
                a[col * r + j] = a[pivot * r + j], a[pivot * r + j] = swap;
            }
            double swap = b[col];
            b[col] = b[pivot], b[pivot] = swap;
        }
        for (size_t i = col + 1; i < r; i++) {
            double factor = a[i * r + col] / a[col * r + col];
            for (size_t j = col; j < r; j++) a[i * r + j] -= factor * a[col * r + j];
            b[i] -= factor * b[col];
        }
    }
    for (size_t i = r; i-- > 0;) {
        double sum = b[i];
        for (size_t j = i + 1; j < r; j++) sum -= a[i * r + j] * x[j];
        x[i] = sum / a[i * r + i];
    }
    return 1;
}

static Ltv kt_of(const KernelImage *k)
{
    Ltv L;
    const double *s = k->settings;
    L.k = k, L.s = s;
    L.n = (size_t)s[KT_N], L.np = (size_t)s[KT_P], L.r = (size_t)s[KT_R], L.d = (size_t)s[KT_DEGREE];
    L.full = (3 + L.np) * L.n, L.columns = 1 + L.full;
    L.C = k->p + (size_t)s[KT_P_C], L.where = k->p + (size_t)s[KT_P_WHERE], L.known = k->p + (size_t)s[KT_P_KNOWN];
    L.points = k->p + (size_t)s[KT_P_POINTS], L.dense = L.points + KT_POINTS;
    L.pf = k->p + (size_t)s[KT_P_F], L.f_time = s[KT_F_TIME] != 0.0, L.c_varies = s[KT_C_VARIES] != 0.0;
    L.bound = s[KT_SIGNAL_BOUND];
    return L;
}

/* [-x0; k; b; m]: the estimates, and the known values where known (observer.full_theta) */
static void kt_full_theta(const Ltv *L, const double *theta, double *full)
{
    for (size_t j = 0; j < L->full; j++) full[j] = L->where[j] >= 0 ? theta[(size_t)L->where[j]] : L->known[j];
}

/* The work doubles a step needs (kernel_bind checks them against the scratch) */
static size_t kt_work_size(const Ltv *L)
{
    size_t nW = L->n * L->columns, r = L->r;
    return 7 * nW + 3 * (L->n * L->n + nW) + 3 * r * r + 3 * r + 2 * L->full + 8;
}

/* The image fits: sizes and offsets within x, p and the scratch (kernel_bind) */
static int kt_fits(const KernelImage *k)
{
    if (k->n < 1 || k->settings == NULL) return 0;
    const double *s = k->settings;
    for (int i = 0; i < KT_COUNT; i++)
        if (!(s[i] >= 0.0)) return 0;
    Ltv L = kt_of(k);
    if (L.n < 1 || L.n > 32 || L.np < 1 || L.np > 30 || L.r < 1 || L.r > L.full || L.d < 1 || L.d > KT_MAX_DEGREE ||
        (size_t)s[KT_X_SIZE] != k->n || (size_t)s[KT_X_NOTED] >= k->n || (size_t)s[KT_X_LONGEST] >= k->n || (size_t)s[KT_P_SIZE] != k->parameters || s[KT_INPUT_U] >= (double)k->m ||
        s[KT_INPUT_Y] >= (double)k->m || (size_t)s[KT_P_POINTS] + 4 * KT_POINTS > k->parameters ||
        (size_t)s[KT_P_WHERE] + L.full > k->parameters || (size_t)s[KT_P_KNOWN] + L.full > k->parameters ||
        (size_t)s[KT_X_MEMO] + 4 + L.n * L.n + L.n * L.columns > (size_t)s[KT_X_SIZE] ||
        k->q != (4 + L.np) * L.n + L.r + 3)
        return 0;
    return kt_work_size(&L) <= 7 * k->n + k->m;
}

/* The outputs of the packed state x (observer.outputs, and the slave's _vouched when step_rate): x_hat, theta_hat,
 * k_hat, b_hat, m_hat, x0_hat, F_max, excitation, converged.  Returns 1 when converged is held at 0 by the
 * communication step (the slave logs that once). */
static int kt_outputs(const KernelImage *k, const double *x, double *out)
{
    Ltv L = kt_of(k);
    const double *s = L.s, *S = x + (size_t)s[KT_X_S], *theta = x + (size_t)s[KT_X_THETA];
    size_t n = L.n, W = L.columns;
    double full[4 * 32 * 32], lambda = x[(size_t)s[KT_X_LAMBDA]], decay = x[(size_t)s[KT_X_DECAY]];
    kt_full_theta(&L, theta, full);
    for (size_t i = 0; i < n; i++) {
        double sum = 0.0;
        for (size_t j = 0; j < L.full; j++) sum += S[i * W + 1 + j] * full[j];
        out[i] = S[i * W] + sum;
    }
    out += n;
    memcpy(out, theta, L.r * sizeof *out);
    out += L.r;
    memcpy(out, full + n, (L.full - n) * sizeof *out);                 /* k_hat, b_hat, m_hat */
    out += L.full - n;
    for (size_t i = 0; i < n; i++) out[i] = -full[i];                  /* x0_hat */
    out += n;
    double bound = s[KT_F0] * decay * s[KT_INITIAL_ERROR] / lambda;   /* LeastSquaresForgetting.error_bound */
    if (s[KT_EPSILON] > 0.0) bound += s[KT_EPSILON] * sqrt(s[KT_GAMMA] * (1.0 - decay) / (s[KT_BETA] * lambda));
    int converged = bound <= s[KT_TOLERANCE], held = 0;
    if (s[KT_STEP_RATE] != 0.0) {
        double product = x[(size_t)s[KT_X_LONGEST]] * s[KT_STEP_RATE];
        held = converged && product * product / 3.0 > s[KT_TOLERANCE];
        if (held) converged = 0;
    }
    out[0] = 1.0 / lambda, out[1] = lambda / s[KT_GAMMA], out[2] = converged;
    return held;
}

/* One communication step of the packed state from t of size h (inputs w0 + s dw) into next; 1 taken, 0 not for
 * the kernel (nothing changed) */
static int kernel_ltv(KernelImage *k, double t, double h, const double *w0, const double *dw, double *next,
                      double *work)
{
    Ltv L = kt_of(k);
    const double *s = L.s, *x = k->x;
    size_t n = L.n, W = L.columns, nW = n * W, r = L.r;
    if (x[(size_t)s[KT_X_LAMBDA]] * s[KT_M] < 1.0) return 0; /* the gain bound met: F frozen, Python's law */
    memcpy(next, x, k->n * sizeof *next);
    Poly u, y;
    size_t iu = (size_t)s[KT_INPUT_U], iy = (size_t)s[KT_INPUT_Y];
    double *u_after = next + (size_t)s[KT_X_U], *y_after = next + (size_t)s[KT_X_Y];
    if (!kt_input(&L, x + (size_t)s[KT_X_U], t, h, w0[iu], dw[iu], &u, u_after) ||
        !kt_input(&L, x + (size_t)s[KT_X_Y], t, h, w0[iy], dw[iy], &y, y_after))
        return 0;
    /* substep_count(h, max_substep, y.max_rate(), max_dy, budget) */
    size_t count = kt_substep_count(h, s[KT_MAX_SUBSTEP], kt_max_rate(&y), s[KT_MAX_DY], s[KT_BUDGET]);
    if (count == 0) return 0;
    double dt = h / (double)count;
    /* the work: slopes, stage, node, three evaluations, the estimator's sums and its solve */
    double *k1 = work, *k2 = k1 + nW, *k3 = k2 + nW, *k4 = k3 + nW, *stage = k4 + nW, *node = stage + nW;
    double *A0s = node + nW, *Gs = A0s + n * n, *A0m = Gs + nW, *Gm = A0m + n * n, *A0e = Gm + nW, *Ge = A0e + n * n;
    double *PtP = Ge + nW, *Ptr = PtP + r * r, *Pn = Ptr + r, *solved = Pn + r * r, *copy = solved + r;
    double *full = copy + r * r, *row = full + L.full;
    const double *theta = x + (size_t)s[KT_X_THETA];
    kt_full_theta(&L, theta, full);
    Inside in;
    in.y = y;
    if (!kt_resolve(&L, x, y_after, t, h, count, full, &in, next + (size_t)s[KT_X_INTEGRAL])) return 0;
    /* the memo: the end of the previous step's last sub-step when this step continues it (observer._continues) */
    const double *memo = x + (size_t)s[KT_X_MEMO];
    double key[3] = {t, y.c[0], u.c[0]};
    int continues = memo[0] != 0.0;
    for (int i = 0; i < 3 && continues; i++) continues = fabs(memo[1 + i] - key[i]) <= 1e-12 * fmax(1.0, fabs(memo[1 + i]));
    if (continues) {
        memcpy(A0s, memo + 4, n * n * sizeof *A0s);
        memcpy(Gs, memo + 4 + n * n, nW * sizeof *Gs);
    } else {
        kt_evaluate(&L, t, y.c[0], u.c[0], A0s, Gs);
    }
    double *S = next + (size_t)s[KT_X_S];
    double beta = s[KT_BETA], scale = h * kt_phi1(beta * h);
    memset(PtP, 0, (r * r + r) * sizeof *PtP);
    for (size_t i = 0; i < count; i++) {
        double points[KT_POINTS];
        kt_y_points(&L, &in, dt, i, points);
        kt_evaluate(&L, t + ((double)i + 0.5) * dt, points[0], kt_at(&u, ((double)i + 0.5) * dt), A0m, Gm);
        kt_evaluate(&L, t + (double)(i + 1) * dt, points[1], kt_at(&u, (double)(i + 1) * dt), A0e, Ge);
        /* rk4_linear */
        kt_slope(&L, A0s, S, Gs, k1);
        for (size_t j = 0; j < nW; j++) stage[j] = S[j] + 0.5 * dt * k1[j];
        kt_slope(&L, A0m, stage, Gm, k2);
        for (size_t j = 0; j < nW; j++) stage[j] = S[j] + 0.5 * dt * k2[j];
        kt_slope(&L, A0m, stage, Gm, k3);
        for (size_t j = 0; j < nW; j++) stage[j] = S[j] + dt * k3[j];
        kt_slope(&L, A0e, stage, Ge, k4);
        for (int g = 2; g < KT_POINTS; g++) { /* the regression (7) at the Gauss nodes, weighted */
            const double *b = L.dense + 3 * g;
            for (size_t j = 0; j < nW; j++) node[j] = S[j] + dt * (b[0] * k1[j] + b[1] * (k2[j] + k3[j]) + b[2] * k4[j]);
            double z = points[g], known = 0.0, residual, buffer[32];
            const double *C = kt_output_vector(&L, t + ((double)i + L.points[g]) * dt, buffer);
            for (size_t j = 0; j < W; j++) {
                double sum = 0.0;
                for (size_t l = 0; l < n; l++) sum += C[l] * node[l * W + j];
                if (j == 0) z -= sum;
                else row[j - 1] = sum;
            }
            for (size_t j = 0; j < L.full; j++)
                if (L.where[j] < 0) known += row[j] * L.known[j];
            z -= known;
            double weight = sqrt(0.5 * dt * exp(-beta * (h - ((double)i + L.points[g]) * dt)) / scale);
            double *Phi = row + L.full;
            for (size_t j = 0; j < L.full; j++)
                if (L.where[j] >= 0) Phi[(size_t)L.where[j]] = weight * row[j];
            residual = weight * z;
            for (size_t a = 0; a < r; a++) residual -= Phi[a] * theta[a];
            for (size_t a = 0; a < r; a++) {
                Ptr[a] += Phi[a] * residual;
                for (size_t b2 = 0; b2 < r; b2++) PtP[a * r + b2] += Phi[a] * Phi[b2];
            }
        }
        for (size_t j = 0; j < nW; j++) S[j] = S[j] + dt / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j]);
        memcpy(A0s, A0e, n * n * sizeof *A0s);
        memcpy(Gs, Ge, nW * sizeof *Gs);
    }
    double largest = 0.0;
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < W; j++) {
            if (!isfinite(S[i * W + j])) return 0; /* finite_signal("filters (2)-(6)") */
            if (j >= 1 && j <= n && fabs(S[i * W + j]) > largest) largest = fabs(S[i * W + j]);
        }
    if (largest > s[KT_PHI_LIMIT]) return 0;   /* A0 not stable: Python names L */
    /* the information step (LeastSquaresForgetting._information_step) */
    const double *P = x + (size_t)s[KT_X_P];
    double gain = s[KT_GAMMA] * h * kt_phi1(beta * h), forget = exp(-beta * h);
    for (size_t a = 0; a < r * r; a++) Pn[a] = forget * P[a] + gain * PtP[a];
    for (size_t a = 0; a < r; a++)
        for (size_t b2 = 0; b2 < r; b2++) copy[a * r + b2] = 0.5 * (Pn[a * r + b2] + Pn[b2 * r + a]);
    memcpy(Pn, copy, r * r * sizeof *Pn);
    for (size_t a = 0; a < r * r + r; a++)
        if (!isfinite(PtP[a])) return 0;
    if (!kt_solve(copy, Ptr, r, solved)) return 0;
    double *theta_next = next + (size_t)s[KT_X_THETA], *P_next = next + (size_t)s[KT_X_P];
    for (size_t a = 0; a < r; a++) theta_next[a] = theta[a] + gain * solved[a];
    memcpy(P_next, Pn, r * r * sizeof *Pn);
    memcpy(copy, Pn, r * r * sizeof *Pn);
    next[(size_t)s[KT_X_LAMBDA]] = kt_smallest_eigenvalue(copy, r);
    next[(size_t)s[KT_X_DECAY]] = x[(size_t)s[KT_X_DECAY]] * exp(-beta * h);
    /* the memo of the next step: (t + h, y(h), u(h)) and the last sub-step's end */
    double *memo_next = next + (size_t)s[KT_X_MEMO];
    memo_next[0] = 1.0, memo_next[1] = t + h, memo_next[2] = kt_at(&y, h), memo_next[3] = kt_at(&u, h);
    memcpy(memo_next + 4, A0s, n * n * sizeof *A0s);
    memcpy(memo_next + 4 + n * n, Gs, nW * sizeof *Gs);
    double *longest = next + (size_t)s[KT_X_LONGEST];
    if (h > *longest) *longest = h;
    return 1;
}

/* ------------------------------------------------------------------ KK_LTV_PLANT: paper 001's plant (plants/ltv.py)
 *
 * x' = A(t) x + k y + b u + sum_i m_i f_i(y, t), y = C^T x (constant C, no noise): the packed state is x and the
 * samples of u; a step is OutputNonlinearLTVPlant.advance -- u as its polynomial, substep_count from y' at the
 * start, integrators.rk4_step -- and the outputs y = C^T x, x, Theta. */

/* The settings of an LTV plant's image (= observers.ltv.kernel.PLANT_SETTINGS) */
enum {
    KQ_N, KQ_P, KQ_DEGREE, KQ_F_TIME, KQ_C_VARIES, KQ_MAX_SUBSTEP, KQ_MAX_DY, KQ_BUDGET, KQ_SIGNAL_BOUND, KQ_INPUT_U, KQ_STEP_RATE,
    KQ_X_X, KQ_X_U, KQ_X_LONGEST, KQ_X_NOTED, KQ_X_SIZE, KQ_P_F, KQ_P_A, KQ_P_C, KQ_P_KBM, KQ_P_THETA, KQ_P_NOISE,
    KQ_P_SIZE, KQ_COUNT
};

static Ltv kq_of(const KernelImage *k)
{
    Ltv L;
    const double *s = k->settings;
    memset(&L, 0, sizeof L);
    L.k = k, L.s = s;
    L.n = (size_t)s[KQ_N], L.np = (size_t)s[KQ_P], L.d = (size_t)s[KQ_DEGREE];
    L.full = (3 + L.np) * L.n;
    L.C = k->p + (size_t)s[KQ_P_C], L.pf = k->p + (size_t)s[KQ_P_F], L.f_time = s[KQ_F_TIME] != 0.0;
    L.c_varies = s[KQ_C_VARIES] != 0.0;
    L.bound = s[KQ_SIGNAL_BOUND];
    return L;
}

/* The image fits (kernel_bind) */
static int kq_fits(const KernelImage *k)
{
    if (k->settings == NULL) return 0;
    const double *s = k->settings;
    for (int i = 0; i < KQ_COUNT; i++)
        if (!(s[i] >= 0.0)) return 0;
    Ltv L = kq_of(k);
    size_t n = L.n;
    if (n < 1 || n > 32 || L.np < 1 || L.np > 30 || L.d < 1 || L.d > KT_MAX_DEGREE || (size_t)s[KQ_X_SIZE] != k->n ||
        (size_t)s[KQ_X_X] + n > k->n || (size_t)s[KQ_X_U] + 2 * L.d + 3 > k->n || (size_t)s[KQ_X_NOTED] >= k->n ||
        (size_t)s[KQ_P_SIZE] != k->parameters || (size_t)s[KQ_P_A] > k->parameters ||
        (size_t)s[KQ_P_C] + (L.c_varies ? 0 : n) > k->parameters || (size_t)s[KQ_P_KBM] + n * (2 + L.np) > k->parameters ||
        (size_t)s[KQ_P_THETA] + L.full > k->parameters || (size_t)s[KQ_P_NOISE] + 3 > k->parameters ||
        s[KQ_INPUT_U] >= (double)k->m || k->q != 1 + n + L.full)
        return 0;
    return 5 * n <= 7 * k->n + k->m;
}

/* plant.rate: A x + [k, b, m] (y, u, f_1(y, t), ...), y = C^T x */
static void kq_rate(const Ltv *L, const double *A, double t, const double *x, double u, double *out)
{
    size_t n = L->n, columns = 2 + L->np;
    const double *kbm = L->k->p + (size_t)L->s[KQ_P_KBM];
    double y = 0.0, values[2 + 30], buffer[32];
    const double *C = kt_output_vector(L, t, buffer);
    for (size_t i = 0; i < n; i++) y += C[i] * x[i];
    values[0] = y, values[1] = u;
    kt_f(L, t, y, values + 2);
    for (size_t i = 0; i < n; i++) {
        double ax = 0.0, forced = 0.0;
        for (size_t j = 0; j < n; j++) ax += A[i * n + j] * x[j];
        for (size_t j = 0; j < columns; j++) forced += kbm[i * columns + j] * values[j];
        out[i] = ax + forced;
    }
}

static void kq_A(const Ltv *L, double t, double *A)
{
    double none = 0.0;
    L->k->g(t, &none, &none, L->k->p + (size_t)L->s[KQ_P_A], A);
}

/* The plant's outputs: y = C^T x + v(t) (v: the measurement noise, plants.signals.SampledNoise.expression), x, Theta */
static int kq_outputs(const KernelImage *k, double t, const double *x, double *out)
{
    Ltv L = kq_of(k);
    double y = 0.0, buffer[32], none = 0.0, noise;
    const double *state = x + (size_t)L.s[KQ_X_X], *C = kt_output_vector(&L, t, buffer);
    for (size_t i = 0; i < L.n; i++) y += C[i] * state[i];
    k->v(t, &none, &none, k->p + (size_t)L.s[KQ_P_NOISE], &noise);
    out[0] = y + noise;
    memcpy(out + 1, state, L.n * sizeof *out);
    memcpy(out + 1 + L.n, k->p + (size_t)L.s[KQ_P_THETA], L.full * sizeof *out);
    return 0;
}

/* One communication step of the plant from t of size h into next; 1 taken, 0 not for the kernel */
static int kernel_ltv_plant(KernelImage *k, double t, double h, const double *w0, const double *dw, double *next,
                            double *work)
{
    Ltv L = kq_of(k);
    const double *s = L.s, *x = k->x;
    size_t n = L.n, iu = (size_t)s[KQ_INPUT_U];
    memcpy(next, x, k->n * sizeof *next);
    Poly u;
    if (!kt_input(&L, x + (size_t)s[KQ_X_U], t, h, w0[iu], dw[iu], &u, next + (size_t)s[KQ_X_U])) return 0;
    double A[32 * 32], *k1 = work, *k2 = k1 + n, *k3 = k2 + n, *k4 = k3 + n, *stage = k4 + n;
    double *X = next + (size_t)s[KQ_X_X];
    /* substep_count(h, max_substep, C^T x', max_dy, budget) */
    kq_A(&L, t, A);
    kq_rate(&L, A, t, X, u.c[0], k1);
    double dy = 0.0, buffer[32];
    const double *C = kt_output_vector(&L, t, buffer);
    for (size_t i = 0; i < n; i++) dy += C[i] * k1[i];
    size_t count = kt_substep_count(h, s[KQ_MAX_SUBSTEP], dy, s[KQ_MAX_DY], s[KQ_BUDGET]);
    if (count == 0) return 0;
    double dt = h / (double)count;
    for (size_t i = 0; i < count; i++) { /* integrators.rk4_step */
        double at = t + (double)i * dt, end = t + (double)(i + 1) * dt, middle = at + dt / 2;
        kq_A(&L, at, A);
        kq_rate(&L, A, at, X, kt_at(&u, at - t), k1);
        kq_A(&L, middle, A);
        for (size_t j = 0; j < n; j++) stage[j] = X[j] + dt / 2 * k1[j];
        kq_rate(&L, A, middle, stage, kt_at(&u, middle - t), k2);
        for (size_t j = 0; j < n; j++) stage[j] = X[j] + dt / 2 * k2[j];
        kq_rate(&L, A, middle, stage, kt_at(&u, middle - t), k3);
        kq_A(&L, end, A);
        for (size_t j = 0; j < n; j++) stage[j] = X[j] + dt * k3[j];
        kq_rate(&L, A, end, stage, kt_at(&u, end - t), k4);
        for (size_t j = 0; j < n; j++) X[j] = X[j] + dt / 6 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
    }
    for (size_t j = 0; j < n; j++)
        if (!isfinite(X[j])) return 0; /* Python names the unstable plant */
    return 1;
}

/* The image's C is a function of time (its kernel library must hold it) */
static int kt_c_varies(const KernelImage *k)
{
    return (k->kind == KK_LTV && k->settings[KT_C_VARIES] != 0.0) ||
           (k->kind == KK_LTV_PLANT && k->settings[KQ_C_VARIES] != 0.0);
}

#endif
