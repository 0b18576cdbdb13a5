/*
 * KK_NOISE_FILTER: band-limited noise (plants/noise.py) in C (issue 39).  Included by kernel.h.
 *
 * The held white samples w_k drive a low-pass discretised exactly, x_{k+1} = Ad x_k + Bd w_k, and the output on
 * interval k is z_k = x_k[0] (plus the input u on a connection).  The image's x packs the cache of the Python
 * block, (k, x_k) of the last interval reached (Noise.filter_form); p holds the parameters of the white samples
 * (std, dt, seed, and the uniform draw's low and width), then Ad and Bd.  w_k comes from the FMU's kernel library:
 * its g(t = k) writes the streams' samples of interval k, numpy's draws (observers/random_stream.py).  Each entry
 * of x_{k+1} is summed as plants.noise.filter_step sums it, so both paths give the same bits.
 *
 * The kernel only goes forward: an interval before the one reached (a state restored, Python's checkpoints), or
 * more filter steps than interval_budget (Python refuses, naming it), is the Python path's.
 */
#ifndef OBSFMU_KERNEL_NOISE_H
#define OBSFMU_KERNEL_NOISE_H

/* The settings of the image (= the keys of plants.noise.Noise.filter_form, in order) */
enum {
    KN_ORDER, KN_STREAMS, KN_BUDGET, KN_DT, KN_INPUT_U, KN_P_AD, KN_P_BD, KN_X_LONGEST, KN_X_NOTED, KN_X_SIZE,
    KN_COUNT
};
static int kn_fits(const KernelImage *k)
{
    const double *s = k->settings;
    for (int i = 0; i < KN_COUNT; i++)
        if (!(s[i] == s[i])) return 0;
    size_t order = (size_t)s[KN_ORDER], streams = (size_t)s[KN_STREAMS];
    int added = s[KN_INPUT_U] >= 0.0;
    return (order == 1 || order == 2) && streams >= 1 && s[KN_DT] > 0.0 &&
           (size_t)s[KN_X_SIZE] == k->n && 1 + order * streams + 2 == k->n && k->q == streams &&
           (size_t)s[KN_P_AD] == 5 && (size_t)s[KN_P_BD] == 5 + order * order &&
           (size_t)s[KN_P_BD] + order == k->parameters &&
           (added ? k->m == streams && s[KN_INPUT_U] == 0.0 : k->m == 0);
}

/* interval_index(t, dt) (plants/sources/base.py) */
static double kn_interval(double t, double dt)
{
    double k = floor(t / dt + 1e-9);
    return k != k ? 0.0 : k < 0.0 ? 0.0 : k > 0x1p62 ? 0x1p62 : k;
}

/* y on interval k(t): z_k (+ u); NaN when the cache is not at k(t) (the Python path evaluates it) */
static int kn_outputs(const KernelImage *k, double t, const double *x, const double *w, double *out)
{
    const double *s = k->settings;
    size_t streams = (size_t)s[KN_STREAMS];
    int added = s[KN_INPUT_U] >= 0.0, current = x[0] == kn_interval(t, s[KN_DT]);
    for (size_t j = 0; j < streams; j++) {
        double z = k->p[0] == 0.0 ? 0.0 : current ? x[1 + j] : NAN; /* std 0: Noise.sample's zeros */
        out[j] = added ? w[j] + z : z;
    }
    return 0;
}

/* One communication step from t of size h: the cache forward to the interval of t + h; 1 taken, 0 Python's.
 * work: the image's scratch after next (7 n doubles, n = 3 + order streams): w_k and the new state. */
static int kernel_noise_filter(KernelImage *k, double t, double h, double *next, double *work)
{
    const double *s = k->settings, *Ad = k->p + (size_t)s[KN_P_AD], *Bd = k->p + (size_t)s[KN_P_BD];
    size_t order = (size_t)s[KN_ORDER], streams = (size_t)s[KN_STREAMS];
    double target = kn_interval(t + h, s[KN_DT]), none = 0.0, *white = work, *state = work + streams;
    memcpy(next, k->x, k->n * sizeof *next);
    if (k->p[0] == 0.0) return 1;                        /* std 0: zeros, the filter untouched (Noise.sample) */
    double reached = next[0];
    if (target < reached || target - reached > s[KN_BUDGET]) return 0;
    double *x = next + 1;
    for (; reached < target; reached += 1.0) {           /* Noise.filtered_state: filter_step */
        k->g(reached, &none, &none, k->p, white);
        for (size_t i = 0; i < order; i++)
            for (size_t j = 0; j < streams; j++) {
                double total = Ad[i * order] * x[j];
                for (size_t l = 1; l < order; l++) total = total + Ad[i * order + l] * x[l * streams + j];
                state[i * streams + j] = total + Bd[i] * white[j];
            }
        memcpy(x, state, order * streams * sizeof *x);
    }
    next[0] = reached;
    return 1;
}

#endif
