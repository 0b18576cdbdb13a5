"""numpy's seeded random stream, ``numpy.random.default_rng((seed, k))``, for the expression language and in C.

Every seeded noise of the project draws interval ``k``'s samples from a fresh ``default_rng((seed, k))``
(:mod:`plants.noise`, :class:`plants.signals.SampledNoise`), so a sample depends only on ``(seed, k)``.  The
expression language offers that stream as two functions (:mod:`observers.expressions`):

* ``randn(seed, k, j)`` -- the ``j``-th value (from 0) of ``default_rng((seed, k)).standard_normal(j + 1)``;
* ``rand(seed, k, j)`` -- the ``j``-th value of ``default_rng((seed, k)).random(j + 1)``, uniform on ``[0, 1)``.

``seed`` and ``k`` are whole numbers in ``[0, 2^53]``, ``j`` in ``[0, MAX_DRAWS)``; anything else gives NaN (a
domain error, as ``log(-1)``).

A compiled step kernel (issue 39) evaluates them in C (:data:`C_STREAM`, :data:`C_RANDN`, :data:`C_RAND`) with the
same values, bit for bit, by the same three published algorithms numpy uses:

1. ``SeedSequence`` (M. E. O'Neill's ``seed_seq`` design, as numpy documents it): the entropy ``(seed, k)`` as
   32-bit words, least significant first, hashed into a pool of four words and drawn out as four 64-bit words;
2. ``PCG64`` (O'Neill's PCG XSL RR 128/64, LCG multiplier ``0x2360ed051fc65da44385df649fccf645``) seeded with
   them: ``state = (w0, w1)``, ``increment = (w2, w3)``; ``random()`` is ``(next64 >> 11) * 2^-53``;
3. the 256-layer ziggurat of ``standard_normal`` (Marsaglia and Tsang; numpy's variant takes the layer, the sign
   and a 52-bit magnitude from one 64-bit draw).

The ziggurat's tables are *read from numpy itself* (:func:`ziggurat_tables`): a ``PCG64`` whose next output is
chosen (its state set through numpy's public ``state`` property) shows each layer's width as the sample of
magnitude 1, and, by bisection, each layer's threshold as the first magnitude that needs a second draw.  No
number of numpy's source is copied, and the C uses exactly the tables of the numpy that runs the Python path.
The layers' heights ``f_i = exp(-x_i^2 / 2)`` (only the rare wedge test reads them) are computed from the widths;
``tests/observers/test_random_stream.py`` checks the C against numpy on samples that take every branch.
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["MAX_DRAWS", "WHOLE_LIMIT", "randn", "rand", "ziggurat_tables", "c_tables", "C_STREAM", "C_RANDN", "C_RAND"]

#: ``j`` is below this (the j-th draw costs j + 1 draws)
MAX_DRAWS = 4096
#: ``seed`` and ``k`` are at most this (every whole double up to it is exact)
WHOLE_LIMIT = 2.0 ** 53
#: the ziggurat's base layer starts at this ``r`` and its tail beyond; ``INVERSE_R = 1 / r`` (the constants of
#: Marsaglia and Tsang's 256-layer normal ziggurat)
R = 3.6541528853610087963519472518
INVERSE_R = 0.27366123732975827203338247596
#: PCG64's multiplier (the 128-bit LCG of O'Neill's reference)
MULTIPLIER = 0x2360ED051FC65DA44385DF649FCCF645
_MASK128 = (1 << 128) - 1
_INVERSE_MULTIPLIER = pow(MULTIPLIER, -1, 1 << 128)


def _whole(value: float, high: float) -> bool:
    return math.isfinite(value) and value == math.floor(value) and 0 <= value <= high


def _generator(seed: float, k: float, j: float) -> np.random.Generator | None:
    if not (_whole(seed, WHOLE_LIMIT) and _whole(k, WHOLE_LIMIT) and _whole(j, MAX_DRAWS - 1)):
        return None
    return np.random.default_rng((int(seed), int(k)))


def randn(seed: float, k: float, j: float) -> float:
    """``default_rng((seed, k)).standard_normal(j + 1)[j]``; NaN outside the domain (module docstring)."""
    generator = _generator(seed, k, j)
    return math.nan if generator is None else float(generator.standard_normal(int(j) + 1)[int(j)])


def rand(seed: float, k: float, j: float) -> float:
    """``default_rng((seed, k)).random(j + 1)[j]``, uniform on ``[0, 1)``; NaN outside the domain."""
    generator = _generator(seed, k, j)
    return math.nan if generator is None else float(generator.random(int(j) + 1)[int(j)])


def _normal_after(raw: int, probe: np.random.Generator) -> tuple[float, bool]:
    """numpy's ``standard_normal()`` when PCG64's next output is ``raw``, and whether it took only that draw.

    PCG64 steps its state ``s -> M s + c`` and outputs ``rotr64(hi ^ lo, hi >> 58)`` of the new state; a new
    state ``(hi, lo) = (0, raw)`` outputs ``raw``, so the state before is ``(raw - c) / M`` (mod 2^128)."""
    increment = 1
    before = ((raw - increment) * _INVERSE_MULTIPLIER) & _MASK128
    probe.bit_generator.state = {"bit_generator": "PCG64", "state": {"state": before, "inc": increment},
                                 "has_uint32": 0, "uinteger": 0}
    value = float(probe.standard_normal())
    return value, probe.bit_generator.state["state"]["state"] == raw


@functools.cache
def ziggurat_tables() -> np.ndarray:
    """numpy's ziggurat as 768 doubles: the thresholds ``k_i`` (whole numbers below 2^53), the widths ``w_i`` and
    the heights ``f_i`` of the 256 layers (module docstring).

    A draw ``r`` gives the layer ``i = r & 255``, the sign ``(r >> 8) & 1`` and the magnitude ``a = (r >> 9) &
    (2^52 - 1)``; the sample is ``+-a w_i``, at once when ``a < k_i``."""
    thresholds, widths = np.zeros(256), np.zeros(256)
    probe = np.random.Generator(np.random.PCG64(0))
    for layer in range(256):
        widths[layer], _ = _normal_after((1 << 9) | layer, probe)   # magnitude 1, sign +: the sample is w_i
        low, high = 0, 1 << 52                                      # the first magnitude that takes a second draw
        while low < high:
            middle = (low + high) // 2
            if _normal_after((middle << 9) | layer, probe)[1]:
                low = middle + 1
            else:
                high = middle
        thresholds[layer] = low
    heights = np.exp(-0.5 * (widths * 2.0 ** 52) ** 2)
    heights[0] = 1.0                                                # the layer above the top one
    return np.concatenate([thresholds, widths, heights])


def c_tables() -> str:
    """``ex_ziggurat``, the 768 doubles of :func:`ziggurat_tables`, as a C definition (hexadecimal: the identical
    doubles)."""
    values = [float(v).hex() for v in ziggurat_tables()]
    rows = ",\n    ".join(", ".join(values[i:i + 4]) for i in range(0, len(values), 4))
    return f"static const double ex_ziggurat[768] = {{  /* numpy's ziggurat: k_i, w_i, f_i */\n    {rows}\n}};"


#: the C of the stream (:mod:`observers.expressions_c` writes it once, then ``C_RANDN`` and/or ``C_RAND``); needs
#: ``<math.h>`` and a C99 compiler with ``unsigned __int128`` (GCC, Clang, MinGW-w64)
C_STREAM = """\
/* numpy's default_rng((seed, k)) (observers/random_stream.py): SeedSequence -> PCG64 -> standard_normal, random */
#include <stdint.h>
typedef unsigned __int128 ex_u128;
typedef struct { ex_u128 state, increment; } ex_pcg64;

static uint32_t ex_hashmix(uint32_t value, uint32_t *hash)
{
    value ^= *hash;
    *hash *= 0x931e8875u;
    value *= *hash;
    return value ^ (value >> 16);
}

static uint32_t ex_mix(uint32_t x, uint32_t y)
{
    uint32_t result = 0xca01f9ddu * x - 0x4973f715u * y;
    return result ^ (result >> 16);
}

static int ex_words(uint64_t n, uint32_t *words)     /* n as 32-bit words, least significant first, at least one */
{
    words[0] = (uint32_t)n;
    if (n >> 32 == 0)
        return 1;
    words[1] = (uint32_t)(n >> 32);
    return 2;
}

static void ex_pcg64_step(ex_pcg64 *g)
{
    const ex_u128 multiplier = ((ex_u128)0x2360ed051fc65da4u << 64) | 0x4385df649fccf645u;
    g->state = g->state * multiplier + g->increment;
}

static void ex_pcg64_seed(ex_pcg64 *g, uint64_t seed, uint64_t k)   /* PCG64(SeedSequence((seed, k))) */
{
    uint32_t entropy[4], pool[4], hash = 0x43b0d7e5u, drawn[8];
    uint64_t words[4];
    int count = ex_words(seed, entropy), i, j;
    count += ex_words(k, entropy + count);                   /* at most 4 words: the pool's size */
    for (i = 0; i < 4; i++)
        pool[i] = ex_hashmix(i < count ? entropy[i] : 0u, &hash);
    for (i = 0; i < 4; i++)
        for (j = 0; j < 4; j++)
            if (i != j)
                pool[j] = ex_mix(pool[j], ex_hashmix(pool[i], &hash));
    hash = 0x8b51f9ddu;                                      /* generate_state(4, uint64) */
    for (i = 0; i < 8; i++) {
        uint32_t value = pool[i % 4] ^ hash;
        hash *= 0x58f38dedu;
        value *= hash;
        drawn[i] = value ^ (value >> 16);
    }
    for (i = 0; i < 4; i++)
        words[i] = drawn[2 * i] | ((uint64_t)drawn[2 * i + 1] << 32);
    g->increment = ((((ex_u128)words[2] << 64) | words[3]) << 1) | 1u;
    g->state = 0;
    ex_pcg64_step(g);
    g->state += ((ex_u128)words[0] << 64) | words[1];
    ex_pcg64_step(g);
}

static uint64_t ex_pcg64_next(ex_pcg64 *g)                /* XSL RR of the stepped state */
{
    uint64_t high, folded;
    unsigned rotation;
    ex_pcg64_step(g);
    high = (uint64_t)(g->state >> 64);
    folded = high ^ (uint64_t)g->state;
    rotation = (unsigned)(high >> 58);
    return (folded >> rotation) | (folded << ((64u - rotation) & 63u));
}

static double ex_pcg64_double(ex_pcg64 *g)
{
    return (double)(ex_pcg64_next(g) >> 11) * (1.0 / 9007199254740992.0);
}

static int ex_stream(double seed, double k, double j, ex_pcg64 *g)   /* 0: outside the domain */
{
    if (!(seed >= 0.0 && seed <= WHOLE_LIMIT_VALUE && seed == floor(seed) && k >= 0.0 && k <= WHOLE_LIMIT_VALUE
          && k == floor(k) && j >= 0.0 && j < MAX_DRAWS_VALUE && j == floor(j)))
        return 0;
    ex_pcg64_seed(g, (uint64_t)seed, (uint64_t)k);
    return 1;
}

static double ex_draw(double seed, double k, double j, double (*next)(ex_pcg64 *))   /* the j-th draw, NaN outside */
{
    ex_pcg64 g;
    double value = NAN;
    int i;
    if (!ex_stream(seed, k, j, &g))
        return NAN;
    for (i = 0; i <= (int)j; i++)
        value = next(&g);
    return value;
}"""

#: ``randn`` in C: the ziggurat, reading ``ex_ziggurat`` (the 768 doubles of :func:`ziggurat_tables`)
C_RANDN = """\
static double ex_standard_normal(ex_pcg64 *g)             /* the ziggurat: k_i, w_i, f_i in ex_ziggurat */
{
    const double *threshold = ex_ziggurat, *width = ex_ziggurat + 256, *height = ex_ziggurat + 512;
    for (;;) {
        uint64_t draw = ex_pcg64_next(g), magnitude;
        int layer = (int)(draw & 0xff), negative = (int)((draw >> 8) & 1u);
        double x, xx, yy;
        magnitude = (draw >> 9) & 0x000fffffffffffffu;
        x = (double)magnitude * width[layer];
        if (negative)
            x = -x;
        if ((double)magnitude < threshold[layer])
            return x;
        if (layer == 0) {                                    /* the tail beyond r */
            for (;;) {
                xx = -INVERSE_R_VALUE * log1p(-ex_pcg64_double(g));
                yy = -log1p(-ex_pcg64_double(g));
                if (yy + yy > xx * xx)
                    return ((magnitude >> 8) & 1u) ? -(R_VALUE + xx) : R_VALUE + xx;
            }
        }
        if ((height[layer - 1] - height[layer]) * ex_pcg64_double(g) + height[layer] < exp(-0.5 * x * x))
            return x;                                        /* the wedge */
    }
}

static double ex_randn(double seed, double k, double j)
{
    return ex_draw(seed, k, j, ex_standard_normal);
}"""

#: ``rand`` in C
C_RAND = """\
static double ex_rand(double seed, double k, double j)
{
    return ex_draw(seed, k, j, ex_pcg64_double);
}"""

C_STREAM = C_STREAM.replace("WHOLE_LIMIT_VALUE", WHOLE_LIMIT.hex()).replace("MAX_DRAWS_VALUE", float(MAX_DRAWS).hex())
C_RANDN = C_RANDN.replace("INVERSE_R_VALUE", INVERSE_R.hex()).replace("R_VALUE", R.hex())
